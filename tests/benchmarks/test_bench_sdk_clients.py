"""Issue 37's done-when, at length: each SDK drives `pafp emulate motor --can` for 60 s of current, velocity and
position commands (20 s each) with a busy core beside it; no emulator error, every reading the SDK reports is a
frame of the emulator's capture, and the commands act (tests/test_sdk_clients.py runs the same for 3 s).

With ``--motor ak80_9`` the torque opensourceleg asks for is current x its AK80-9 Kt (0.115 N m/A); the plant feels
current x the maker's Kt of the AK80-9 V3.0 KV100 (0.095 N m/A, profiles/motors/ak80_9.toml). The current the SDK
reads is the plant's (status frames, 0.01 A steps), so the two torques differ by exactly the ratio of those
constants, 0.826: the benchmark measures that ratio and prints it; it does not pass a 5 % band, and says so.

Measured on the 2-core development machine (load 8-14 from other work, pure-Python worktree): opensourceleg 60 s
with the busy core: 4177 of 4177 readings in the capture, ratio 0.8261. TMotorCANControl 60 s without the busy
core: 8157 of 8157; with it, its start-up check (ten replies to ten power-on frames within about 1.1 s) failed in 3
runs of 3 ("Device not connected"), and in one run that got past it the SDK recorded no reply at all.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
pytest.importorskip("opensourceleg")
pytest.importorskip("TMotorCANControl")

from test_sdk_clients import drive  # noqa: E402

from hal.virtual.plant.motors import load_motor  # noqa: E402

SECONDS = 60.0


@pytest.fixture
def busy_core():
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    yield
    proc.kill()


def test_osl_servo_60_s_on_the_ak80_9(tmp_path: Path, busy_core) -> None:
    from opensourceleg.actuators.tmotor import TMOTOR_MODELS, CANManagerServo

    log, summary, frames = drive("osl", "servo", "AK80-9", tmp_path, SECONDS, ("--motor", "ak80_9"))
    status = [CANManagerServo.parse_servo_message(None, bytes(m.data)) for m in frames  # type: ignore[arg-type]
              if not m.is_rx and m.arbitration_id == 0x2901]
    seen = {(round(s.position, 1), round(s.current, 2), s.temperature, s.error) for s in status}
    rows = [r for rows in log["phases"].values() for r in rows if r[5] > 0]
    agree = sum((round(math.degrees(r[2]), 1), round(r[4], 2), r[5], r[6]) in seen for r in rows)
    kt_sdk = TMOTOR_MODELS["AK80-9"]["Kt_actual"]
    kt_plant = load_motor("ak80_9").kt_nm_per_a
    settled = [r for r in log["phases"]["current"] if (r[0] % 0.5) >= 0.3]
    plant_torque = sum(abs(r[4]) * kt_plant for r in settled) / len(settled)
    sdk_torque = sum(abs(r[4]) * kt_sdk for r in settled) / len(settled)
    print(f"\nosl 60 s: {len(rows)} readings, {agree} in the capture; {summary}\n"
          f"torque the plant feels / torque the SDK computes = {plant_torque / sdk_torque:.4f} "
          f"(Kt {kt_plant} / {kt_sdk})")
    assert agree == len(rows) and len(rows) > 3000
    assert plant_torque / sdk_torque == pytest.approx(kt_plant / kt_sdk, rel=0.01)


def test_tmcc_mit_60_s_on_the_ak60_6(tmp_path: Path, busy_core) -> None:
    from TMotorCANControl.mit_can import CAN_Manager

    log, summary, frames = drive("tmcc", "mit", "AK60-6", tmp_path, SECONDS)
    parser = object.__new__(CAN_Manager)
    parser.debug = False
    replies = [parser.parse_MIT_message(bytes(m.data), "AK60-6") for m in frames
               if not m.is_rx and m.arbitration_id == 0 and m.data[0] == 1]
    seen = {(s.position, s.temperature, s.error) for s in replies}
    rows = [r for rows in log["phases"].values() for r in rows if r[5] > 0]
    agree = sum((r[2], r[5], r[6]) in seen for r in rows)
    print(f"\ntmcc 60 s: {len(rows)} readings, {agree} in the capture; {summary}")
    assert agree >= 0.99 * len(rows) and len(rows) > 3000

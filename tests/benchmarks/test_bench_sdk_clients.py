"""Issue 37's done-when, at length: each SDK drives `pafp emulate motor --can` for 60 s of current, velocity and
position commands (20 s each) with a busy core beside it; no emulator error, every reading the SDK reports is a
frame of the emulator's capture, and the commands act (tests/test_sdk_clients.py runs the same for 3 s).

With ``--motor ak80_9 --current-convention rms`` the torque opensourceleg asks for is current x its AK80-9 Kt
(0.115 N m/A); the plant feels the catalogue's Kt (0.095 N m/A, profiles/motors/ak80_9.toml) x its own current, which
is the wire's current x sqrt(3/2) in that convention (docs/hardware.md, "Current conventions"; the plant's own
current is measured in tests/test_can_emulate_step.py, here it is taken from the convention): the benchmark prints
the ratio of the two torques over the current phase and asserts it within 5 % of 1 (0.988 expected).

Measured on the 2-core development machine before the emulator's fixes of this issue (load 8-14 from other work,
pure-Python worktree, catalogue convention): opensourceleg 60 s with the busy core: 4177 of 4177 readings in the
capture, ratio 0.8261. TMotorCANControl 60 s with the busy core: its start-up check (ten replies to ten power-on
frames within about 0.2 s) failed in 3 runs of 3 ("Device not connected"): the MIT-mode motor's first reply
integrated the whole quiet spell of plant since the emulator started (hal World.commit_plant now keeps it current).
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

    log, summary, frames = drive("osl", "servo", "AK80-9", tmp_path, SECONDS,
                                 ("--motor", "ak80_9", "--current-convention", "rms"))
    status = [CANManagerServo.parse_servo_message(None, bytes(m.data)) for m in frames  # type: ignore[arg-type]
              if not m.is_rx and m.arbitration_id == 0x2901]
    seen = {(round(s.position, 1), round(s.current, 2), s.temperature, s.error) for s in status}
    rows = [r for rows in log["phases"].values() for r in rows if r[5] > 0]
    agree = sum((round(math.degrees(r[2]), 1), round(r[4], 2), r[5], r[6]) in seen for r in rows)
    kt_sdk = TMOTOR_MODELS["AK80-9"]["Kt_actual"]
    kt_plant = load_motor("ak80_9").kt_nm_per_a
    settled = [r for r in log["phases"]["current"] if (r[0] % 0.5) >= 0.3]
    plant_a = 1.5 ** 0.5  # plant amps per wire amp in the RMS convention (Ak60CanConfig.current_convention)
    plant_torque = sum(abs(r[4]) * plant_a * kt_plant for r in settled) / len(settled)
    sdk_torque = sum(abs(r[4]) * kt_sdk for r in settled) / len(settled)
    print(f"\nosl 60 s: {len(rows)} readings, {agree} in the capture; {summary}\n"
          f"torque the plant feels / torque the SDK computes = {plant_torque / sdk_torque:.4f} "
          f"(Kt {kt_plant} x sqrt(3/2) / {kt_sdk})")
    assert agree == len(rows) and len(rows) > 3000
    assert plant_torque / sdk_torque == pytest.approx(1.0, rel=0.05)


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

"""Serial mode against `pafp emulate bench` (UART and CAN): after a fault the motor gets the profile's safe behaviour,
and its frames are the last on the motor's wire, as the emulator captured it (firmware/safe_state.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from test_serial_run import _emulator, _stop

from host_tools.cli import main
from protocol import can_mit, can_servo
from protocol.vesc import Decoder, SetCurrent, SetDuty

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="ptys")
IMU_SILENT_AT_S = 1.0  # on the firmware's clock: RUN by then (from 0.5 s: the start-up move ends at 1.0 s)
RUN_S = "1.5"  # the IMU's timeout (40 ms) latches the fault, then the safe state runs for about 0.45 s
LEAN = ("--quiet", "--no-plot", "--no-trace")  # no assertion here reads the plot or the trace


def _profile(tmp_path: Path, safe_state: str) -> Path:
    text = (ROOT / "profiles" / "firmware.toml").read_text(encoding="utf-8")
    lines = [f'safe_state = "{safe_state}"' if line.startswith("safe_state =") else line for line in text.splitlines()]
    path = tmp_path / "firmware.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _assert_safe_after_imu_silence(out: Path) -> None:
    s = json.loads((out / "summary.json").read_text())
    assert s["faults"] and s["faults"][0] in ("IMU_TIMEOUT", "COMMAND_STALE", "MOTOR_TIMEOUT"), s["fault"]
    assert s["stop"]["safe_on_wire"], s["stop"]


def test_uart_a_fault_ends_with_the_phase_short_on_the_motors_wire(tmp_path: Path) -> None:
    proc, motor, imu = _emulator(20.0, "--capture", str(tmp_path / "device"))
    out = tmp_path / "out"
    try:
        main(["run", "--motor", motor, "--imu", f"fault://{imu}?fault=imu_silent&at={IMU_SILENT_AT_S}",
              "--profile", str(_profile(tmp_path, "short")), "--duration", RUN_S, "--out", str(out), *LEAN])
    finally:
        _stop(proc)
    _assert_safe_after_imu_silence(out)
    frames = Decoder("to-motor").feed((tmp_path / "device" / "motor.rx.bin").read_bytes())
    commands = [f for f in frames if isinstance(f, (SetCurrent, SetDuty))]
    assert commands[-2:] == [SetCurrent(0.0), SetDuty(0.0)], commands[-3:]  # the stop path: zero, then the short
    assert SetDuty(0.0) in commands[-20:-2]  # and the safe state's own periodic command before it


@pytest.mark.parametrize(("mode", "safe_state", "last"), [
    ("servo", "short", (can_servo.command_id(can_servo.PacketId.SET_DUTY, 1),
                        can_servo.encode_command(can_servo.PacketId.SET_DUTY, 0.0))),
    ("mit", "damping", (1, can_mit.encode_command(can_mit.MitCommand(kd=1.0)))),  # damping: kd = damping_kd always
])
def test_can_a_fault_ends_with_the_safe_behaviour_on_the_motors_wire(
        tmp_path: Path, mode: str, safe_state: str, last: tuple[int, bytes]) -> None:
    got = _can_fault_run(tmp_path, mode, safe_state)
    assert got[-1] == last, got[-3:]
    assert got.count(last) > 2  # the safe state's own periodic frames before the stop path's


def test_can_mit_a_fault_ends_with_the_mit_hold_on_the_motors_wire(tmp_path: Path) -> None:
    got = _can_fault_run(tmp_path, "mit", "hold")
    ident, data = got[-1]
    hold = can_mit.decode_command(data, can_mit.AK60_6)
    # kp = hold_kp, kd = damping_kd (profiles/firmware.toml) about the reported position, nothing else
    assert ident == 1 and hold.kp == pytest.approx(20.0, abs=0.2) and hold.kd == pytest.approx(1.0, abs=0.01)
    assert hold.v_des == pytest.approx(0.0, abs=0.05) and hold.t_ff == pytest.approx(0.0, abs=0.01)
    assert got.count(got[-1]) > 2  # the same target every period since the hold began: taken once


def _can_fault_run(tmp_path: Path, mode: str, safe_state: str) -> list[tuple[int, bytes]]:
    """A RUN_S run against the CAN bench whose IMU falls silent; the frames the motor received, in order."""
    pytest.importorskip("can")
    pytest.importorskip("msgpack")
    from test_serial_can import can_bench, can_url, received, stop_bench

    url = can_url(mode)
    bench, imu = can_bench(url, tmp_path / "device")
    out = tmp_path / "out"
    try:
        main(["run", "--motor", url, "--imu", f"fault://{imu}?fault=imu_silent&at={IMU_SILENT_AT_S}",
              "--profile", str(_profile(tmp_path, safe_state)), "--duration", RUN_S, "--out", str(out), *LEAN])
    finally:
        stop_bench(bench)
    _assert_safe_after_imu_silence(out)
    return [(m.arbitration_id, bytes(m.data)) for m in received(tmp_path / "device" / "motor.can.log")]

"""A controller that leaves `update` by sys.exit, KeyboardInterrupt, GeneratorExit or any BaseException, or
blocks in it, never skips the stop path (issue 25, items 1 and 2).

Virtual and serial mode (UART against `pafp emulate bench --pty`): the safe frames are the last commands on
the motor's wire (read from the motor side's capture in serial mode), summary.json names what happened,
every file is written, and the exit code is the documented one for a controller error (1: a fault latched,
CONTROLLER_ERROR; docs/hardware.md). The controllers: tests/misbehaving_controllers.py.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from test_serial_run import _emulator, _stop, _summary, assert_stopped_safely
from test_serial_stop import assert_outputs_complete

from host_tools.cli import main
from protocol.vesc import Decoder, SetCurrent, SetCurrentBrake

HERE = Path(__file__).resolve().parent
CONTROLLERS = HERE / "misbehaving_controllers.py"
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="ptys")
WAYS_OUT = [("Exits", "SystemExit: 0"), ("Interrupts", "KeyboardInterrupt"),
            ("ClosesGenerator", "GeneratorExit"), ("RaisesBase", "Escape: out of here")]


def _commands(to_motor: bytes) -> list[object]:
    """The current and brake commands in what went to the motor, in order."""
    return [f for f in Decoder("to-motor").feed(to_motor) if isinstance(f, (SetCurrent, SetCurrentBrake))]


def assert_safe_at_the_end(to_motor: bytes) -> None:
    """The commands end with a run of brakes that follows a zero-current command (the safe state's sequence)."""
    cmds = _commands(to_motor)
    k = len(cmds)
    while k > 0 and isinstance(cmds[k - 1], SetCurrentBrake):
        k -= 1
    assert k < len(cmds) and cmds[-1].current_a > 0, cmds[-3:]
    assert k > 0 and cmds[k - 1] == SetCurrent(0.0), cmds[max(0, k - 3):k + 2]


@pytest.mark.parametrize(("cls", "named"), WAYS_OUT)
def test_virtual_run_latches_controller_error_and_writes_everything(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], cls: str, named: str) -> None:
    out, capture = tmp_path / "out", tmp_path / "capture"
    code = main(["run", "--strides", "2", "--controller", f"{CONTROLLERS}:{cls}", "--out", str(out), "--quiet",
                 "--no-plot", "--capture", str(capture)])
    err = capsys.readouterr().err
    assert code == 1, err
    s = _summary(out)
    assert s["faults"] == ["CONTROLLER_ERROR"] and s["complete"] is True
    assert f"raised {named}" in s["controller"]["error"] and "misbehaving_controllers.py" in s["controller"]["error"]
    assert f"raised {named}" in err and "CONTROLLER_ERROR" in err
    for name in ("summary.json", "report.md", "telemetry.bin", "telemetry.csv", "trace.json"):
        assert (out / name).stat().st_size > 0, name
    assert_safe_at_the_end((capture / "motor.tx.bin").read_bytes())


@pytest.mark.parametrize(("cls", "named"), WAYS_OUT)
def test_serial_run_over_uart_stops_safely_when_the_controller_exits(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], cls: str, named: str) -> None:
    bench, motor, imu = _emulator(20.0, "--capture", str(tmp_path / "device"))
    out = tmp_path / "out"
    try:
        code = main(["run", "--motor", motor, "--imu", imu, "--duration", "2.5", "--out", str(out), "--quiet",
                     "--controller", f"{CONTROLLERS}:{cls}"])
    finally:
        _stop(bench)
    err = capsys.readouterr().err
    s = assert_outputs_complete(out)
    assert code == 1 and s["exit_code"] == 1, err
    stop = s["stop"]
    assert stop["reason"] == "duration" and stop["signal"] is None and stop["safe_on_wire"], stop
    if s["fault"]["reason"] == "CONTROLLER_ERROR":  # else a host stall latched first (the controller never ran on)
        assert f"raised {named}" in s["controller"]["error"] and f"raised {named}" in err
    # the motor's side of the wire: the stop path's zero current then brake are the last frames it got
    assert_stopped_safely((tmp_path / "device" / "motor.rx.bin").read_bytes())


def _rows(index: Path, file: str) -> list[tuple[float, int, int]]:
    """(t_s, offset, bytes) of each row of a capture's index.csv for one file."""
    rows = []
    for line in index.read_text().splitlines()[1:]:
        t, name, offset, n = line.split(",")
        if name == file:
            rows.append((float(t), int(offset), int(n)))
    return rows


def test_serial_run_over_uart_blocking_controller_gets_the_safe_frames_from_the_host_watchdog(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    device = tmp_path / "device"
    bench, motor, imu = _emulator(20.0, "--capture", str(device))
    out = tmp_path / "out"
    try:
        code = main(["run", "--motor", motor, "--imu", imu, "--duration", "4", "--out", str(out), "--quiet",
                     "--controller", f"{CONTROLLERS}:Blocks"])
    finally:
        _stop(bench)
    err = capsys.readouterr().err
    s = assert_outputs_complete(out)
    assert code == 1 and s["exit_code"] == 1, err
    stop, hw = s["stop"], s["host_watchdog"]
    assert stop["reason"] == "watchdog" and stop["task"] == "control" and stop["safe_on_wire"], stop
    assert s["fault"]["reason"] in ("WATCHDOG", "COMMAND_STALE", "MOTOR_TIMEOUT", "IMU_TIMEOUT"), s["fault"]
    assert hw["armed"] and hw["fired"] and hw["sends"] >= 3, hw  # sent again every timeout while the loop slept
    assert hw["timeout_ms"] <= hw["silent_ms"] < 1000.0 and stop["latency_ms"] == hw["silent_ms"], hw
    assert "host watchdog fired" in err
    # the motor's side: the watchdog's frames came long before the 2 s block ended, the stop path's are last
    to_motor = (device / "motor.rx.bin").read_bytes()
    assert_stopped_safely(to_motor)
    safe = SetCurrent(0.0).encode() + SetCurrentBrake(2.0).encode()
    first = to_motor.find(safe)
    assert first > 0 and to_motor.count(safe) >= 3
    rows = _rows(device / "index.csv", "motor.rx.bin")
    k = next(i for i, (_, offset, n) in enumerate(rows) if offset <= first < offset + n)
    gap_s = rows[k][0] - rows[k - 1][0]  # from the last bytes the loop sent to the watchdog's frames
    assert gap_s < 1.0, gap_s  # the motor's own timeout; the controller slept 2 s


@pytest.mark.parametrize("mode", ["servo", "mit"])
def test_serial_run_over_can_stops_safely_when_the_controller_exits(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], mode: str) -> None:
    pytest.importorskip("can")
    pytest.importorskip("msgpack")
    from test_serial_can import assert_stopped_safely_on_can, can_bench, can_url, stop_bench

    url = can_url(mode, 1)
    bench, imu = can_bench(url, tmp_path / "device")
    out = tmp_path / "out"
    try:
        code = main(["run", "--motor", url, "--imu", imu, "--duration", "2.5", "--out", str(out), "--quiet",
                     "--controller", f"{CONTROLLERS}:Exits"])
    finally:
        stop_bench(bench)
    err = capsys.readouterr().err
    s = assert_outputs_complete(out)
    assert code == 1 and s["exit_code"] == 1, err
    assert s["stop"]["reason"] == "duration" and s["stop"]["safe_on_wire"], s["stop"]
    if s["fault"]["reason"] == "CONTROLLER_ERROR":  # else a host stall latched first (the controller never ran on)
        assert "raised SystemExit: 0" in s["controller"]["error"] and "raised SystemExit: 0" in err
    assert_stopped_safely_on_can(tmp_path / "device" / "motor.can.log", mode)


@pytest.mark.parametrize("mode", ["servo", "mit"])
def test_serial_run_over_can_blocking_controller_gets_the_safe_frames_from_the_host_watchdog(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], mode: str) -> None:
    pytest.importorskip("can")
    pytest.importorskip("msgpack")
    from test_serial_can import assert_stopped_safely_on_can, can_bench, can_url, received, safe_frames, stop_bench

    url = can_url(mode, 2)
    bench, imu = can_bench(url, tmp_path / "device")
    out = tmp_path / "out"
    try:
        code = main(["run", "--motor", url, "--imu", imu, "--duration", "4", "--out", str(out), "--quiet",
                     "--controller", f"{CONTROLLERS}:Blocks"])
    finally:
        stop_bench(bench)
    err = capsys.readouterr().err
    s = assert_outputs_complete(out)
    assert code == 1 and s["exit_code"] == 1, err
    stop, hw = s["stop"], s["host_watchdog"]
    assert stop["reason"] == "watchdog" and stop["task"] == "control" and stop["safe_on_wire"], stop
    assert hw["armed"] and hw["handle"].startswith("second bus") and hw["fired"] and hw["sends"] >= 3, hw
    assert hw["timeout_ms"] <= hw["silent_ms"] < 1000.0, hw
    # the motor's side: the watchdog's frames long before the 2 s block ended, the stop path's last
    log = tmp_path / "device" / "motor.can.log"
    assert_stopped_safely_on_can(log, mode)
    got = received(log)
    pair = safe_frames(mode)
    keys = [(m.arbitration_id, bytes(m.data)) for m in got]
    starts = [i for i in range(1, len(keys) - 1) if keys[i:i + 2] == pair]
    assert len(starts) >= 3, len(starts)  # the watchdog's, again while the loop slept, then the stop path's
    gap_s = got[starts[0]].timestamp - got[starts[0] - 1].timestamp
    assert gap_s < 1.0, gap_s  # the motor's own timeout; the controller slept 2 s

"""A controller that leaves `update` by sys.exit, KeyboardInterrupt, GeneratorExit or any BaseException, or
blocks in it, never skips the stop path (issue 25, items 1 and 2).

Virtual and serial mode (UART against `pafp emulate bench --pty`, CAN against `--can`): the safe frames are the
last commands on the motor's wire (read from the motor side's capture in serial mode), summary.json names what
happened, every file is written, and the exit code is the documented one for a controller error (1: a fault
latched, CONTROLLER_ERROR; docs/hardware.md). The controllers: tests/misbehaving_controllers.py.

The virtual runs take all four ways out; the serial runs three of them, one each (SERIAL_WAYS_OUT). Serial mode has
no code per way out: the firmware's control task catches whatever `update` (or `reset`) raises, BaseException and
all, in one ``except`` (firmware/tasks.py, the same compiled code in both modes) before serial mode's loop could see
it; serial mode's only look at a kind, KeyboardInterrupt taken for a Ctrl-C (host_tools/serial_mode/serial_run.py),
is for what a task lets through. The UART run takes KeyboardInterrupt, the one that branch could mistake.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from test_serial_run import SAFE_UART, STALL_FAULTS, _emulator, _stop, _summary, assert_stopped_safely
from test_serial_stop import assert_outputs_complete, fail_encoder_read

from host_tools.cli import main
from protocol.vesc import Decoder, SetCurrent, SetCurrentBrake, SetDuty

HERE = Path(__file__).resolve().parent
CONTROLLERS = HERE / "misbehaving_controllers.py"
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="ptys")
WAYS_OUT = [("Exits", "SystemExit: 0"), ("Interrupts", "KeyboardInterrupt"),
            ("ClosesGenerator", "GeneratorExit"), ("RaisesBase", "Escape: out of here")]
SERIAL_WAYS_OUT = {"uart": WAYS_OUT[1], "servo": WAYS_OUT[0], "mit": WAYS_OUT[3]}
"""The way out each serial run takes (UART; CAN by mode): see the module's doc."""
EXIT_RUN_S = 1.5
"""A serial run whose controller exits: past RUN's start (startup_grace_s, 0.5 s) and MISBEHAVE_AFTER_S (0.3 s) of
RUN, with room to spare for a late start on a busy host."""
BLOCK_RUN_S = 1.5
"""A serial run whose controller blocks: the block (BLOCK_S, 2 s) begins inside it, at 0.8 s; the host watchdog
then ends the run, after the block."""


def _commands(to_motor: bytes) -> list[object]:
    """The current, brake and duty commands in what went to the motor, in order."""
    return [f for f in Decoder("to-motor").feed(to_motor) if isinstance(f, (SetCurrent, SetCurrentBrake, SetDuty))]


def assert_safe_at_the_end(to_motor: bytes) -> None:
    """The commands end with a run of the shipped safe state's phase short (duty 0) that follows a zero-current
    command (the failing period's)."""
    cmds = _commands(to_motor)
    k = len(cmds)
    while k > 0 and cmds[k - 1] == SetDuty(0.0):
        k -= 1
    assert k < len(cmds), cmds[-3:]
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
    for name in ("summary.json", "report.md", "telemetry.bin", "telemetry.csv", "trace.pftrace"):
        assert (out / name).stat().st_size > 0, name
    assert_safe_at_the_end((capture / "motor.tx.bin").read_bytes())


def run_against_emulator(tmp_path: Path, link: str, controller: str, duration_s: float, mode: str = "servo"
                         ) -> tuple[int, dict, Path]:
    """`pafp run` with `controller` against `pafp emulate bench` (--pty, or --can on udp_multicast), capturing on
    the motor's side: the exit code, summary.json (every output checked) and the emulator's capture folder."""
    device = tmp_path / "device"
    if link == "uart":
        bench, motor, imu = _emulator(20.0, "--capture", str(device))
        stop = lambda: _stop(bench)  # noqa: E731
    else:
        pytest.importorskip("can")
        pytest.importorskip("msgpack")
        from test_serial_can import can_bench, can_url, stop_bench

        motor = can_url(mode)
        can_proc, imu = can_bench(motor, device)
        stop = lambda: stop_bench(can_proc)  # noqa: E731
    out = tmp_path / "out"
    try:
        code = main(["run", "--motor", motor, "--imu", imu, "--duration", str(duration_s), "--out", str(out),
                     "--quiet", "--controller", f"{CONTROLLERS}:{controller}"])
    finally:
        stop()
    return code, assert_outputs_complete(out), device


def assert_stopped_safely_on(device: Path, link: str, mode: str = "servo") -> None:
    """The motor's side of the wire (the emulator's capture): the stop path's frames are the last it got."""
    if link == "uart":
        assert_stopped_safely((device / "motor.rx.bin").read_bytes())
    else:
        from test_serial_can import assert_stopped_safely_on_can

        assert_stopped_safely_on_can(device / "motor.can.log", mode)


def watchdog_on_the_wire(device: Path, link: str, mode: str = "servo") -> tuple[float, int]:
    """On the motor's side: ms from the loop's last bytes (frame) to the first safe pair, and how many pairs came."""
    if link == "uart":
        to_motor = (device / "motor.rx.bin").read_bytes()
        safe = b"".join(m.encode() for m in SAFE_UART)
        first = to_motor.find(safe)
        assert first > 0, "no safe frames"
        rows = _rows(device / "index.csv", "motor.rx.bin")
        k = next(i for i, (_, offset, n) in enumerate(rows) if offset <= first < offset + n)
        return (rows[k][0] - rows[k - 1][0]) * 1e3, to_motor.count(safe)
    from test_serial_can import received, safe_frames

    got = received(device / "motor.can.log")
    keys = [(m.arbitration_id, bytes(m.data)) for m in got]
    safe = safe_frames(mode)  # the host watchdog's pre-built stop path: the shipped safe state's frame
    starts = [i for i in range(1, len(keys) - len(safe) + 1) if keys[i:i + len(safe)] == safe]
    assert starts, "no safe frames"
    return (got[starts[0]].timestamp - got[starts[0] - 1].timestamp) * 1e3, len(starts)


def _rows(index: Path, file: str) -> list[tuple[float, int, int]]:
    """(t_s, offset, bytes) of each row of a capture's index.csv for one file."""
    rows = []
    for line in index.read_text().splitlines()[1:]:
        t, name, offset, n = line.split(",")
        if name == file:
            rows.append((float(t), int(offset), int(n)))
    return rows


def test_serial_run_over_uart_stops_safely_when_the_controller_exits(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cls, named = SERIAL_WAYS_OUT["uart"]
    code, s, device = run_against_emulator(tmp_path, "uart", cls, EXIT_RUN_S)
    _assert_controller_exit(s, code, capsys.readouterr().err, named)
    assert_stopped_safely_on(device, "uart")


@pytest.mark.parametrize("mode", ["servo", "mit"])
def test_serial_run_over_can_stops_safely_when_the_controller_exits(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], mode: str) -> None:
    cls, named = SERIAL_WAYS_OUT[mode]
    code, s, device = run_against_emulator(tmp_path, "can", cls, EXIT_RUN_S, mode)
    _assert_controller_exit(s, code, capsys.readouterr().err, named)
    assert_stopped_safely_on(device, "can", mode)


def _assert_controller_exit(s: dict, code: int, err: str, named: str) -> None:
    assert code == 1 and s["exit_code"] == 1, err
    stop = s["stop"]
    assert stop["signal"] is None and stop["safe_on_wire"], stop
    if stop["reason"] == "watchdog":  # this shared host stalled the loop past the host watchdog: it ended the run
        assert s["host_watchdog"]["fired"] and s["fault"]["reason"] in ("WATCHDOG", *STALL_FAULTS), s["fault"]
    else:
        assert stop["reason"] == "duration", stop
    if s["fault"]["reason"] == "CONTROLLER_ERROR":  # else a host stall latched first (the controller never ran on)
        assert f"raised {named}" in s["controller"]["error"] and f"raised {named}" in err


@pytest.mark.parametrize(("link", "mode"), [("uart", "servo"), ("can", "servo"), ("can", "mit")])
def test_blocking_controller_gets_the_safe_frames_from_the_host_watchdog(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], link: str, mode: str) -> None:
    code, s, device = run_against_emulator(tmp_path, link, "Blocks", BLOCK_RUN_S, mode)
    err = capsys.readouterr().err
    assert code == 1 and s["exit_code"] == 1, err
    stop, hw = s["stop"], s["host_watchdog"]
    # the job it caught is the controller's (control), unless this shared host stalled the loop first
    assert stop["reason"] == "watchdog" and stop["task"] is not None and stop["safe_on_wire"], stop
    assert s["fault"]["reason"] in ("WATCHDOG", *STALL_FAULTS), s["fault"]
    assert hw["armed"] and hw["fired"] and hw["sends"] >= 3, hw  # sent again every timeout while the loop slept
    assert hw["handle"].startswith("duplicate of fd" if link == "uart" else "second bus"), hw
    assert hw["timeout_ms"] <= hw["silent_ms"] < 1000.0 and stop["latency_ms"] == hw["silent_ms"], hw
    assert "host watchdog fired" in err
    # the motor's side: the watchdog's frames came long before the 2 s block ended, the stop path's are last
    assert_stopped_safely_on(device, link, mode)
    gap_ms, pairs = watchdog_on_the_wire(device, link, mode)
    assert pairs >= 3  # the watchdog's, again while the loop slept, then the stop path's
    assert gap_ms < 1000.0, gap_ms  # the motor's own timeout; the controller slept 2 s


@pytest.mark.parametrize("raised", [SystemExit(5), KeyboardInterrupt(), GeneratorExit()])
def test_any_base_exception_from_a_task_ends_in_the_stop_path_with_exit_3(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
        raised: BaseException) -> None:
    """Not the controller (that latches): a task of the firmware itself; no signal came, so no signal is named."""
    fail_encoder_read(monkeypatch, raised)
    out, capture = tmp_path / "out", tmp_path / "capture"
    code = main(["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--duration", "3", "--out", str(out),
                 "--capture", str(capture), "--quiet"])
    err = capsys.readouterr().err
    assert code == 3, err
    s = assert_outputs_complete(out)
    stop = s["stop"]
    assert stop["reason"] == "exception" and stop["signal"] is None and stop["task"] == "encoder", stop
    assert stop["error"].startswith(type(raised).__name__) and stop["safe_on_wire"], stop
    assert_stopped_safely((capture / "motor.tx.bin").read_bytes())

"""Serial mode's stop path on every way out: a signal, an exception in a task, a lost port, the end of the run.

Each test reads what went over the motor's wire (the byte-capturing relay `tests/serial_mitm.py`, or the run's
own ``--capture``) and asserts that the last frames are the safe command: zero current, then the profile's safe
state (the shipped graded: the phase short); and
that every output file is there and valid. Timing figures (how soon after the signal) live in
tests/benchmarks/test_bench_wallclock.py; here only what the code guarantees.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from test_serial_faults import CLEAN, _relay, _relay_counts
from test_serial_run import _emulator, _stop, _summary, assert_faults_justified, assert_stopped_safely, is_graded_stop

import host_tools.serial_mode.serial_run as serial_run
from host_tools.cli import main
from protocol.telemetry import TelemetryDecoder
from tests.trace_reader import read_trace

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="ptys, POSIX signals")
OUTPUTS = ("summary.json", "report.md", "telemetry.bin", "telemetry.csv", "trace.pftrace", "tracking.png")


def assert_outputs_complete(out: Path) -> dict:
    """Every output file is there; summary.json is strict JSON; telemetry.bin decodes whole into the CSV."""
    for name in OUTPUTS:
        assert (out / name).stat().st_size > 0, name
    s = _summary(out)
    dec = TelemetryDecoder()
    records = dec.feed((out / "telemetry.bin").read_bytes())
    assert len(records) == s["telemetry"]["records_sent"] and dec.pending_bytes == 0
    assert len((out / "telemetry.csv").read_text().splitlines()) == len(records) + 1
    assert read_trace(out / "trace.pftrace").slices  # a complete trace
    return s


def _wait_for_traffic(index: Path, run: subprocess.Popen, timeout_s: float = 20.0) -> None:
    """Return once the run's wire capture shows its loop running (index.csv has rows)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and run.poll() is None:
        if index.exists() and index.stat().st_size > 1000:
            return
        time.sleep(0.02)
    raise AssertionError(f"no traffic in {index} (run exit code {run.poll()})")


def _pafp(*args: str) -> subprocess.Popen:
    """`pafp` in its own process (a signal goes to it, not to pytest)."""
    return subprocess.Popen([sys.executable, "-m", "host_tools", *args], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_mid_run_stops_the_motor_and_writes_everything(tmp_path: Path, sig: signal.Signals) -> None:
    bench, motor_dev, imu = _emulator()
    relay, paths = _relay({"motor": motor_dev}, *CLEAN, "--capture", str(tmp_path))
    out, capture = tmp_path / "out", tmp_path / "capture"
    run = _pafp("run", "--motor", paths["motor"], "--imu", imu, "--duration", "20", "--out", str(out),
                "--capture", str(capture), "--quiet")
    try:
        _wait_for_traffic(capture / "index.csv", run)
        time.sleep(0.5)  # mid-run: the start-up move is under way
        run.send_signal(sig)
        stdout, stderr = run.communicate(timeout=20)
    finally:
        if run.poll() is None:
            run.kill()
        _relay_counts(relay)
        _stop(bench)
    assert run.returncode == 128 + sig, (run.returncode, stderr)
    s = assert_outputs_complete(out)
    stop = s["stop"]
    assert stop["reason"] == "signal" and stop["signal"] == sig.name and stop["safe_on_wire"], stop
    zero, safe = stop["safe_frames"]
    assert zero == "SetCurrent(current_a=0.0)" and is_graded_stop(safe, bool(s["faults"])), (stop, s["faults"])
    assert s["sim_time_s"] < 10  # the signal ended it, not the duration
    # what the relay saw on the cable, and what the run captured itself: both end with the safe command
    assert_stopped_safely((tmp_path / "motor.to_device.bin").read_bytes())
    assert_stopped_safely((capture / "motor.tx.bin").read_bytes())
    assert_faults_justified(s)


def fail_encoder_read(monkeypatch: pytest.MonkeyPatch, raised: BaseException, at_call: int = 300) -> None:
    """The encoder task's read (FeedbackAngle.angle_rad, every period) raises `raised` at its at_call-th call."""
    calls = [0]
    angle = serial_run.FeedbackAngle.angle_rad

    def failing(self: serial_run.FeedbackAngle, t: int) -> float:
        calls[0] += 1
        if calls[0] == at_call:
            raise raised
        return angle(self, t)

    monkeypatch.setattr(serial_run.FeedbackAngle, "angle_rad", failing)


def test_exception_in_a_task_stops_the_motor_names_the_task_and_exits_3(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    fail_encoder_read(monkeypatch, RuntimeError("encoder read failed (injected)"))
    out, capture = tmp_path / "out", tmp_path / "capture"
    code = main(["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--duration", "3", "--out", str(out),
                 "--capture", str(capture), "--quiet"])
    err = capsys.readouterr().err
    assert code == 3
    assert "task 'encoder' raised RuntimeError: encoder read failed (injected)" in err
    assert "test_serial_stop.py" in err  # the file and line of the raise
    s = assert_outputs_complete(out)
    stop = s["stop"]
    assert stop["reason"] == "exception" and stop["task"] == "encoder" and stop["safe_on_wire"]
    assert s["exit_code"] == 3 and s["sim_time_s"] < 1.0
    assert_stopped_safely((capture / "motor.tx.bin").read_bytes())


def test_lost_imu_port_is_named_and_the_motor_still_gets_the_safe_command(tmp_path: Path) -> None:
    bench, motor_dev, imu_dev = _emulator()
    motor_relay, motor = _relay({"motor": motor_dev}, *CLEAN, "--capture", str(tmp_path))
    imu_relay, imu = _relay({"imu": imu_dev}, *CLEAN)
    timer = threading.Timer(1.2, imu_relay.kill)  # the IMU's cable is pulled; the motor's stays
    timer.start()
    out = tmp_path / "out"
    try:
        code = main(["run", "--motor", motor["motor"], "--imu", imu["imu"], "--duration", "5", "--out", str(out),
                     "--quiet"])
    finally:
        timer.join()
        _relay_counts(motor_relay)
        _stop(bench)
    s = assert_outputs_complete(out)
    assert code == 4 and s["stop"]["reason"] == "link_lost"
    link = s["link_lost"]
    assert link["role"] == "imu" and link["port"] == imu["imu"] and link["detection_ms"] >= 0
    assert s["faults"] == ["LINK_LOST"] or s["fault"]["reason"] in ("COMMAND_STALE", "MOTOR_TIMEOUT", "IMU_TIMEOUT")
    assert s["stop"]["safe_on_wire"]
    assert_stopped_safely((tmp_path / "motor.to_device.bin").read_bytes())


def test_telemetry_pty_is_printed_and_a_monitor_attaches(tmp_path: Path) -> None:
    """The run outlasts the monitor whatever its start-up takes (seconds on a host without a bytecode cache: a run
    of fixed length could end before the monitor opened the pty); SIGINT then ends it the usual way."""
    run = _pafp("run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--encoder", "sim", "--duration", "60",
                "--telemetry", "pty", "--out", str(tmp_path / "out"), "--quiet", "--no-plot", "--no-trace")
    try:
        run.stdout.readline()  # type: ignore[union-attr]  # the banner
        line = run.stdout.readline()  # type: ignore[union-attr]
        assert line.startswith("telemetry: /dev/"), line
        path = line.split()[1]
        assert main(["monitor", path, "--duration", "1", "--csv", str(tmp_path / "live.csv")]) == 0  # in-process
        assert run.poll() is None, "the run ended before the monitor was done"
        run.send_signal(signal.SIGINT)
        run.communicate(timeout=20)
    finally:
        if run.poll() is None:
            run.kill()
    rows = (tmp_path / "live.csv").read_text().splitlines()
    assert len(rows) > 50, rows[:3]  # about 500 records per second came through the pty
    assert run.returncode == 128 + signal.SIGINT

"""Serial mode end to end: the firmware on the ptys of `pafp emulate bench`, unplug, start-up errors."""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from host_tools.cli import main
from protocol.telemetry import FaultReason, SupervisorState, TelemetryDecoder
from protocol.vesc import Decoder, SetCurrent, SetDuty, SetPos
from tests.trace_reader import read_trace

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="ptys")


SETTLE_S = 0.5  # the emulated suspended foot starts level and rests on its -30 deg stop 0.3 s later
# Faults that a stall of this shared host can justify on the wall clock, each with the measured age in
# summary["fault"]["detail"]. DEADLINE_MISSES is not among them: on the wall clock it is a warning
# (docs/serial_mode.md, "Fault criteria"). A stall of the loop past the host watchdog's timeout (100 ms) also
# latches WATCHDOG, justified by the watchdog's measured silence (summary["host_watchdog"]["silent_ms"]).
STALL_FAULTS = ("COMMAND_STALE", "MOTOR_TIMEOUT", "IMU_TIMEOUT")


def _emulator(duration_s: float = 20.0, *options: str) -> tuple[subprocess.Popen, str, str]:
    """Start `pafp emulate bench --pty`; return it with its motor and IMU paths once the foot is at rest.

    A firmware started while the foot still falls sees its relative encoder (zeroed at the first reply)
    and the IMU part ways and rightly trips SENSOR_DISAGREEMENT; a real foot is at rest when powered up.
    """
    proc = subprocess.Popen([sys.executable, "-m", "host_tools", "emulate", "bench", "--pty", "--duration",
                             str(duration_s), *options], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    paths = {}
    for _ in range(2):
        role, path = proc.stdout.readline().strip().split(": ")  # type: ignore[union-attr]
        paths[role] = path
    _like_a_device(proc.pid)
    time.sleep(SETTLE_S)
    return proc, paths["motor"], paths["imu"]


EMULATOR_FIFO_PRIORITY = 5  # below serial mode's loop (RealtimeSettings.fifo_priority, 10): the firmware comes first


def _like_a_device(pid: int) -> None:
    """Give the emulated bench SCHED_FIFO below the firmware's loop, when the OS grants it (else it stays as it is).

    A real AK60-6 and BNO08x answer on their own processors; the emulated ones are a process of this shared host,
    which busy neighbours starve for tens of ms: the replies then come late and the run rightly latches
    MOTOR_TIMEOUT, a fault of the test bench, not of the firmware under test.
    """
    if hasattr(os, "sched_setscheduler"):
        with contextlib.suppress(OSError):
            os.sched_setscheduler(pid, os.SCHED_FIFO, os.sched_param(EMULATOR_FIFO_PRIORITY))


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    proc.communicate(timeout=10)


def _summary(out: Path) -> dict:
    """summary.json, parsed strictly: NaN or Infinity is an error (they are not JSON)."""
    def refuse(token: str) -> None:
        raise ValueError(f"summary.json holds {token}, which is not JSON")

    return json.loads((out / "summary.json").read_text(), parse_constant=refuse)


def assert_faults_justified(s: dict) -> None:
    """Any latched fault is one a measured stall explains, with its age over the limit; never a miss streak."""
    if not s["faults"]:
        return
    if s["faults"][0] == "WATCHDOG":
        hw = s["host_watchdog"]
        assert hw["fired"] and hw["silent_ms"] >= hw["timeout_ms"], hw
        return
    assert s["faults"][0] in STALL_FAULTS, (s["faults"], s["fault"])
    assert_age_over_limit(s["fault"]["detail"])


def assert_age_over_limit(detail: str) -> float:
    """The measured age in a fault's detail ("motor feedback age 20.0 ms > 20.0 ms") is over its limit; returned.

    The detail prints the age to 0.1 ms: an age just over the limit (20.04 ms) prints as the limit itself, so the
    printed age is at least the limit (the supervisor's strict comparison: tests/test_safety_boundaries.py).
    """
    age, limit = (float(v) for v in re.findall(r"([0-9.]+) ms", detail))
    assert age >= limit, detail
    return age


SAFE_UART = (SetCurrent(0.0), SetDuty(0.0))
"""The shipped profile's stop path on the UART before its safe state has taken a hold: zero current, then the
phase short (graded's damper)."""


def assert_stopped_safely(motor_to_device: bytes) -> None:
    """The last two frames on the motor's wire are zero current, then the safe state's: the shipped profile's graded
    state leaves the phase short, or, once it has taken the loaded foot (``brake_delay_s`` after a trip: a stop that
    follows a fault, a lost link's, finds it so when the run ends late enough), the hold at the position the drive
    reported (firmware/safe_state.py)."""
    frames = Decoder("to-motor").feed(motor_to_device)
    assert len(frames) >= 2, frames
    zero, safe = frames[-2:]
    held = isinstance(safe, SetPos) and math.isfinite(safe.position_rad)
    assert zero == SetCurrent(0.0) and (safe == SetDuty(0.0) or held), frames[-3:]


def is_graded_stop(name: str, tripped: bool) -> bool:
    """Whether a stop frame as summary.json names it (``stop.safe_frames``) is the shipped graded safe state's: the
    phase short, or, only after a trip (``tripped``: a fault latched), the hold at a position (assert_stopped_safely).
    """
    hold = "SetPos(position_rad="
    if tripped and name.startswith(hold) and name.endswith(")"):
        return math.isfinite(float(name[len(hold):-1]))
    return name == "SetDuty(duty=0.0)"


def test_e2e_against_emulated_bench_tracks_like_virtual(tmp_path: Path) -> None:
    proc, motor, imu = _emulator(20.0, "--capture", str(tmp_path / "device"))
    out, capture = tmp_path / "out", tmp_path / "capture"
    try:
        code = main(["run", "--motor", motor, "--imu", imu, "--duration", "3", "--out", str(out), "--quiet",
                     "--capture", str(capture)])
    finally:
        _stop(proc)
    s = _summary(out)
    assert s["mode"] == "serial" and s["stop"]["reason"] == "duration" and s["stop"]["safe_on_wire"]
    sent = (capture / "motor.tx.bin").read_bytes()
    assert_stopped_safely(sent)
    # both ends' captures agree (from the start-up check on): what the firmware wrote is what the emulated
    # motor received; what the firmware read, the motor sent (it may have sent more after the stop)
    device = tmp_path / "device"
    assert (device / "motor.rx.bin").read_bytes() == sent
    assert (device / "motor.tx.bin").read_bytes().startswith((capture / "motor.rx.bin").read_bytes())
    manifest = json.loads((device / "capture.json").read_text())
    decode = manifest["files"]["motor.rx.bin"]["decode"]
    assert decode == "pafp decode --protocol vesc --direction to-motor motor.rx.bin"
    assert_faults_justified(s)
    assert code == (1 if s["faults"] else 0)  # a warning (a host stall) does not change the exit code
    rt = s["realtime"]
    assert abs(rt["control_releases"] - 3000) <= 1 and rt["control_releases_expected"] == 3000
    assert rt["release_jitter_us"]["p99_us"] is not None
    for f in ("telemetry.bin", "telemetry.csv", "trace.pftrace", "tracking.png", "report.md"):
        assert (out / f).stat().st_size > 0, f
    if s["faults"]:
        return  # the stall that tripped it is checked above; tracking over too short a RUN proves nothing
    assert s["supervisor_state"] == "RUN" and s["strides"] >= 2
    # every request is answered or counted missing (how many replies came in time is the emulator's speed on
    # this shared host, a benchmark figure)
    link = s["motor_link"]
    assert 0 <= link["requests"] - link["replies"] - link["missing_replies"] <= 1, link
    assert link["replies"] > 0 and s["wire_errors"]["imu"]["frames"] > 0
    # tracking measured over the RUN time, from the firmware's own signals (no plant here: truth is null).
    # How close it comes to the virtual bench's depends on how promptly this shared host runs the emulator
    # process: a figure of tests/benchmarks/test_bench_wallclock.py, not a guarantee.
    tr = s["tracking"]
    assert tr["enough_run"] and tr["truth"]["rms_deg"] is None
    assert all(0 < tr[k]["rms_deg"] < 90 for k in ("imu", "encoder", "fused"))


def test_unplug_is_attributed_and_files_are_complete(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    proc, motor, imu = _emulator()
    timer = threading.Timer(1.5, proc.kill)  # the whole emulator dies: both ports go
    timer.start()
    try:
        code = main(["run", "--motor", motor, "--imu", imu, "--duration", "3", "--out", str(tmp_path), "--quiet",
                     "--no-plot"])  # the files read below: the telemetry and the trace
    finally:
        timer.cancel()
        _stop(proc)
    err = capsys.readouterr().err
    s = _summary(tmp_path)
    link = s["link_lost"]
    assert code == 4 and "lost" in err and s["stop"]["reason"] == "link_lost"
    assert s["supervisor_state"] == "SAFE"
    assert link["port"] == {"motor": motor, "imu": imu}[link["role"]]
    assert link["detection_ms"] >= 0  # from the first failed read or write to the supervisor's look at it
    if s["faults"] != ["LINK_LOST"]:  # a stall tripped first: the first reason is kept, and justified
        assert_faults_justified(s)
    assert s["sim_time_s"] < 2.5  # stopped shortly after the loss, not at the end of the duration
    # telemetry complete up to the fault: every record sent is in the file, no torn frame, last ones SAFE
    dec = TelemetryDecoder()
    records = dec.feed((tmp_path / "telemetry.bin").read_bytes())
    assert len(records) == s["telemetry"]["records_sent"] and dec.pending_bytes == 0
    assert dec.stats.crc_errors == dec.stats.dropped_bytes == 0
    assert records[-1].supervisor_state == SupervisorState.SAFE
    assert records[-1].fault_reason == FaultReason[s["faults"][0]]
    rows = (tmp_path / "telemetry.csv").read_text().splitlines()
    assert len(rows) == len(records) + 1
    assert read_trace(tmp_path / "trace.pftrace").slices  # a complete trace


def test_sim_urls_run_in_process_with_1000_releases_per_second(tmp_path: Path) -> None:
    code = main(["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--encoder", "sim", "--duration", "1",
                 "--out", str(tmp_path), "--quiet", "--no-plot", "--no-trace"])
    s = _summary(tmp_path)
    assert_faults_justified(s)
    assert code == (1 if s["faults"] else 0)
    assert abs(s["realtime"]["control_releases"] - 1000) <= 1
    assert s["angle_source"] == "plant" and s["encoder_source"] == "sim"
    assert s["time_in_run_s"] < 1.0 and s["strides"] == 0  # 1 s is less than a stride after the start-up move


@pytest.fixture()
def pty_pair():  # type: ignore[no-untyped-def]
    """A raw pty: (master fd, slave path)."""
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    yield master, os.ttyname(slave)
    os.close(master)
    os.close(slave)


def _startup_error(tmp_path: Path, capsys: pytest.CaptureFixture[str], motor: str, imu: str) -> str:
    out = tmp_path / "out"
    code = main(["run", "--motor", motor, "--imu", imu, "--duration", "1", "--out", str(out), "--quiet"])
    assert code == 2
    assert not out.exists()  # nothing half-written
    return capsys.readouterr().err


def test_no_trace_and_no_plot_leave_those_files_out_in_serial_mode(tmp_path: Path) -> None:
    """--no-trace and --no-plot mean in serial mode what they mean on the virtual bench."""
    main(["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--duration", "1", "--no-realtime", "--no-trace",
          "--no-plot", "--out", str(tmp_path), "--quiet"])
    names = {p.name for p in tmp_path.iterdir()}
    assert {"summary.json", "report.md", "telemetry.bin", "telemetry.csv"} <= names, names
    assert not names & {"trace.pftrace", "tracking.png"}, names


def test_port_that_cannot_open_names_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _startup_error(tmp_path, capsys, "/dev/does-not-exist-42", "sim://bno08x")
    assert "/dev/does-not-exist-42" in err and "motor" in err


def test_garbage_means_wrong_baud(tmp_path: Path, capsys: pytest.CaptureFixture[str], pty_pair) -> None:  # type: ignore[no-untyped-def]
    master, path = pty_pair
    stop = threading.Event()

    def noise() -> None:
        while not stop.is_set():
            os.write(master, bytes(range(0x80, 0xC0)))
            time.sleep(0.01)

    t = threading.Thread(target=noise)
    t.start()
    try:
        err = _startup_error(tmp_path, capsys, "sim://ak60-6", path)
    finally:
        stop.set()
        t.join()
    assert path in err and "no valid frame" in err and "wrong baud" in err and "UART-RVC" in err


def test_wrong_protocol_and_silence(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    proc, motor, imu = _emulator(6)
    try:
        err = _startup_error(tmp_path, capsys, imu, motor)  # swapped
    finally:
        _stop(proc)
    assert f"motor port {imu!r}: the device speaks UART-RVC" in err


def test_imu_silent(tmp_path: Path, capsys: pytest.CaptureFixture[str], pty_pair) -> None:  # type: ignore[no-untyped-def]
    _, path = pty_pair
    err = _startup_error(tmp_path, capsys, "sim://ak60-6", path)
    assert f"imu port {path!r}: silent" in err

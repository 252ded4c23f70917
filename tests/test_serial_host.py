"""The host side of serial mode in isolation: real-time settings undone, stop signals, wire capture, pty telemetry."""

from __future__ import annotations

import gc
import json
import os
import signal
import sys
from pathlib import Path

import pytest

from firmware.drivers.motor import MotorDriver
from hal.interfaces import Uart
from host_tools.serial_mode.realtime import RealtimeSection, RealtimeSettings
from host_tools.serial_mode.telemetry_pty import TelemetryPty
from host_tools.stop_signals import StopSignals
from host_tools.wire_capture import WireCapture
from protocol.vesc import Decoder, SetCurrent, SetCurrentBrake


class SinkUart(Uart):
    """Takes every byte (kept in `sent`) and is always drained."""

    def __init__(self) -> None:
        super().__init__(921600, "sink")
        self.sent = b""

    def _send(self, data: bytes) -> int:
        self.sent += data
        return len(data)

    def _receive(self, max_bytes: int) -> bytes:
        return b""

    def _rx_count(self) -> int:
        return 0

    def _tx_space(self) -> int:
        return 4096


linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux scheduling calls")


@linux
def test_realtime_section_is_undone_whatever_was_granted() -> None:
    before = (os.sched_getaffinity(0), os.sched_getscheduler(0), gc.isenabled())
    with RealtimeSection(RealtimeSettings()) as rt:
        assert not gc.isenabled() and rt.granted["gc"] == "granted"
        for key in ("fifo", "pin", "mlock"):
            assert rt.granted[key].startswith(("granted", "refused", "not done", "unsupported")), rt.granted
    assert (os.sched_getaffinity(0), os.sched_getscheduler(0), gc.isenabled()) == before


@linux
def test_refused_fifo_is_reported_and_then_no_pinning(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    affinity = os.sched_getaffinity(0)
    with RealtimeSection(RealtimeSettings(mlock=False)) as rt:
        assert rt.granted["fifo"].startswith("refused: Operation not permitted")
        assert rt.granted["pin"].startswith("not done") and os.sched_getaffinity(0) == affinity
        assert rt.granted["mlock"] == "not requested"


_PINNED_FIFO_CHILD = """
import os, sys, time
core = max(os.sched_getaffinity(0))
os.sched_setaffinity(0, {core})
os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
print(core, flush=True)
time.sleep(30)
"""


@linux
@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2 if hasattr(os, "sched_getaffinity") else True,
                    reason="one core: nothing to choose")
def test_a_second_loop_is_pinned_away_from_a_core_another_fifo_loop_holds() -> None:
    """Another process's SCHED_FIFO thread pinned to the last core (another serial run's loop): it is counted, and
    this loop takes another core (two loops on one core reach the kernel's RT throttling: 50 ms stalls)."""
    import subprocess

    from host_tools.serial_mode.realtime import realtime_threads_pinned

    child = subprocess.Popen([sys.executable, "-c", _PINNED_FIFO_CHILD], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        line = child.stdout.readline().strip()  # type: ignore[union-attr]
        if not line:
            pytest.skip(f"SCHED_FIFO not granted here: {child.stderr.read().strip().splitlines()[-1:]}")  # type: ignore[union-attr]
        core = int(line)
        assert realtime_threads_pinned()[core] >= 1
        with RealtimeSection(RealtimeSettings(gc=False, mlock=False)) as rt:
            assert rt.granted["pin"].startswith("granted"), rt.granted
            assert os.sched_getaffinity(0) != {core}
    finally:
        child.kill()
        child.wait()


def test_kernel_threads_and_unpinned_or_ordinary_threads_are_not_counted(tmp_path: Path) -> None:
    from host_tools.serial_mode.realtime import realtime_threads_pinned

    def task(pid: int, flags: int, policy: int, cpus: str) -> None:
        d = tmp_path / str(pid) / "task" / str(pid)
        d.mkdir(parents=True)
        fields = ["S"] + ["0"] * 5 + [str(flags)] + ["0"] * 31 + [str(policy)] + ["0"] * 5
        (d / "stat").write_text(f"{pid} (a (b) c) " + " ".join(fields) + "\n")
        (d / "status").write_text(f"Name:\tx\nCpus_allowed_list:\t{cpus}\n")

    task(101, 0x00200000, 1, "3")  # a kernel thread (migration/3): FIFO on one core
    task(102, 0, 1, "3")  # a user FIFO thread on core 3
    task(103, 0, 2, "1")  # a user SCHED_RR thread on core 1
    task(104, 0, 1, "0-3")  # FIFO, not pinned
    task(105, 0, 0, "2")  # pinned, ordinary policy
    (tmp_path / "106" / "task" / "106").mkdir(parents=True)  # ended while read: no files
    assert realtime_threads_pinned(tmp_path) == {3: 1, 1: 1}


def test_realtime_settings_refuse_bad_values() -> None:
    with pytest.raises(ValueError, match="spin_s 0.5 out of range: 0..0.01 s"):
        RealtimeSettings(spin_s=0.5)
    with pytest.raises(ValueError, match="fifo_priority 0 out of range: 1..99"):
        RealtimeSettings(fifo_priority=0)


def test_stop_signals_ask_once_then_raise_and_restore_handlers() -> None:
    asked: list[bool] = []
    previous = signal.getsignal(signal.SIGHUP)
    with StopSignals(lambda: asked.append(True)) as sigs:
        os.kill(os.getpid(), signal.SIGHUP)
        assert asked == [True] and sigs.name == "SIGHUP" and sigs.exit_code == 129 and sigs.at_ns is not None
        with pytest.raises(KeyboardInterrupt, match="second signal SIGTERM"):
            os.kill(os.getpid(), signal.SIGTERM)
    assert signal.getsignal(signal.SIGHUP) is previous


def test_motor_stop_writes_zero_current_then_brake_and_drains() -> None:
    uart = SinkUart()
    driver = MotorDriver(uart)
    stop = driver.send_stop(1.25, 2.0)
    assert stop.on_wire and stop.written == 20 and driver.last_command_s == 1.25
    assert Decoder("to-motor").feed(uart.sent) == [SetCurrent(0.0), SetCurrentBrake(2.0)]


def test_wire_capture_files_index_and_manifest(tmp_path: Path) -> None:
    t = [0.0]
    cap = WireCapture(tmp_path, lambda: t[0], side="device")
    cap.open("motor", "rx", "tx")
    cap.record("motor", "rx", b"\x02\x05\x06")
    t[0] = 0.5
    cap.record("motor", "rx", b"\x00\x00")
    cap.record("motor", "tx", b"")  # nothing moved: no row
    cap.close()
    assert (tmp_path / "motor.rx.bin").read_bytes() == b"\x02\x05\x06\x00\x00"
    assert (tmp_path / "motor.tx.bin").read_bytes() == b""
    rows = (tmp_path / "index.csv").read_text().splitlines()
    assert rows == ["t_s,file,offset,bytes", "0.000000000,motor.rx.bin,0,3", "0.500000000,motor.rx.bin,3,2"]
    files = json.loads((tmp_path / "capture.json").read_text())["files"]
    assert files["motor.rx.bin"]["decode"] == "pafp decode --protocol vesc --direction to-motor motor.rx.bin"
    assert files["motor.tx.bin"]["bytes"] == 0
    with pytest.raises(ValueError, match="already holds a capture"):
        WireCapture(tmp_path, lambda: 0.0)


@pytest.mark.skipif(sys.platform == "win32", reason="ptys")
def test_telemetry_pty_delivers_and_never_pushes_back() -> None:
    pty = TelemetryPty()
    try:
        reader = os.open(pty.path, os.O_RDONLY | os.O_NONBLOCK)
        assert pty.write(b"abc") == 3
        assert os.read(reader, 16) == b"abc"
        os.close(reader)
        taken = sum(pty.write(bytes(1000)) for _ in range(200))  # nobody reading: the pty fills up
        assert taken == 200_000 and pty.dropped > 0  # dropped here, never refused to the logger
    finally:
        pty.close()

"""Serial mode with the motor on a CAN bus (`pafp run --motor can://...`) against `pafp emulate bench --can`:
one plant serves the motor on the bus and the IMU on a pty, so the run reaches RUN; the stop path's frames
are the last the motor got (the emulator's candump capture); the drain waits for the frames still on the
wire only; the bus's echoes of a port's own frames are not frames in; can:// URLs need id and mode."""

from __future__ import annotations

import csv
import math
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

can = pytest.importorskip("can")
pytest.importorskip("msgpack")  # udp_multicast needs it

from can_groups import multicast_group  # noqa: E402
from test_serial_run import _like_a_device  # noqa: E402

import hal.pycan as pycan  # noqa: E402
from hal.can import CanFrame  # noqa: E402
from hal.pycan import PythonCanPort, parse_can_url  # noqa: E402
from host_tools.cli import main  # noqa: E402
from protocol import can_mit, can_servo  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SETTLE_S = 0.5  # the emulated suspended foot comes to rest on its stop (tests/test_serial_run.py)
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="ptys")


def can_url(mode: str) -> str:
    """A udp_multicast can:// URL on a group of its own (tests/can_groups.py)."""
    return f"can://udp_multicast/{multicast_group()}?id=1&mode={mode}"


def can_bench(url: str, capture: Path, duration_s: float = 30.0,
              options: tuple[str, ...] = ()) -> tuple[subprocess.Popen, str]:
    """Start `pafp emulate bench --can URL --capture DIR [options]`; return it and its IMU pty once the foot rests."""
    proc = subprocess.Popen([sys.executable, "-m", "host_tools", "emulate", "bench", "--can", url, "--duration",
                             str(duration_s), "--capture", str(capture), *options], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == f"motor: {url}", proc.stderr.read() if proc.poll() else ""
    role, imu = proc.stdout.readline().strip().split(": ")
    assert role == "imu"
    _like_a_device(proc.pid)  # as the pty bench: starved, its foot may still be falling when the firmware starts
    time.sleep(SETTLE_S)
    return proc, imu


def stop_bench(proc: subprocess.Popen) -> str:
    """SIGTERM the emulator; its summary line."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err
    return out.strip().splitlines()[-1]


def safe_frames(mode: str) -> list[tuple[int, bytes]]:
    """The stop path's frame, (arbitration id, data), as the motor must receive it last: the shipped profile's safe
    state (graded: the phase short in servo mode; in MIT mode the damper, kd 1.0 loaded or 0.25 unloaded: is_safe)."""
    if mode == "mit":
        return [(1, can_mit.encode_command(can_mit.MitCommand(kd=1.0)))]
    return [(0x001, can_servo.encode_command(can_servo.PacketId.SET_DUTY, 0.0))]


def is_safe(frames: list[tuple[int, bytes]], mode: str) -> bool:
    """Whether frames are the stop path's (in MIT mode: one damping command, kp = 0, no torque, kd > 0; in servo
    mode the short, or graded's hold at a position once it has taken the loaded foot, as on the UART:
    test_serial_run.assert_stopped_safely)."""
    if mode != "mit":
        if len(frames) == 1 and frames[0][0] == can_servo.command_id(can_servo.PacketId.SET_POS, 1):
            return math.isfinite(can_servo.decode_command(*frames[0]).value)
        return frames == safe_frames(mode)
    if len(frames) != 1 or frames[0][0] != 1 or len(frames[0][1]) != 8:
        return False
    c = can_mit.decode_command(frames[0][1])
    return c.kp == 0.0 and abs(c.t_ff) < 0.01 and c.kd > 0.0


def received(log: Path) -> list[can.Message]:
    """The frames a side received (R), read back by python-can from its candump capture."""
    return [m for m in can.LogReader(str(log)) if m.is_rx]


def assert_stopped_safely_on_can(device_log: Path, mode: str) -> None:
    """The last two frames the motor received are the stop path's."""
    got = received(device_log)
    assert is_safe([(m.arbitration_id, bytes(m.data)) for m in got[-1:]], mode), got[-3:]


@pytest.mark.parametrize("mode", ["servo", "mit"])
def test_serial_run_on_can_reaches_run_against_the_emulated_bench_and_stops_with_the_safe_frames(
        tmp_path: Path, mode: str) -> None:
    url = can_url(mode)
    bench, imu = can_bench(url, tmp_path / "device")
    out, capture = tmp_path / "out", tmp_path / "capture"
    try:
        code = main(["run", "--motor", url, "--imu", imu, "--duration", "2", "--out", str(out), "--quiet",
                     "--no-plot", "--no-trace", "--capture", str(capture)])  # neither is read here
    finally:
        line = stop_bench(bench)
    import json

    s = json.loads((out / "summary.json").read_text())
    assert s["stop"]["reason"] == "duration" and s["stop"]["safe_on_wire"], s["stop"]
    assert code in (0, 1)  # a fault latched by a host stall is reported (1), never a crash
    # one plant: the IMU and the motor agree, so the supervisor leaves INIT for RUN and never sees them apart
    states = {row["supervisor_state_name"] for row in csv.DictReader((out / "telemetry.csv").open())}
    assert "RUN" in states, states
    assert "SENSOR_DISAGREEMENT" not in s["faults"], s["fault"]
    assert s["motor_link"]["replies"] > 200, s["motor_link"]
    # the motor's side, read by python-can: the stop path's frames are the last it got
    assert_stopped_safely_on_can(tmp_path / "device" / "motor.can.log", mode)
    sent = [m for m in can.LogReader(str(capture / "motor.can.log")) if not m.is_rx]
    assert is_safe([(m.arbitration_id, bytes(m.data)) for m in sent[-1:]], mode), sent[-3:]
    # the emulator counts the frames it got, not its own frames handed back by the multicast loopback
    frames_in = int(re.search(r"(\d+) frames in", line).group(1))  # type: ignore[union-attr]
    echoes = int(re.search(r"(\d+) own echoes dropped", line).group(1))  # type: ignore[union-attr]
    assert frames_in == len(received(tmp_path / "device" / "motor.can.log")) and echoes > 0, line
    assert frames_in <= len(sent) + 2, (frames_in, len(sent))


class _Bus:
    """A python-can bus double: what is sent is kept, and handed back too when it echoes (udp_multicast)."""

    def __init__(self, echo: bool) -> None:
        self.echo = echo
        self.sent: list[can.Message] = []
        self.inbox: list[can.Message] = []

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.sent.append(msg)
        if self.echo:
            self.inbox.append(msg)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self.inbox.pop(0) if self.inbox else None

    def shutdown(self) -> None:
        pass


def test_drain_waits_for_the_frames_still_on_the_wire_not_one_frame_time_per_frame(
        monkeypatch: pytest.MonkeyPatch) -> None:
    now = [100.0]
    slept: list[float] = []
    monkeypatch.setattr(pycan.time, "sleep", slept.append)
    port = PythonCanPort(_Bus(False), 1_000_000, clock_s=lambda: now[0])
    for _ in range(2000):  # two seconds of a 1 kHz loop: each frame long gone when the next is sent
        assert port.send(CanFrame(0x101, bytes(4), True))
        now[0] += 0.001
    assert port.flush(0.5) and slept == []  # nothing is still on the wire
    port.send(CanFrame(0x101, bytes(4), True))
    port.send(CanFrame(0x201, bytes(4), True))  # the stop path: two frames at once
    assert port.flush(0.5)
    assert slept == [pytest.approx(2 * 160e-6)]  # their worst-case wire time, back to back
    now[0] += 1.0
    for _ in range(10_000):  # a burst longer than the timeout: the wait is capped and reported
        port.send(CanFrame(0x101, bytes(8), True))
    slept.clear()
    assert port.flush(0.5) is False and slept == [0.5]


def test_own_frames_handed_back_by_the_bus_are_dropped_and_counted() -> None:
    bus = _Bus(echo=True)
    port = PythonCanPort(bus, echoes=True)
    port.send(CanFrame(0x101, b"\x00\x00\x00\x00", True))
    bus.inbox.append(can.Message(arbitration_id=0x2901, data=b"\x01" * 8, is_extended_id=True))  # the motor's
    port.send(CanFrame(0x101, b"\x00\x00\x00\x00", True))
    got = [port.receive() for _ in range(3)]
    assert got == [CanFrame(0x2901, b"\x01" * 8, True), None, None] and port.echoes == 2
    plain = PythonCanPort(_Bus(echo=False))  # a bus that does not echo: an equal frame from elsewhere is kept
    plain.bus.inbox.append(can.Message(arbitration_id=0x101, data=bytes(4), is_extended_id=True))
    assert plain.receive() == CanFrame(0x101, bytes(4), True) and plain.echoes == 0
    mc = pycan.open_can(parse_can_url(can_url("servo")))  # udp_multicast hands a bus its own frames
    try:
        mc.send(CanFrame(0x101, bytes(4), True))
        time.sleep(0.1)
        assert mc.receive() is None and mc.echoes == 1
    finally:
        mc.close()


def test_echoes_of_a_long_burst_are_all_told_from_the_others_frames() -> None:
    """An emulator that fell behind: thousands of its status frames sent before their echoes come back (the filter
    used to remember 1024 and took the rest for another node's frames), one echo lost in the receive buffer, and
    the other node's frames in between."""
    bus = _Bus(echo=False)
    port = PythonCanPort(bus, echoes=True)
    ours = [CanFrame(0x2901, (k % 251).to_bytes(2, "big") + bytes(6), True) for k in range(5000)]
    for frame in ours:
        port.send(frame)
    theirs = [can.Message(arbitration_id=0x101, data=k.to_bytes(4, "big"), is_extended_id=True) for k in range(50)]
    for k, frame in enumerate(ours):
        if k != 1234:  # dropped by an overflowing receive buffer
            bus.inbox.append(can.Message(arbitration_id=frame.arbitration_id, data=frame.data, is_extended_id=True))
        if k % 100 == 99:
            bus.inbox.append(theirs[k // 100])
    got = []
    while (frame := port.receive()) is not None:
        got.append(frame)
    assert got == [CanFrame(m.arbitration_id, bytes(m.data), True) for m in theirs]
    assert port.echoes == 4999 and port._own.lost == 1  # noqa: SLF001 (the count the summary does not show)


@pytest.mark.parametrize(("url", "needle"), [
    ("can://virtual/x", "id and mode missing"),
    ("can://virtual/x?id=1", "mode missing"),
    ("can://virtual/x?mode=servo", "id missing"),
])
def test_can_url_needs_id_and_mode(capsys: pytest.CaptureFixture[str], url: str, needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        parse_can_url(url)
    code = main(["run", "--motor", url, "--imu", "sim://bno08x", "--duration", "1"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and url in err[0] and "mode=servo|mit" in err[0], err


def test_bad_can_url_is_one_line_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["run", "--motor", "can://virtual/x?id=1&mode=foc", "--imu", "sim://bno08x", "--duration", "1"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mode='foc' not one of ('servo', 'mit')" in err[0], err


def test_udp_multicast_buses_on_two_groups_do_not_hear_each_other() -> None:
    a = pycan.open_can(parse_can_url(can_url("servo")))
    b = pycan.open_can(parse_can_url(can_url("servo")))
    try:
        a.send(CanFrame(0x101, bytes(4), True))
        time.sleep(0.1)
        assert b.receive() is None  # Linux hands a socket bound to the port every joined group's datagrams
    finally:
        a.close()
        b.close()

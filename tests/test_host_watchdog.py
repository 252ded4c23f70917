"""The host watchdog (host_tools/serial_mode/host_watchdog.py): its pre-built frames are the driver's own stop path, it
stays quiet while kicked, fires once the kicks stop and sends again while the loop stays silent; its
timeout comes from the firmware profile, with a range."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from firmware.config import load_firmware_config
from hal.virtual.bench import VirtualBench
from host_tools.serial_mode.host_watchdog import HostWatchdog, stop_frames
from profiles import profile_path
from protocol import can_mit, can_servo
from protocol.vesc import SetCurrent, SetDuty


def test_stop_frames_are_what_the_drivers_stop_path_sends() -> None:
    cfg = load_firmware_config()
    data, frames = stop_frames(VirtualBench(lambda: 0, 168_000_000).board, cfg)  # graded: the phase short
    assert data == SetCurrent(0.0).encode() + SetDuty(0.0).encode() and frames == []
    servo = cfg.with_changes(motor_link="can-servo")
    _, frames = stop_frames(VirtualBench(lambda: 0, 168_000_000, motor_link="can-servo").board, servo)
    assert [(f.arbitration_id, f.data) for f in frames] == [
        (0x101, can_servo.encode_command(can_servo.PacketId.SET_CURRENT, 0.0)),
        (0x001, can_servo.encode_command(can_servo.PacketId.SET_DUTY, 0.0))][1:]  # the short alone on CAN
    mit = cfg.with_changes(motor_link="can-mit")
    _, frames = stop_frames(VirtualBench(lambda: 0, 168_000_000, motor_link="can-mit").board, mit)
    assert [f.data for f in frames] == [can_mit.encode_command(can_mit.MitCommand(kd=1.0))]  # graded: the damper


class _Sender:
    handle = "test"

    def __init__(self) -> None:
        self.sent: list[float] = []
        self.closed = False

    def send(self) -> int:
        self.sent.append(time.perf_counter())
        return 20

    def close(self) -> None:
        self.closed = True


def test_quiet_while_kicked_then_fires_and_sends_again_while_silent() -> None:
    sender, fired = _Sender(), []
    wd = HostWatchdog(0.5, sender, lambda: fired.append(1), running=lambda: "control")  # type: ignore[arg-type]
    wd.start()
    end = time.perf_counter() + 0.6
    while time.perf_counter() < end:  # kicked every 10 ms for longer than the timeout: nothing sent
        wd.kick()
        time.sleep(0.01)
    assert sender.sent == [] and fired == []
    wd.kick()
    silent_from = time.perf_counter()  # just after the last kick
    time.sleep(1.7)  # silent: fires after 0.5 s, then every 0.5 s
    record = wd.close()
    assert fired == [1] and record.task == "control" and sender.closed
    assert len(sender.sent) >= 2 and record.sends == len(sender.sent) and record.bytes_sent == 20 * record.sends
    assert sender.sent[0] - silent_from >= 0.499 and record.silent_ms is not None and record.silent_ms >= 500
    assert all(b - a >= 0.5 for a, b in zip(sender.sent, sender.sent[1:], strict=False))
    n = len(sender.sent)
    time.sleep(0.6)
    assert len(sender.sent) == n  # closed: nothing more


@pytest.mark.parametrize(("text", "needle"), [
    ("timeout_s = 0.01", "timeout_s = 0.01 is not allowed: must be a finite number in [0.03, 0.5] s"),
    ("timeout_s = 2.0", "timeout_s = 2.0 is not allowed: must be a finite number in [0.03, 0.5] s"),
    ("timeout = 0.1", "has no key 'timeout': its key is timeout_s"),
])
def test_profile_timeout_has_a_range(tmp_path: Path, text: str, needle: str) -> None:
    base = profile_path("firmware.toml").read_text().split("[host_watchdog]")[0]
    p = tmp_path / "fw.toml"
    p.write_text(base + f"[host_watchdog]\n{text}\n")
    with pytest.raises(ValueError, match=r"\[host_watchdog\] " + needle.replace("[", r"\[").replace("]", r"\]")
                       .replace(".", r"\.")):
        load_firmware_config(p)
    assert load_firmware_config().host_watchdog_s == 0.1

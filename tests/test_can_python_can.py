"""Real buses through python-can: a plain python-can program drives `pafp emulate motor --can` on udp_multicast;
the serial-mode stop path on CAN (Firmware.stop through a python-can bus)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

can = pytest.importorskip("can")
pytest.importorskip("msgpack")  # udp_multicast needs it

from can_groups import multicast_group  # noqa: E402

from firmware.app import Firmware  # noqa: E402
from firmware.config import load_firmware_config  # noqa: E402
from hal.interfaces import Board  # noqa: E402
from hal.pycan import PythonCanPort, parse_can_url  # noqa: E402
from hal.virtual.bench import VirtualBench  # noqa: E402
from protocol import can_mit, can_servo  # noqa: E402

CLIENT = Path(__file__).with_name("can_client.py")


@pytest.mark.parametrize("mode", ["mit", "servo"])
def test_plain_python_can_program_drives_the_emulated_motor(mode: str) -> None:
    group = multicast_group()
    url = f"can://udp_multicast/{group}?id=1&mode={mode}"
    emu = subprocess.Popen([sys.executable, "-m", "host_tools", "emulate", "motor", "--can", url, "--duration", "8"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert emu.stdout is not None
        assert emu.stdout.readline().strip() == f"motor: {url}"
        client = subprocess.run([sys.executable, str(CLIENT), "udp_multicast", group, mode, "1"],
                                capture_output=True, text=True, timeout=30)
        assert client.returncode == 0, client.stderr
        seen = json.loads(client.stdout)
    finally:
        emu.terminate()
        out, err = emu.communicate(timeout=15)
    assert emu.returncode == 0, err
    assert "stopped (SIGTERM)" in out
    if mode == "mit":
        assert seen["replies"] > 20
        assert seen["last_p"] - seen["first_p"] > 0.05  # 2 N m of torque turned the output
    else:
        assert seen["status_frames"] > 20
        assert seen["last_current_a"] == pytest.approx(2.0, abs=0.1)


def test_parse_can_url_names_the_bad_value() -> None:
    u = parse_can_url("can://socketcan/can0?id=5&mode=mit")
    assert (u.interface, u.channel, u.driver_id, u.mode) == ("socketcan", "can0", 5, "mit")
    with pytest.raises(ValueError, match="mode='foc' not one of"):
        parse_can_url("can://socketcan/can0?mode=foc")
    with pytest.raises(ValueError, match="id=300 out of range 0..127"):
        parse_can_url("can://socketcan/can0?id=300")
    with pytest.raises(ValueError, match="is not can://"):
        parse_can_url("can://socketcan")


@pytest.mark.parametrize(("link", "expected"), [
    ("can-mit", [(False, 1, can_mit.encode_command(can_mit.MitCommand(kd=1.0)))]),  # graded: the damper
    ("can-servo", [(True, 0x001, can_servo.encode_command(can_servo.PacketId.SET_DUTY, 0.0))]),  # the short
])
def test_serial_mode_stop_path_on_can_sends_the_safe_frames(link, expected) -> None:
    """Firmware.stop (serial mode calls it: host_tools/serial_mode/serial_run.py) puts the safe frames on the bus."""
    channel = f"pafp-stop-{os.getpid()}-{link}"
    motor_end = can.Bus(interface="virtual", channel=channel)
    port = PythonCanPort(can.Bus(interface="virtual", channel=channel))
    bench = VirtualBench(lambda: 0, 168_000_000)  # IMU, encoder, pins: the CAN port replaces the motor link
    b = bench.board
    board = Board(b.motor_uart, b.imu_uart, b.telemetry_uart, b.encoder, b.estop, b.led, b.watchdog,
                  b.now_cycles, b.f_cpu_hz, port)
    cfg = load_firmware_config().with_changes(motor_link=link)
    fw = Firmware(board, cfg)
    stop = fw.stop(1.0)
    assert stop.on_wire and stop.written == len(stop.frames)
    got = []
    while (msg := motor_end.recv(0.5)) is not None:
        got.append((msg.is_extended_id, msg.arbitration_id, bytes(msg.data)))
    assert got == expected
    port.close()
    motor_end.shutdown()

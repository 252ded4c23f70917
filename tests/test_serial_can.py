"""Serial mode with the motor on a CAN bus (`pafp run --motor can://...`): the run and its stop path."""

from __future__ import annotations

import json
import os
import threading
from pathlib import Path

import pytest

can = pytest.importorskip("can")

from hal.pycan import PythonCanPort, parse_can_url  # noqa: E402
from host_tools.can_emulate import WallCanMotor  # noqa: E402
from host_tools.cli import main  # noqa: E402


@pytest.mark.parametrize("mode", ["servo", "mit"])
def test_serial_run_on_can_stops_with_the_safe_frames(tmp_path: Path, mode: str) -> None:
    channel = f"pafp-serial-{os.getpid()}-{mode}"
    url = f"can://virtual/{channel}?id=1&mode={mode}"
    motor = WallCanMotor(PythonCanPort(can.Bus(interface="virtual", channel=channel)), parse_can_url(url))
    stop: list[str] = []
    server = threading.Thread(target=motor.serve, args=(stop, 20.0), daemon=True)
    server.start()
    try:
        code = main(["run", "--motor", url, "--imu", "sim://bno08x", "--duration", "1.5", "--out", str(tmp_path),
                     "--quiet"])
    finally:
        stop.append("done")
        server.join(5)
        motor.port.close()
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["stop"]["reason"] == "duration" and s["stop"]["safe_on_wire"], s["stop"]
    assert s["motor_link"]["replies"] > 200, s["motor_link"]
    assert code in (0, 1)  # a fault latched by a host stall is reported (1), never a crash
    d = motor.device
    if mode == "mit":  # zero torque then exit motor mode: the driver is out of motor mode, released
        assert not d.motor_mode and d.core.mode.value == "released"
    else:  # zero current then the brake
        assert d.core.mode.value == "brake"


def test_bad_can_url_is_one_line_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["run", "--motor", "can://virtual/x?mode=foc", "--imu", "sim://bno08x", "--duration", "1"])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mode='foc' not one of ('servo', 'mit')" in err[0], err

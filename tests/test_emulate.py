"""`pafp emulate`: virtual devices served on ptys, driven through pyserial, stopped by SIGTERM."""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

from host_tools.cli import main
from protocol.rvc import RvcDecoder
from protocol.vesc import Decoder, GetValues, SetCurrent, Values

ROOT = Path(__file__).resolve().parents[1]


def _start(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "host_tools", "emulate", *args], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_bench_on_ptys_round_trip_then_sigterm() -> None:
    proc = _start("bench", "--pty", "--seed", "3")
    try:
        paths = dict(proc.stdout.readline().strip().split(": ", 1) for _ in range(2))  # type: ignore[union-attr]
        assert set(paths) == {"motor", "imu"} and all(p.startswith("/dev/") for p in paths.values())
        motor = serial.Serial(paths["motor"], 921_600, timeout=2.0)
        imu = serial.Serial(paths["imu"], 115_200, timeout=2.0)
        motor.write(SetCurrent(1.0).encode() + GetValues().encode())
        (values,) = Decoder("from-motor").feed(motor.read(78))
        assert isinstance(values, Values) and values.controller_id == 0x7E
        imu.reset_input_buffer()
        time.sleep(0.25)
        frames = RvcDecoder().feed(imu.read(imu.in_waiting))
        assert len(frames) >= 15
        motor.close()
        imu.close()
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    summary = out.strip().splitlines()[-1]
    assert summary.startswith("pafp emulate: stopped (SIGTERM)")
    assert "motor: frames_in=2 frames_out=1 errors=0" in summary and "imu: frames_in=0 frames_out=" in summary


def test_bad_port_is_one_line_and_exit_2() -> None:
    result = subprocess.run([sys.executable, "-m", "host_tools", "emulate", "motor", "--port", "/dev/no-such-tty"],
                            cwd=ROOT, capture_output=True, text=True, timeout=30)
    assert result.returncode == 2 and result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pafp emulate: cannot open motor port '/dev/no-such-tty'")


def test_option_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "bench", "--port", "/dev/null"]) == 2
    assert "--imu-port" in capsys.readouterr().err
    assert main(["emulate", "imu", "--pty", "--baud", "0"]) == 2
    assert "--baud" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["emulate", "motor"])  # neither --pty nor --port


def test_duration_serves_then_stops(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "imu", "--pty", "--duration", "0.2"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert out[0].startswith("imu: /dev/") and out[-1].startswith("pafp emulate: stopped (duration)")
    frames_out = int(out[-1].split("frames_out=")[1].split()[0])
    assert 15 <= frames_out <= 21


def test_serves_on_a_serial_port_given_by_path() -> None:
    """--port through pyserial: here the port is one end of a pty, the test holds the other."""
    master, slave = os.openpty()
    path = os.ttyname(slave)
    proc = _start("motor", "--port", path, "--duration", "3")
    try:
        assert proc.stdout.readline().strip() == f"motor: {path}"  # type: ignore[union-attr]
        os.write(master, GetValues().encode())
        reply = b""
        deadline = time.monotonic() + 2.0
        while len(reply) < 78 and time.monotonic() < deadline:
            if select.select([master], [], [], 0.1)[0]:
                reply += os.read(master, 256)
        (values,) = Decoder("from-motor").feed(reply)
        assert isinstance(values, Values)
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
        os.close(master)
        os.close(slave)
    assert proc.returncode == 0, err
    assert "motor: frames_in=1 frames_out=1 errors=0" in out


@pytest.mark.parametrize("duration", ["inf", "1e300"])
def test_endless_duration_serves_until_stopped(duration: str) -> None:
    """--duration inf (or one whose nanoseconds overflow) serves until a signal, no OverflowError after the path."""
    proc = _start("imu", "--pty", "--duration", duration)
    try:
        assert proc.stdout.readline().startswith("imu: /dev/")  # type: ignore[union-attr]
        time.sleep(0.3)
        assert proc.poll() is None
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0 and err == "", err
    assert out.strip().splitlines()[-1].startswith("pafp emulate: stopped (SIGTERM)")

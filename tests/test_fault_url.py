"""`fault://` (hal/serial/protocol_fault.py): the injectors between a real port and the firmware."""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

import pytest
import serial

from hal.serial.protocol_fault import parse_fault_url, register_fault_handler
from host_tools.cli import main
from protocol.vesc import Decoder, SetCurrent, SetCurrentBrake

sys.path.insert(0, str(Path(__file__).parent))
from test_serial_run import _emulator, _stop, _summary  # noqa: E402 - the emulated bench of the serial tests


def test_loop_port_loses_bytes_in_the_window_only():
    register_fault_handler()
    port = serial.serial_for_url("fault://loop://?fault=motor_replies_lost&at=0.2&duration=0.2", timeout=0)
    try:
        port.write(b"before")
        time.sleep(0.01)
        assert port.read(100) == b"before"
        time.sleep(0.25)
        port.write(b"during")
        time.sleep(0.01)
        assert port.read(100) == b""  # lost on the line
        time.sleep(0.25)
        port.write(b"after")
        time.sleep(0.01)
        assert port.read(100) == b"after"
        rec = port.fault.record
        assert rec.fired and rec.count == 1 and 0.2 <= rec.first_s < 0.4
    finally:
        port.close()


def test_a_phase_onset_waits_for_the_gait_clock_then_starts_at_that_phase():
    register_fault_handler()
    port = serial.serial_for_url("fault://loop://?fault=motor_replies_lost&phase=0.5&duration=0.5", timeout=0)
    try:
        port.write(b"no gait clock")
        time.sleep(0.01)
        assert port.read(100) == b"no gait clock"  # not placed: without the gait clock the fault never acts
        gait_start = time.monotonic() + 0.05  # the gait starts 50 ms from now, its stride 0.4 s: phase 0.5 at +0.25 s
        port.follow_gait(lambda: time.monotonic() - gait_start, 0.4)
        port.write(b"placed")
        time.sleep(0.01)
        assert port.read(100) == b"placed"
        onset = port.fault.onset_s
        assert onset == pytest.approx(gait_start + 0.2 - port._t0, abs=0.02)
        time.sleep(max(0.0, gait_start + 0.2 + 0.03 - time.monotonic()))
        port.write(b"during")
        time.sleep(0.01)
        assert port.read(100) == b""  # lost in the window
        time.sleep(max(0.0, gait_start + 0.75 - time.monotonic()))
        port.write(b"after")
        time.sleep(0.01)
        assert port.read(100) == b"after"
        assert port.fault.record.fired and port.fault.record.count == 1
    finally:
        port.close()


@pytest.mark.parametrize("url, match", [
    ("fault://loop://?fault=encoder_reversed&at=1", "virtual bench only"),
    ("fault://loop://?fault=imu_bias_step&at=1", "refused on a real port"),
    ("fault://loop://?fault=imu_silent", "one of at=SECONDS or phase=P"),
    ("fault://loop://?fault=imu_silent&at=1&phase=0.5", "one of at=SECONDS or phase=P"),
    ("fault://loop://?fault=imu_silent&phase=1.5", "phase=1.5 out of range"),
    ("fault://loop://?fault=imu_silent&at=soon", "at='soon' is not a number"),
    ("fault://loop://?fault=imu_corrupt&at=1&bit_error_rate=5", "bit_error_rate = 5.0 out of range"),
    ("fault://?fault=imu_silent&at=1", "name the port to wrap"),
])
def test_bad_or_dangerous_urls_are_refused(url, match):
    with pytest.raises(serial.SerialException, match=match):
        parse_fault_url(url)


def test_dangerous_fault_with_the_explicit_flag():
    inner, fault = parse_fault_url("fault:///dev/ttyUSB0?fault=imu_bias_step&at=1&step_deg=5&allow_dangerous=1")
    assert inner == "/dev/ttyUSB0" and fault.params["step_deg"] == 5.0 and fault.onset_s == 1.0


@pytest.mark.skipif(sys.platform == "win32", reason="ptys")
@pytest.mark.parametrize("onset", ["at=1.5", "phase=0.3"])
def test_motor_replies_lost_on_the_emulated_bench_is_detected_and_made_safe(tmp_path: Path, caplog, onset):
    """The issue's end-to-end case: fault:// around the pty of `pafp emulate bench`, replies lost from 1.5 s after
    the port opened, or from 30 % of the first stride on the firmware's gait clock."""
    for attempt in range(3):  # a host stall latches COMMAND_STALE (justly) first: the fault is then untested
        out, capture = tmp_path / f"out{attempt}", tmp_path / f"capture{attempt}"
        caplog.clear()
        proc, motor, imu = _emulator(20.0)
        try:
            code = main(["run", "--motor", f"fault://{motor}?fault=motor_replies_lost&{onset}&duration=1", "--imu",
                         imu, "--duration", "3", "--out", str(out), "--quiet", "--capture", str(capture)])
        finally:
            _stop(proc)
        s = _summary(out)
        if s["faults"] == ["COMMAND_STALE"]:  # lost replies leave the commands' age alone: this host stalled
            age = float(re.findall(r"([0-9.]+) ms", s["fault"]["detail"])[0])
            assert age > 20.0  # measured over the limit
            continue
        break
    assert code == 1 and s["faults"] == ["MOTOR_TIMEOUT"], s["faults"]
    age = float(re.findall(r"([0-9.]+) ms", s["fault"]["detail"])[0])
    assert age > 20.0
    assert any("fault://: motor_replies_lost" in r.getMessage() for r in caplog.records)
    if onset.startswith("phase"):
        assert any("placed at gait phase 0.3" in r.getMessage() for r in caplog.records)
    # the capture of what the firmware sent: after the trip, zero current then the brake, and nothing else
    frames = Decoder("to-motor").feed((capture / "motor.tx.bin").read_bytes())
    commands = [f for f in frames if isinstance(f, (SetCurrent, SetCurrentBrake))]
    first_zero = max((i for i, f in enumerate(commands) if isinstance(f, SetCurrent) and f.current_a != 0.0),
                     default=-1) + 1  # under load the run may reach the fault before it commanded any current
    assert commands[first_zero] == SetCurrent(0.0)
    assert isinstance(commands[-1], SetCurrentBrake) and commands[-1].current_a > 0


def test_python_can_wrapper_destroys_frames_in_the_window():
    import can

    from hal.fault_bus import FaultBus
    from hal.virtual.faults import make_injector

    channel = f"pafp-fault-{time.monotonic_ns()}"
    motor = can.Bus(interface="virtual", channel=channel)
    mcu = FaultBus(can.Bus(interface="virtual", channel=channel), make_injector("can_bus_off", 0.2, 0.2))
    try:
        motor.send(can.Message(arbitration_id=0x2901, data=b"\x01"))
        assert mcu.recv(0.1).data == b"\x01"
        time.sleep(max(0.0, 0.25 - (time.monotonic() - mcu._t0)))
        motor.send(can.Message(arbitration_id=0x2901, data=b"\x02"))
        assert mcu.recv(0.05) is None  # bus-off: lost
        time.sleep(0.2)
        motor.send(can.Message(arbitration_id=0x2901, data=b"\x03"))
        assert mcu.recv(0.1).data == b"\x03"
        assert mcu.fault.record.count == 1
    finally:
        mcu.shutdown()
        motor.shutdown()
    other = can.Bus(interface="virtual", channel=channel)
    try:
        with pytest.raises(ValueError, match="virtual bench only"):
            FaultBus(other, make_injector("motor_stall", 1.0))
    finally:
        other.shutdown()

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
from protocol.vesc import Decoder, SetCurrent, SetCurrentBrake, SetDuty

sys.path.insert(0, str(Path(__file__).parent))
from test_serial_run import _emulator, _stop, _summary, assert_age_over_limit  # noqa: E402 - the serial tests' bench


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


def test_the_window_counts_on_the_firmware_clock_it_follows_and_not_before_its_start():
    """Serial mode hands the port the firmware's clock: before the firmware starts (the start-up checks) the fault
    does not act, however long since the open; then the window is on that clock (scripted here)."""
    register_fault_handler()
    port = serial.serial_for_url("fault://loop://?fault=motor_replies_lost&at=0.5&duration=0.2", timeout=0)
    fw_time: list[float | None] = [None]
    try:
        port._t0 -= 10.0  # the port opened 10 s ago: a window counted from the open would be long over
        port.follow_clock(lambda: fw_time[0])
        port.write(b"start-up check")
        assert port.read(100) == b"start-up check"  # the firmware has not started: the fault does not act
        fw_time[0] = 0.499
        port.write(b"before")
        assert port.read(100) == b"before"
        fw_time[0] = 0.5
        port.write(b"during")
        assert port.read(100) == b""  # lost: 0.5 s on the firmware's clock
        fw_time[0] = 0.7
        port.write(b"after")
        assert port.read(100) == b"after"
        rec = port.fault.record
        assert rec.count == 1 and rec.first_s == 0.5 == rec.last_s  # the record is on the firmware's clock
    finally:
        port.close()


@pytest.mark.parametrize("url, match", [
    ("fault://loop://?fault=encoder_reversed&at=1", "virtual bench only"),
    ("fault://loop://?fault=imu_bias_step&at=1", "refused on a real port"),
    ("fault://loop://?fault=imu_silent", "one of at=SECONDS or phase=P"),
    ("fault://loop://?fault=imu_silent&at=1&phase=0.5", "at=1 and phase=0.5 both given: give either"),
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


ATTEMPTS = 5  # runs of the end-to-end case, each until a run no host stall faulted before the fault acted


def _host_stall(s: dict, onset_s: float | None) -> bool:
    """Whether a measured stall of this shared host latched a fault before the injected one could: the command's age
    (lost replies leave it alone), the host watchdog's silence, an IMU frame's age, or the motor's feedback age
    before the fault acted (or before a phase onset was placed: the gait never started). Each with its measured
    value over its limit (else the test fails here)."""
    fault = s["faults"][0] if s["faults"] else None
    if fault == "WATCHDOG":
        hw = s["host_watchdog"]
        assert hw["fired"] and hw["silent_ms"] >= hw["timeout_ms"], hw
        return True
    if fault in ("COMMAND_STALE", "IMU_TIMEOUT") or (fault == "MOTOR_TIMEOUT" and (
            onset_s is None or s["fault"]["at_s"] <= onset_s)):  # None: tripped before the gait placed the onset
        assert_age_over_limit(s["fault"]["detail"])
        return True
    return False


def _log_seconds(caplog, pattern: str) -> float | None:
    """The seconds a fault:// WARNING matching pattern names (its first group), or None if none did."""
    for r in caplog.records:
        m = re.search(pattern, r.getMessage())
        if m:
            return float(m.group(1))
    return None


def _run_with_lost_replies(tmp_path: Path, caplog, onset: str) -> tuple[int, dict, Path, float, float]:
    """`pafp run` on the emulated bench with the motor's replies lost for 1 s from `onset`; a run a host stall
    faulted before the fault acted is run again (up to ATTEMPTS times). (exit code, summary, capture, onset, first
    loss) on the firmware's clock."""
    for attempt in range(ATTEMPTS):
        out, capture = tmp_path / f"out{attempt}", tmp_path / f"capture{attempt}"
        caplog.clear()
        proc, motor, imu = _emulator(20.0)
        try:
            code = main(["run", "--motor", f"fault://{motor}?fault=motor_replies_lost&{onset}&duration=1", "--imu",
                         imu, "--duration", "3", "--out", str(out), "--quiet", "--capture", str(capture),
                         "--no-plot", "--no-trace"])  # what is read here: the summary, the capture, the log
        finally:
            _stop(proc)
        s = _summary(out)
        onset_s = (float(onset[3:]) if onset.startswith("at=")
                   else _log_seconds(caplog, r"placed at gait phase [0-9.]+: at ([0-9.]+) s"))
        if not _host_stall(s, onset_s):
            break
    else:
        pytest.fail(f"{ATTEMPTS} runs in a row faulted by measured host stalls before the fault acted (the last: "
                    f"{s['faults']} {s['fault']}): the fault is untested on this host")
    first_s = _log_seconds(caplog, r"fault://: motor_replies_lost acts from ([0-9.]+) s \(on the firmware's clock\)")
    assert first_s is not None, "the fault never acted: the run tested nothing"  # an error, never a pass
    assert onset_s is not None and onset_s <= first_s < onset_s + 1.0
    return code, s, capture, onset_s, first_s


def _assert_motor_timeout_made_safe(code: int, s: dict, capture: Path, first_s: float) -> None:
    """MOTOR_TIMEOUT latched while the replies were lost, its measured age over 20 ms; the capture of what the
    firmware sent ends with zero current, then the shipped safe state (graded: duty 0, the phase short), and
    nothing else."""
    assert code == 1 and s["faults"] == ["MOTOR_TIMEOUT"], (s["faults"], s["fault"])
    assert first_s <= s["fault"]["at_s"] < first_s + 1.0, (first_s, s["fault"])  # tripped in the window
    assert s["fault"]["detail"].endswith("> 20.0 ms")
    assert_age_over_limit(s["fault"]["detail"])
    frames = Decoder("to-motor").feed((capture / "motor.tx.bin").read_bytes())
    commands = [f for f in frames if isinstance(f, (SetCurrent, SetCurrentBrake, SetDuty))]
    first_zero = max((i for i, f in enumerate(commands) if isinstance(f, SetCurrent) and f.current_a != 0.0),
                     default=-1) + 1  # under load the run may reach the fault before it commanded any current
    assert commands[-1] == SetDuty(0.0), commands[-3:]
    assert all(f in (SetCurrent(0.0), SetDuty(0.0)) for f in commands[first_zero:]), commands[first_zero:][:5]


@pytest.mark.skipif(sys.platform == "win32", reason="ptys")
@pytest.mark.parametrize("onset", ["at=1.5", "phase=0.3"])
def test_motor_replies_lost_on_the_emulated_bench_is_detected_and_made_safe(tmp_path: Path, caplog, onset):
    """The issue's end-to-end case: fault:// around the pty of `pafp emulate bench`, replies lost from 1.5 s after
    the firmware started, or from 30 % of the first stride on the firmware's gait clock."""
    code, s, capture, _, first_s = _run_with_lost_replies(tmp_path, caplog, onset)
    if onset.startswith("phase"):
        assert any("placed at gait phase 0.3" in r.getMessage() for r in caplog.records)
    _assert_motor_timeout_made_safe(code, s, capture, first_s)


@pytest.mark.skipif(sys.platform == "win32", reason="ptys")
def test_a_slow_start_up_leaves_the_window_on_the_firmware_clock(tmp_path: Path, caplog, monkeypatch):
    """A scripted host stall of 2.2 s between the ports' checks and the firmware's start. Counted from the port's
    open, at=1.5 put the whole window into the firmware's first 0.3 s, its start-up grace, where a motor not yet
    heard from is rightly no fault: the run latched nothing (seen twice on a loaded host). On the firmware's clock
    the replies are lost from its 1.5 s and MOTOR_TIMEOUT latches."""
    from host_tools.serial_mode import serial_run

    checked = serial_run.check_imu

    def check_then_stall(*args, **kwargs):
        seen = checked(*args, **kwargs)
        time.sleep(2.2)
        return seen

    monkeypatch.setattr(serial_run, "check_imu", check_then_stall)
    code, s, capture, _, first_s = _run_with_lost_replies(tmp_path, caplog, "at=1.5")
    _assert_motor_timeout_made_safe(code, s, capture, first_s)


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

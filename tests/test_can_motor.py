"""The AK60-6 over CAN on the virtual bench (servo and MIT mode) with the firmware's CAN drivers."""

from __future__ import annotations

import math

import pytest

from firmware.drivers.can_mit import CanMitDriver
from firmware.drivers.can_servo import CanServoDriver
from hal.can import CanFrame
from hal.virtual.bench import VirtualBench
from protocol import can_mit

F_CPU = 168_000_000


class _Clock:
    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


def _bench(link: str) -> tuple[VirtualBench, _Clock]:
    clock = _Clock()
    return VirtualBench(clock, F_CPU, fixture="suspended", motor_link=link), clock


def _run(drv, clock: _Clock, seconds: float, current_a: float, *, start_s: float = 0.0) -> None:
    """Poll and send every millisecond, as the motor task does."""
    for k in range(int(seconds * 1000)):
        now_s = start_s + k / 1000
        clock.t = int(now_s * F_CPU) + 1
        drv.poll(now_s)
        drv.send(current_a, now_s)


def test_mit_torque_moves_the_output_and_each_command_is_answered():
    bench, clock = _bench("can-mit")
    drv = CanMitDriver(bench.can, 1)
    _run(drv, clock, 0.05, 0.0)
    p0 = drv.feedback.position_rad
    _run(drv, clock, 0.2, 3.0, start_s=0.05)
    assert bench.motor_device.motor_mode
    assert drv.feedback.position_rad - p0 > 0.05  # positive torque, the foot turns the positive way
    assert drv.feedback.current_a == pytest.approx(3.0, abs=0.3)
    assert drv.stats.requests == 250 and drv.stats.replies >= 249 and drv.stats.missing_replies == 0
    assert drv.stats.max_age_s <= 0.0011  # answered within the period
    assert bench.can.errors.overruns == 0 and bench.can_bus.frames >= 2 * 250


def test_mit_commands_before_enter_motor_mode_are_ignored():
    bench, clock = _bench("can-mit")
    clock.t = 1000
    assert bench.can.send(CanFrame(1, can_mit.encode_command(can_mit.MitCommand(t_ff=5.0))))
    clock.t = int(0.1 * F_CPU)
    bench.advance_to(clock.t)
    assert bench.motor_device.ignored_frames == 1 and not bench.motor_device.motor_mode
    assert abs(bench.motor.meter.current_a) < 1e-6


def test_mit_law_runs_in_the_driver_position_hold():
    bench, clock = _bench("can-mit")
    port = bench.can
    clock.t = 1000
    port.send(CanFrame(1, can_mit.ENTER_MOTOR_MODE))
    port.send(CanFrame(1, can_mit.SET_ZERO))
    for k in range(400):  # a stiff spring about +0.3 rad, refreshed at 1 kHz
        clock.t = int((0.001 + k / 1000) * F_CPU)
        port.send(CanFrame(1, can_mit.encode_command(can_mit.MitCommand(p_des=0.3, kp=20.0, kd=0.5))))
        while port.receive() is not None:
            pass
    assert bench.motor.pid_pos_deg() == pytest.approx(math.degrees(0.3), abs=3.0)


def test_mit_stop_sends_zero_torque_then_exit_and_releases():
    bench, clock = _bench("can-mit")
    drv = CanMitDriver(bench.can, 1)
    _run(drv, clock, 0.05, 2.0)
    clock.t = int(0.06 * F_CPU)
    stop = drv.send_stop(0.06, 5.0)
    assert stop.frames == can_mit.encode_command(can_mit.MitCommand()) + can_mit.EXIT_MOTOR_MODE
    assert stop.written == 16 and not stop.error
    clock.t = int(0.07 * F_CPU)
    bench.advance_to(clock.t)
    assert not bench.motor_device.motor_mode and bench.motor.mode.value == "released"


def test_servo_current_is_read_back_in_the_status_frames():
    bench, clock = _bench("can-servo")
    drv = CanServoDriver(bench.can, 1)
    _run(drv, clock, 0.1, 2.0)
    assert drv.feedback.current_a == pytest.approx(2.0, abs=0.05)
    assert drv.stats.replies == pytest.approx(0.1 * 500, abs=2)  # status frames at 500 Hz, no request
    assert 0.0019 <= drv.stats.max_age_s <= 0.0031


def test_servo_stop_sends_zero_current_then_the_brake():
    bench, clock = _bench("can-servo")
    drv = CanServoDriver(bench.can, 1)
    _run(drv, clock, 0.05, 2.0)
    stop = drv.send_stop(0.05, 4.0)
    assert stop.frames.hex() == "00000000" + "00000fa0" and stop.written == 8
    clock.t = int(0.06 * F_CPU)
    bench.advance_to(clock.t)
    assert bench.motor.mode.value == "brake"


def test_a_silent_bus_is_a_lost_link_for_the_supervisor():
    from firmware.safety import FaultReason
    from host_tools.runner import RunConfig, run_virtual

    def silence(bench, fw) -> None:
        bench.motor_device.bus = None  # the motor falls silent: nothing more from it on the bus

    from firmware.config import load_firmware_config
    fw_cfg = load_firmware_config().with_changes(motor_link="can-servo")
    r = run_virtual(RunConfig(strides=1, firmware=fw_cfg, settle_s=0.3, actions=[(0.9, silence)],
                              trace_capacity=0))
    assert r.firmware.supervisor.reason is FaultReason.MOTOR_TIMEOUT


def test_the_link_is_chosen_by_name_and_a_bad_name_is_one_line(tmp_path, capsys):
    from firmware.config import load_firmware_config
    from host_tools.cli import main

    assert load_firmware_config().motor_link == "uart"
    from firmware.config import DEFAULT_PROFILE

    profile = DEFAULT_PROFILE.read_text()
    assert 'link = "uart"' in profile
    bad = tmp_path / "p.toml"
    bad.write_text(profile.replace('link = "uart"', 'link = "rs485"'))
    with pytest.raises(ValueError,
                       match="\\[motor\\] link 'rs485' unknown: one of \\['can-mit', 'can-servo', 'uart'\\]"):
        load_firmware_config(bad)
    bad.write_text(profile.replace('link = "uart"', 'speed = 1'))
    with pytest.raises(ValueError, match="\\[motor\\] has no key 'speed'"):
        load_firmware_config(bad)
    assert main(["run", "--motor-link", "rs485", "--strides", "1", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["pafp run: --motor-link 'rs485' unknown: one of ['can-mit', 'can-servo', 'uart']"]


@pytest.mark.parametrize("link", ["can-servo", "can-mit"])
def test_can_runs_track_and_are_deterministic(link):
    from firmware.config import load_firmware_config
    from host_tools.reports.report import summarise
    from host_tools.runner import RunConfig, run_virtual

    fw_cfg = load_firmware_config().with_changes(motor_link=link)
    runs = [run_virtual(RunConfig(strides=1, seed=7, firmware=fw_cfg, trace_capacity=0)) for _ in range(2)]
    assert runs[0].telemetry == runs[1].telemetry  # same seed, byte-identical telemetry
    s = summarise(runs[0])
    assert not s["faults"] and s["deadline_misses"] == 0
    # tracks the reference as well as the UART link on the same bench (seed 7 draws an IMU bias and an
    # encoder offset that set the truth RMS near 1.1 deg on every link; 0.14 deg with --ideal all)
    uart = summarise(run_virtual(RunConfig(strides=1, seed=7, trace_capacity=0)))
    truth, uart_truth = s["tracking"]["truth"]["rms_deg"], uart["tracking"]["truth"]["rms_deg"]
    assert truth <= 1.05 * uart_truth, (truth, uart_truth)
    assert s["motor_link"]["link"] == link and s["motor_link"]["rx_overruns"] == 0
    assert 0.0 < s["motor_link"]["bus_load"] < 0.5


def test_emulate_can_serves_the_motor_not_the_imu_alone(capsys):
    from host_tools.cli import main

    for device in ("imu", "ground"):
        assert main(["emulate", device, "--can", "can://virtual/x?id=1&mode=mit"]) == 2
        assert capsys.readouterr().err.strip() == (f"pafp emulate: --can serves the motor, not `{device}`: "
                                                   "`motor --can URL`, or `bench --can URL` with the IMU on a pty")
    assert main(["emulate", "motor", "--can", "can://virtual/x?id=1&mode=foc"]) == 2
    assert "mode='foc' not one of ('servo', 'mit')" in capsys.readouterr().err


def test_a_new_link_is_one_registry_entry():
    """A link registered under a new name drives both sides (firmware driver, bench wiring) with no other edit."""
    from firmware.config import load_firmware_config
    from firmware.drivers.motor_links import MOTOR_LINKS
    from hal.virtual.wiring import MOTOR_WIRING
    from host_tools.runner import RunConfig, run_virtual

    MOTOR_LINKS.register("uart-again", "firmware.drivers.motor:MotorDriver")
    MOTOR_WIRING.register("uart-again", "hal.virtual.wiring:wire_uart_motor")
    try:
        base = load_firmware_config()
        runs = [run_virtual(RunConfig(strides=1, firmware=base.with_changes(motor_link=link), trace_capacity=0))
                for link in ("uart", "uart-again")]
    finally:
        MOTOR_LINKS.unregister("uart-again")
        MOTOR_WIRING.unregister("uart-again")
    assert runs[1].bench.motor_link == "uart-again"
    assert runs[0].telemetry == runs[1].telemetry
    with pytest.raises(ValueError, match=r"motor_link 'uart-again' unknown: one of \['can-mit', 'can-servo', 'uart'\]"):
        base.with_changes(motor_link="uart-again")

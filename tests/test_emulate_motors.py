"""Any catalogue motor on the wire: `pafp emulate --motor NAME` / `--profile DESIGN.toml` serve that motor's Kt,
ratio, pole pairs, peak current, thermal model and CAN ranges over UART, CAN servo and CAN MIT (issue 37)."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from hal.can import CanFrame
from hal.pycan import CanUrl
from hal.serial.sim_port import WallDevices
from hal.virtual.devices.ak60_can import Ak60CanConfig
from hal.virtual.plant.motors import load_motor
from host_tools.cli import main
from host_tools.serial_mode.can_emulate import WallCanMotor
from host_tools.serial_mode.served_plant import served_plant
from protocol import can_mit, can_servo, vesc

ROOT = Path(__file__).resolve().parents[1]


class _Port:
    def __init__(self) -> None:
        self.waiting: list[CanFrame] = []
        self.sent: list[CanFrame] = []

    def receive(self) -> CanFrame | None:
        return self.waiting.pop(0) if self.waiting else None

    def send(self, frame: CanFrame) -> bool:
        self.sent.append(frame)
        return True


def _can_motor(name: str, mode: str) -> tuple[WallCanMotor, list[int]]:
    served = served_plant(motor=name)
    clock = [0]
    m = WallCanMotor(_Port(), CanUrl("t", "x", 1, mode), "suspended", lambda: clock[0], plant_options=served.options,
                     can_config=Ak60CanConfig(driver_id=1, mode=mode, limits=served.limits))
    served.attach_thermal(m.device.core.meter)
    return m, clock


def _run(m: WallCanMotor, clock: list[int], ms: float, *frames: CanFrame) -> None:
    m.port.waiting.extend(frames)
    end = clock[0] + round(ms * 1e6)
    while clock[0] < end:
        clock[0] += 1_000_000
        m.step()


@pytest.mark.parametrize("name", ["ak60_6", "ak80_9", "ak10_9"])
def test_servo_speed_and_current_follow_the_motor(name: str) -> None:
    """SET_RPM in ERPM: the rotor turns at ERPM / pole pairs, the output at that / ratio (both the motor's)."""
    spec = load_motor(name)
    m, clock = _can_motor(name, "servo")
    assert m.device.core.params.kt_nm_per_a == spec.kt_nm_per_a
    _run(m, clock, 300, CanFrame((3 << 8) | 1, struct.pack(">i", 2100), True))
    before = m.device.core.pid_pos_deg()
    _run(m, clock, 100, CanFrame((3 << 8) | 1, struct.pack(">i", 2100), True))
    out_deg_s = (m.device.core.pid_pos_deg() - before) / 0.1
    assert out_deg_s == pytest.approx(2100 / spec.pole_pairs / 60 * 360 / spec.gear_ratio, rel=0.05)
    last = can_servo.decode_status(m.port.sent[-1].data)
    assert last.speed_erpm == pytest.approx(2100, abs=60)


def test_servo_current_is_clamped_at_the_motors_peak() -> None:
    """40 A asked: the drive's current target is the AK80-9's peak, and the current never goes above it (the measured
    current itself is soon capped lower by the free rotor's back-EMF, which depends on the rotor's inertia)."""
    m, clock = _can_motor("ak80_9", "servo")  # peak 28 A (the AK60-6: 22.7 A)
    peak = 0.0
    for _ in range(20):
        _run(m, clock, 1, CanFrame((1 << 8) | 1, struct.pack(">i", 40_000), True))
        peak = max(peak, m.device.core.meter.current_a)
    assert m.device.core.meter.target_a == pytest.approx(28.0)
    assert 20.0 < peak <= 28.0 + 1e-9


def test_mit_torque_uses_the_motors_kt_ratio_and_ranges() -> None:
    """t_ff = 16 N m (beyond the AK60-6's 15 N m range, inside the AK80-9's 18): q current = 16 / (Kt x 9)."""
    spec = load_motor("ak80_9")
    m, clock = _can_motor("ak80_9", "mit")
    lim = m.device.limits
    assert (lim.p_max, lim.v_max, lim.t_max) == (spec.p_max_rad, spec.v_max_rad_s, spec.t_max_nm)
    enter = CanFrame(1, can_mit.ENTER_MOTOR_MODE)
    cmd = CanFrame(1, can_mit.encode_command(can_mit.MitCommand(t_ff=16.0), lim))
    _run(m, clock, 1, enter)
    _run(m, clock, 30, cmd)
    _run(m, clock, 2, cmd)  # its reply (50 us later) reports the torque reached
    amps = 16.0 / (spec.kt_nm_per_a * spec.gear_ratio)
    meter = m.device.core.meter
    assert meter.target_a == pytest.approx(amps, rel=0.01)  # the free rotor's back-EMF caps the current it reaches
    replies = [can_mit.decode_reply(f.data, lim) for f in m.port.sent if f.arbitration_id == can_mit.MASTER_ID]
    assert 0.0 < replies[-1].t <= 16.0 + 0.05  # in the AK80-9's range (the AK60-6's 15 N m would have clipped 16)


def test_thermal_model_is_the_motors() -> None:
    m, clock = _can_motor("ak80_9", "servo")
    winding = m.device.core.meter._winding
    assert winding is not None and winding.params.winding_heat_capacity_j_per_k == pytest.approx(16.3)
    _run(m, clock, 2000, CanFrame((1 << 8) | 1, struct.pack(">i", 20_000), True))
    s = can_servo.decode_status(m.port.sent[-1].data)
    assert s.temperature_c > 26  # 20 A in 0.16 Ohm heats the winding's 16.3 J/K within 2 s


@pytest.mark.parametrize("name", ["ak80_9", "ak70_10"])
def test_uart_serves_the_motor(name: str) -> None:
    spec = load_motor(name)
    served = served_plant(motor=name)
    clock = [0]
    devices = WallDevices(["motor"], fixture="suspended", clock_ns=lambda: clock[0], **served.options)
    served.attach_thermal(devices.motor.meter)
    uart = devices.uarts["motor"]
    uart.write(vesc.SetRpm(2100).encode())
    clock[0] = 400_000_000
    uart.write(vesc.GetValues().encode())
    clock[0] = 410_000_000
    (values,) = vesc.Decoder("from-motor").feed(uart.read())
    assert values.erpm == pytest.approx(2100, abs=60)
    assert devices.motor.params.pole_pairs == spec.pole_pairs and devices.motor.params.gearbox_ratio == spec.gear_ratio
    devices.close()


def test_a_design_profile_serves_its_motor_and_belt() -> None:
    served = served_plant(profile=ROOT / "profiles" / "designs" / "adult_80kg.toml")
    from hal.virtual.plant.design import load_design

    design = load_design(ROOT / "profiles" / "designs" / "adult_80kg.toml")
    p = served.options["plant_params"]
    assert p.gearbox_ratio == design.motor_spec().gear_ratio and math.isclose(p.belt_ratio, design.belt_ratio)


def test_bad_motor_or_profile_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "motor", "--pty", "--motor", "ak99_1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ak99_1" in err[0] and "ak80_9" in err[0]
    assert main(["emulate", "motor", "--pty", "--motor", "ak80_9", "--profile", "x.toml"]) == 2
    assert "give one" in capsys.readouterr().err

"""AK60-6 driver model, drive side: control modes, inner loops, thermal model, faults and their injection."""

from __future__ import annotations

import math

import pytest
from test_ak60 import F, Rig

from hal.virtual.devices.ak60 import DriveMode
from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.plant.thermal import COPPER_LOSS_FACTOR
from protocol.vesc import (
    FaultCode,
    GetValues,
    GetValuesSelective,
    SetCurrent,
    SetCurrentBrake,
    SetCurrentRel,
    SetDuty,
    SetPos,
    SetPosOrigin,
    SetPosSingle,
    SetPosSpd,
    SetRpm,
    Values,
)

POS_ERPM = GetValuesSelective((1 << 7) | (1 << 15) | (1 << 16)).encode()


def values_at(rig: Rig, t_s: float) -> Values:
    rig.at(t_s)
    rig.send(GetValues().encode())
    rig.at(t_s + 0.002)
    (v,) = [m for m in rig.replies() if isinstance(m, Values)]
    return v


def hold_current(rig: Rig, current_a: float, until_s: float, every_s: float = 0.25) -> None:
    """Command current_a repeatedly (inside the 1 s timeout) until until_s."""
    t = rig.t / F
    while t < until_s:
        rig.at(t)
        rig.send(SetCurrent(current_a).encode())
        t += every_s
    rig.at(until_s)


def test_current_is_clamped_to_the_peak_and_rel_is_relative_to_it() -> None:
    rig = Rig(initial_angle_rad=0.6283)  # pressed against the dorsiflexion stop: no back-EMF
    rig.send(SetCurrent(40.0).encode())
    rig.at(0.02)
    rig.world.advance_to(rig.t)
    assert math.isclose(rig.plant.current_q_a(rig.t / F), 22.7, rel_tol=1e-6)
    end = rig.send(SetCurrentRel(0.5).encode())
    rig.world.advance_to(end)
    assert rig.plant.state_at(end / F).current_command_a == pytest.approx(11.35)


def test_thermal_model_heats_with_current_first_order() -> None:
    cfg = Ak60Config()
    rig = Rig(cfg)
    hold_current(rig, 20.0, 4.0)
    v = values_at(rig, 4.0)
    tau_w, tau_f = cfg.thermal_time_constants_s
    r = rig.plant.params.phase_resistance_ohm
    k = COPPER_LOSS_FACTOR  # the q current's loss per ohm line to line: 0.75, not the DC current's 1
    rise_w = k * r * 400.0 * cfg.winding_thermal_resistance_k_per_w * (1 - math.exp(-4.0 / tau_w))
    rise_f = k * cfg.fet_resistance_ohm * 400.0 * cfg.fet_thermal_resistance_k_per_w * (1 - math.exp(-4.0 / tau_f))
    assert v.temp_motor_c == pytest.approx(25.0 + rise_w, abs=0.15)
    assert v.temp_fet_c == pytest.approx(25.0 + rise_f, abs=0.15)
    assert v.watt_hours > 0 and v.amp_hours > 0
    idle = values_at(Rig(), 4.0)
    assert idle.temp_motor_c == idle.temp_fet_c == 25.0


def test_over_temperature_fault_releases_the_motor() -> None:
    rig = Rig(Ak60Config(temp_motor_max_c=28.0))  # 20 A for 2.5 s: about 4.5 K on the single node
    hold_current(rig, 20.0, 2.5)
    v = values_at(rig, 2.5)
    assert v.fault == FaultCode.OVER_TEMP_MOTOR and v.temp_motor_c > 27.5  # cooling since it tripped
    assert rig.motor.mode is DriveMode.RELEASED
    assert rig.motor.stats.ignored_commands > 0


def test_injected_fault_is_reported_held_and_then_cleared() -> None:
    rig = Rig()
    rig.send(SetCurrent(1.0).encode())
    rig.motor.inject_fault(FaultCode.DRV, 0.05)
    v = values_at(rig, 0.06)
    assert v.fault == FaultCode.DRV
    assert rig.plant.state_at(rig.t / F).current_command_a == 0.0
    rig.send(SetCurrent(2.0).encode())
    rig.world.advance_to(rig.t + F // 100)
    assert rig.motor.stats.ignored_commands == 1 and rig.motor.mode is DriveMode.RELEASED
    v = values_at(rig, 0.56)
    assert v.fault == 0
    end = rig.send(SetCurrent(2.0).encode())
    rig.world.advance_to(end)
    assert rig.motor.mode is DriveMode.CURRENT


def test_fault_injection_rejects_bad_arguments() -> None:
    rig = Rig()
    rig.at(0.1)
    rig.uart.in_waiting()  # the world is now at 0.1 s
    with pytest.raises(ValueError, match="past"):
        rig.motor.inject_fault(FaultCode.DRV, 0.05)
    with pytest.raises(ValueError, match="1..255"):
        rig.motor.inject_fault(0, 0.2)


def test_under_voltage_from_the_supply() -> None:
    rig = Rig()
    rig.motor.set_supply_voltage(6.0, 0.02)
    v = values_at(rig, 0.03)
    assert v.fault == FaultCode.UNDER_VOLTAGE and v.v_in_v == pytest.approx(6.0, abs=0.1)


def _erpm_now(rig: Rig, t_s: float) -> tuple[int, float]:
    rig.at(t_s)
    rig.send(POS_ERPM)
    rig.at(t_s + 0.001)
    (m,) = rig.replies()
    return m.values["erpm"], math.degrees(m.values["pid_pos_rad"])


def test_speed_mode_reaches_the_erpm() -> None:
    rig = Rig()
    rig.send(SetRpm(2000).encode())
    erpm, _ = _erpm_now(rig, 0.3)
    assert erpm == pytest.approx(2000, rel=0.05)


def test_position_mode_goes_to_the_target_and_respects_the_speed_limit() -> None:
    rig = Rig()  # pid_pos starts at 0 (rotor at 0)
    rig.send(SetPosSpd.from_degrees(90.0, 5000, 30000).encode())
    peak = 0
    for k in range(1, 46):  # 0.9 s: within the 1 s command timeout
        erpm, pos = _erpm_now(rig, 0.02 * k)
        peak = max(peak, abs(erpm))
    assert pos == pytest.approx(90.0, abs=0.5)
    assert 4000 < peak <= 5500


def test_plain_set_pos_uses_the_default_limits() -> None:
    rig = Rig(initial_angle_rad=0.1)
    _, start = _erpm_now(rig, 0.001)
    rig.send(SetPos.from_degrees(start - 30.0).encode())
    _, pos = _erpm_now(rig, 0.9)
    assert pos == pytest.approx(start - 30.0, abs=0.5)


def test_duty_mode_drives_forward() -> None:
    rig = Rig()
    rig.send(SetDuty(0.2).encode())
    erpm, _ = _erpm_now(rig, 0.1)
    assert erpm > 1000 and rig.motor.mode is DriveMode.DUTY


def test_brake_slows_the_falling_foot() -> None:
    free, braked = Rig(initial_angle_rad=0.6), Rig(initial_angle_rad=0.6)
    braked.send(SetCurrentBrake(15.0).encode())
    a_free, _ = free.plant_at(round(0.15 * F))
    a_braked, _ = braked.plant_at(round(0.15 * F))
    assert a_braked > a_free + 1.0  # rotor radians: the brake held the foot back


def test_origin_and_single_turn() -> None:
    rig = Rig(initial_angle_rad=0.5)
    _, pos = _erpm_now(rig, 0.01)
    assert pos == pytest.approx(math.degrees(0.5 * 28 / 6), abs=1.0)
    rig.send(SetPosOrigin(0).encode())
    _, pos0 = _erpm_now(rig, 0.02)
    assert abs(pos0) < 1.0
    rig.send(SetPosOrigin(2).encode())
    rig.send(SetPosSingle().encode())
    _, single = _erpm_now(rig, 0.03)
    assert 0.0 <= single < 360.0


@pytest.mark.parametrize(("field", "value"), [("timeout_s", True), ("timeout_s", -1.0), ("max_duty", math.nan)])
def test_config_refuses_a_value_outside_its_range_naming_it(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=rf"Ak60Config\.{field} = {value!r} is outside the allowed range"):
        Ak60Config(**{field: value})  # type: ignore[arg-type]

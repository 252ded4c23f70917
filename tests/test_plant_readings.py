"""The driver and geometry readings of the plant (hal.virtual.plant.readings, Plant(driver=...))."""

import math

import pytest

from hal.virtual.plant import Plant, load_plant_params
from hal.virtual.plant.readings import check_reading, geometry_of, with_geometry


def test_geometry_readings_are_profile_values():
    p = load_plant_params()
    assert geometry_of(p) == "level-com"
    hanging = with_geometry(p, "hanging")
    assert geometry_of(hanging) == "hanging" and hanging.com_angle_at_zero_rad == 0
    with pytest.raises(ValueError, match="geometry reading 'upside-down' unknown"):
        with_geometry(p, "upside-down")
    with pytest.raises(ValueError, match="reading kind"):
        check_reading("belt", "x")


def test_voltage_amplifier_driver_drives_the_winding_current_towards_v_minus_emf_over_r():
    # Report eq 3.41 as a voltage amplifier: the PID's +-1 is +-24 V; the current goes to (V - K_e N w)/R
    # with one lag of tau_amp + L/R (1.14 + 0.68 ms), clamped to the peak current.
    p = load_plant_params()
    plant = Plant(p, driver="voltage-amplifier")
    plant.set_voltage_command(0.05, 0.0)  # 1.2 V
    tau = p.current_time_constant_s + p.phase_inductance_h / p.phase_resistance_ohm
    i_tau = plant.current_q_a(tau)
    target = 0.05 * p.supply_voltage_v / p.phase_resistance_ohm
    assert i_tau == pytest.approx(target * (1 - math.exp(-1)), rel=0.05)  # the motor barely moves in 1.8 ms
    s = plant.state_at(0.5)
    steady = (0.05 * p.supply_voltage_v - p.ke_v_s_per_rad * p.total_ratio * s.output_velocity_rad_s) \
        / p.phase_resistance_ohm
    assert s.current_q_a == pytest.approx(steady, abs=0.05)
    stall = Plant(p, driver="voltage-amplifier")
    stall.set_voltage_command(5.0, 0.0)  # clamped to +1: 24 V / 0.202 Ohm = 119 A, clamped to the peak
    assert stall.current_q_a(0.01) == pytest.approx(p.peak_current_a, rel=0.01)
    with pytest.raises(ValueError, match="set_voltage_command"):
        stall.set_current_command(1.0, 0.02)
    with pytest.raises(ValueError, match="driver='voltage-amplifier'"):
        Plant(p).set_voltage_command(0.1, 0.0)
    with pytest.raises(ValueError, match="driver reading"):
        Plant(p, driver="pwm")


def test_voltage_amplifier_at_zero_shorts_the_winding_and_brakes_the_fall():
    # Zero output shorts the winding through the amplifier: the back-EMF brakes the unpowered-like fall that
    # the open bridge lets happen (the foot reaches the -30 deg stop within 0.5 s only with the bridge open).
    p = load_plant_params()
    shorted = Plant(p, initial_angle_rad=math.pi / 5, driver="voltage-amplifier")
    shorted.set_voltage_command(0.0, 0.0)
    open_bridge = Plant(p, initial_angle_rad=math.pi / 5)
    open_bridge.set_powered(False, 0.0)
    assert open_bridge.output_angle_rad(0.5) < p.stop_min_rad + 0.02
    assert shorted.output_angle_rad(0.5) > 0.5
    off = Plant(p, initial_angle_rad=math.pi / 5, driver="voltage-amplifier")
    off.set_powered(False, 0.0)  # powered off: the bridge open whatever the driver
    assert off.output_angle_rad(0.5) == pytest.approx(open_bridge.output_angle_rad(0.5), abs=1e-12)

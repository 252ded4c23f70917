"""Belt compliance (hal/virtual/plant/belt.py): off, the plant is the rigid one bit for bit; on, a static torque
stretches the belt by what k predicts, the motor-on-belt mode rings at its natural frequency, the step resolves it,
and energy is kept where nothing dissipates."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from hal.virtual.plant import Plant, load_plant_params, suspended
from hal.virtual.plant.belt import motor_side_inertia_kg_m2
from hal.virtual.plant.imperfections import active, profile_text
from hal.virtual.plant.params import load_plant_params as load_file

BASE = load_plant_params()
BELT = {"belt_stiffness_n_per_mm": 2000.0, "belt_width_mm": 10.0, "belt_center_distance_m": 0.080}
# no friction, no gravity, no foot damping: the belt alone decides the motion
FREE = replace(BASE, coulomb_friction_nm=0.0, actuator_backdrive_torque_nm=0.0, gravity_m_s2=0.0,
               foot_damping_nm_s_per_rad=0.0, **BELT)


def _stretch(plant: Plant, t: float) -> float:
    """The belt's stretch at the ankle as the sensors see it: the drive's rotor angle / N minus the ankle angle."""
    _, _, rotor = plant.motor_sample(t)
    return rotor / plant.params.total_ratio - plant.output_angle_rad(t)


def test_off_by_default_and_at_zero_stiffness_bit_identical():
    assert "belt_compliance" not in active(BASE) and BASE.belt_stiffness_nm_per_rad == 0.0
    assert Plant(BASE)._c.imp_energy is None
    runs = []
    for p in (BASE, replace(BASE, belt_width_mm=25.0, belt_center_distance_m=0.2, belt_damping_ratio=0.5)):
        plant = Plant(p, suspended())
        out = []
        for k, t in enumerate(np.linspace(0.0, 0.6, 31)):
            plant.set_current_command(2.0 * math.sin(11.0 * t) + (0.5 if k % 6 < 3 else -0.5), t)
            out.append((plant.state_at(t + 3e-5), plant.motor_sample(t + 7e-5)))
        runs.append(out)
    assert runs[0] == runs[1]


def test_stiffness_at_the_ankle_is_two_spans_of_ea_over_l():
    p = replace(BASE, **BELT)
    span = math.sqrt(0.080**2 - (0.5 * (0.089127 - 0.0191)) ** 2)
    assert p.belt_span_m == pytest.approx(span, rel=1e-12)
    assert p.belt_stiffness_nm_per_rad == pytest.approx(2.0 * 20e3 / span * 0.0445635**2, rel=1e-12)
    assert p.belt_stiffness_nm_per_rad == pytest.approx(1104.3, abs=0.1)
    assert active(p) == ("belt_compliance",)


@pytest.mark.parametrize("current_a", [5.0, -3.0])
def test_a_static_torque_stretches_the_belt_by_torque_over_k(current_a):
    """The motor side at rest passes its whole torque K_t N eta i to the belt: stretch = K_t N eta i / k, seen as the
    difference of the drive's rotor angle / N and the ankle's (the foot held on its stop)."""
    plant = Plant(FREE, suspended())
    plant.set_current_command(current_a, 0.0)
    expected = FREE.output_torque_per_amp_nm * current_a / FREE.belt_stiffness_nm_per_rad
    assert abs(expected) > 0.004  # a quarter of a degree and more: far above rounding
    assert _stretch(plant, 2.0) == pytest.approx(expected, rel=0.01)
    assert not FREE.stop_min_rad < plant.output_angle_rad(2.0) < FREE.stop_max_rad  # held by the stop


@pytest.mark.parametrize("more", [{}, {"stribeck_peak_nm": 0.415, "ripple_amplitude_nm": 0.025}])
def test_with_friction_the_stretch_is_within_breakaway_over_k(more):
    """The motor side's friction (and ripple, with the others on) holds at most breakaway + ripple off the belt."""
    p = replace(BASE, **BELT, **more)
    assert set(active(p)) == {"belt_compliance"} | ({"stribeck", "torque_ripple"} if more else set())
    plant = Plant(p, suspended())
    plant.set_current_command(5.0, 0.0)
    torque = p.output_torque_per_amp_nm * 5.0
    held = max(p.static_friction_nm, p.coulomb_friction_nm + p.stribeck_peak_nm) + p.ripple_amplitude_nm
    off = _stretch(plant, 2.0) * p.belt_stiffness_nm_per_rad - torque
    assert abs(off) <= held * 1.001 and plant.state_at(2.0).motor_velocity_rad_s == 0.0


def _ring(params, step_s=1e-4, t_end=0.15, n=6001):
    """The stretch under a small current from the start, the belt unstretched then (the foot free, far from its
    stops), sampled at n points."""
    plant = Plant(params, suspended(), step_s=step_s, initial_current_a=0.5)
    plant.set_current_command(0.5, 0.0)
    ts = np.linspace(0.0, t_end, n)
    return ts, np.array([_stretch(plant, t) for t in ts])


def test_the_motor_on_belt_mode_rings_at_its_natural_frequency():
    """Free-free two masses on the belt: omega_n = sqrt(k / J_red), damped by the belt's ratio zeta."""
    zeta = 0.05
    p = replace(FREE, belt_damping_ratio=zeta)
    j_ms = motor_side_inertia_kg_m2(p)
    j_red = j_ms * (p.output_inertia_kg_m2 - j_ms) / p.output_inertia_kg_m2
    f_n = math.sqrt(p.belt_stiffness_nm_per_rad / j_red) / (2.0 * math.pi)
    assert 45.0 < f_n < 52.0  # the AK60-6 bench's belt mode
    ts, d = _ring(p)
    x = d - p.output_torque_per_amp_nm * 0.5 * (1.0 - j_ms / p.output_inertia_kg_m2) / p.belt_stiffness_nm_per_rad
    up = np.nonzero((x[:-1] < 0.0) & (x[1:] >= 0.0))[0]
    crossings = ts[up] - x[up] * (ts[up + 1] - ts[up]) / (x[up + 1] - x[up])
    assert len(crossings) >= 5
    f_d = (len(crossings) - 1) / (crossings[-1] - crossings[0])
    assert f_d == pytest.approx(f_n * math.sqrt(1.0 - zeta**2), rel=0.01)
    peaks = [np.max(np.abs(x[(ts >= a) & (ts < b)])) for a, b in zip(crossings[:-1], crossings[1:], strict=True)]
    decrement = math.log(peaks[0] / peaks[2]) / 2.0
    assert decrement / (2.0 * math.pi) == pytest.approx(zeta, rel=0.1)


def test_the_plant_step_resolves_the_belt_mode():
    """A quarter of the step changes the ringing stretch by under 1e-6 of its swing (RK4 at omega h = 0.03)."""
    _, a = _ring(FREE, n=301)
    _, b = _ring(FREE, step_s=2.5e-5, n=301)
    assert np.max(np.abs(a - b)) < 1e-6 * np.ptp(a)


def test_a_belt_too_stiff_for_one_step_is_substepped_and_stays_stable():
    stiff = replace(FREE, belt_stiffness_n_per_mm=1e5, belt_width_mm=200.0)  # omega h ~ 3.8 at 0.1 ms: beyond RK4
    plant = Plant(stiff, suspended())
    plant.set_current_command(5.0, 0.0)
    expected = stiff.output_torque_per_amp_nm * 5.0 / stiff.belt_stiffness_nm_per_rad
    assert _stretch(plant, 1.0) == pytest.approx(expected, rel=0.01)


def test_energy_is_kept_without_loss():
    """No friction, damping or current: the energy (both sides' motion and the belt's spring) is constant while the
    belt rings."""
    p = replace(FREE, belt_damping_ratio=0.0)
    plant = Plant(p, suspended())
    plant.set_external_torque(2.0, 0.0)
    plant.set_external_torque(0.0, 0.02)
    energies = [plant.energy_j(t) for t in np.linspace(0.02, 0.1, 81)]
    assert plant.state_at(0.1).output_angle_rad < p.stop_max_rad
    assert max(energies) - min(energies) < 1e-6 * max(energies)
    assert _stretch(plant, 0.1) != 0.0


def test_the_belt_plant_profile_loads_and_a_bad_centre_distance_is_refused(tmp_path):
    path = tmp_path / "belt.toml"
    path.write_text(profile_text("belt"), encoding="utf-8")
    assert active(load_file(path)) == ("belt_compliance",)
    with pytest.raises(ValueError, match="belt.belt_center_distance_m = 0.05"):
        replace(BASE, belt_stiffness_n_per_mm=2000.0, belt_center_distance_m=0.05)

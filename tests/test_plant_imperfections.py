"""The plant's opt-in imperfections (hal/virtual/plant/imperfections.py): off, the plant is the nominal one; on,
each one's documented effect is there and of its documented size."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from hal.virtual.plant import Plant, load_plant_params, suspended
from hal.virtual.plant.imperfections import MISSPECIFIED, active, install, profile_text
from hal.virtual.plant.integrator import Coefficients
from hal.virtual.plant.params import plant_params_from_mapping
from profiles import read_toml

BASE = load_plant_params()
# no gravity, no stops in reach: the ankle moves under the torques the test applies only
FLAT = replace(BASE, gravity_m_s2=0.0)


def _run(params, torque_nm, t_end, *, samples=0, w0=0.0, current_a=0.0):
    """A suspended plant under a constant external torque (and current): its states at `samples` times up to t_end,
    or the final state."""
    plant = Plant(params, suspended(), initial_velocity_rad_s=w0)
    plant.set_external_torque(torque_nm, 0.0)
    if current_a:
        plant.set_current_command(current_a, 0.0)
    if not samples:
        return plant.state_at(t_end)
    return [plant.state_at(t) for t in np.linspace(0.0, t_end, samples)]


def test_default_profile_has_none_and_the_integrator_is_untouched():
    assert active(BASE) == ()
    plant = Plant(BASE)
    assert plant._c.imp_accel is None and plant._c.imp_integrate is None


@pytest.mark.parametrize("off", [{"stribeck_speed_rad_s": 0.5}, {"ripple_periods_per_rev": 12.0}])
def test_an_imperfection_at_zero_size_leaves_the_trajectory_bit_identical(off):
    """A changed shape parameter with the amplitude 0 changes nothing, bit for bit."""
    a = _run(FLAT, 1.5, 0.3, samples=7, current_a=0.7)
    b = _run(replace(FLAT, **off), 1.5, 0.3, samples=7, current_a=0.7)
    assert a == b


def test_the_imperfect_integrator_without_imperfections_agrees_with_the_nominal_one():
    """The imperfect path forced on with zero sizes reproduces the inlined nominal integrator (rounding only):
    the two integrate the same model, through stick, breakaway, reversal and the current lag."""
    params = replace(BASE, stribeck_peak_nm=1e-300)  # on, and far below rounding
    assert active(params) == ("stribeck",)
    times = np.linspace(0.0, 1.0, 41)
    out = []
    for p in (BASE, params):
        plant = Plant(p, suspended())
        states = []
        for k, t in enumerate(times):
            plant.set_current_command(2.5 * math.sin(9.0 * t) + (0.8 if k % 10 < 5 else -0.8), t)
            states.append(plant.state_at(t + 0.004))
        out.append(states)
    for a, b in zip(*out, strict=True):
        assert a.output_angle_rad == pytest.approx(b.output_angle_rad, abs=1e-9)
        assert a.output_velocity_rad_s == pytest.approx(b.output_velocity_rad_s, abs=1e-7)
        assert a.current_q_a == pytest.approx(b.current_q_a, abs=1e-9)
        assert a.stuck == b.stuck
    assert sum(s.stuck for s in out[0]) > 0 and sum(not s.stuck for s in out[0]) > 0  # both modes were crossed


def _breakaway_nm(params):
    """The least constant external torque (to 0.01 N m) that moves the foot from rest within 0.2 s."""
    lo, hi = 0.0, 5.0
    while hi - lo > 0.01:
        mid = 0.5 * (lo + hi)
        moved = abs(_run(params, mid, 0.2).output_angle_rad) > 1e-6
        lo, hi = (lo, mid) if moved else (mid, hi)
    return hi


def test_stribeck_raises_breakaway_to_the_friction_at_zero_speed():
    """Breakaway is max(static, Coulomb + peak): a peak above the static-minus-Coulomb raises it by the excess."""
    nominal = _breakaway_nm(FLAT)
    assert nominal == pytest.approx(FLAT.static_friction_nm, abs=0.011)
    peak = 1.5
    raised = _breakaway_nm(replace(FLAT, stribeck_peak_nm=peak))
    assert raised == pytest.approx(FLAT.coulomb_friction_nm + peak, abs=0.011)
    # the review's figure is the static minus Coulomb friction: breakaway unchanged
    review = MISSPECIFIED["stribeck"]["friction"]
    assert _breakaway_nm(replace(FLAT, **review)) == pytest.approx(nominal, abs=0.011)


def test_stribeck_friction_decays_with_speed_at_its_scale():
    """Sliding at w, the friction is Coulomb + peak exp(-(w/w_s)^2): measured from the deceleration of a coasting
    foot (no current, no gravity) at two speeds, minus the viscous damping."""
    review = MISSPECIFIED["stribeck"]["friction"]
    params = replace(FLAT, **review)
    peak, ws = review["stribeck_peak_nm"], review["stribeck_speed_rad_s"]
    j = Plant(params).output_inertia_kg_m2
    for w0 in (0.01, 0.02, 0.04):
        sliding = [s for s in _run(params, 0.0, 4e-4, w0=w0, samples=5) if not s.stuck]
        assert len(sliding) >= 3
        for s in sliding:  # the speed falls as it coasts: read at each sample
            w = s.output_velocity_rad_s
            friction = -s.output_accel_rad_s2 * j - params.foot_damping_nm_s_per_rad * w
            assert friction == pytest.approx(params.coulomb_friction_nm + peak * math.exp(-(w / ws) ** 2), rel=1e-6)
    coast = _run(FLAT, 0.0, 0.0, w0=0.02)  # the nominal plant: Coulomb only from the first instant
    assert -coast.output_accel_rad_s2 * j == pytest.approx(FLAT.coulomb_friction_nm + 0.5 * 0.02, rel=1e-6)
    # and the motion it makes: the foot coasting from 0.04 rad/s stops sooner than on the nominal plant
    stop = [next(k for k, s in enumerate(_run(p, 0.0, 0.1, w0=0.04, samples=201)) if s.stuck) for p in (FLAT, params)]
    assert stop[1] < stop[0]


def test_torque_ripple_has_its_amplitude_and_140_periods_per_rotor_revolution():
    """Pushed through its range at a steady speed, the foot's torque balance shows a ripple of the profile's
    amplitude whose spectrum peaks at 140 periods per rotor revolution."""
    cog = MISSPECIFIED["cogging"]["ripple"]
    params = replace(FLAT, **cog, foot_damping_nm_s_per_rad=5.0)
    # steady ~0.1 rad/s (damping 5 N m s/rad, 0.6 N m beyond Coulomb), from -0.45 rad: 0.75 s stays inside the stops
    plant = Plant(params, suspended(), initial_angle_rad=-0.45, initial_velocity_rad_s=0.1)
    plant.set_external_torque(0.6, 0.0)
    j = plant.output_inertia_kg_m2
    times = np.arange(0.25, 0.75, 2e-4)
    states = [plant.state_at(t) for t in times]
    th = np.array([s.output_angle_rad for s in states])
    w = np.array([s.output_velocity_rad_s for s in states])
    a = np.array([s.output_accel_rad_s2 for s in states])
    ripple = j * a + params.foot_damping_nm_s_per_rad * w + params.coulomb_friction_nm - 0.6  # what is left
    assert 0.5 * (ripple.max() - ripple.min()) == pytest.approx(cog["ripple_amplitude_nm"], rel=0.02)
    # against the rotor angle (uniform in time at a near-constant speed): the periods per rotor revolution
    rotor_rev = th * params.total_ratio / (2.0 * math.pi)
    grid = np.linspace(rotor_rev[0], rotor_rev[-1], 4096)
    spectrum = np.abs(np.fft.rfft(np.interp(grid, rotor_rev, ripple)))
    cycles = np.fft.rfftfreq(grid.size, grid[1] - grid[0])
    assert cycles[np.argmax(spectrum[1:]) + 1] == pytest.approx(cog["ripple_periods_per_rev"], rel=0.02)


def test_load_friction_is_the_transmission_efficiency_by_direction():
    """The 5 % recording's transmission: driving gives 0.95 of Kt N i at the ankle, backdriven takes Kt N i / 0.95;
    the plant's output torque follows the direction of motion."""
    p = plant_params_from_mapping(_mapping("load_friction"))
    assert active(p) == ("load_friction",)
    kn = p.kt_nm_per_a * p.total_ratio
    assert p.output_torque_nm(1.0, 1) == pytest.approx(0.95 * kn)
    assert p.output_torque_nm(1.0, -1) == pytest.approx(kn / 0.95)


def _mapping(name):
    import tomllib

    return tomllib.loads(profile_text(name))


@pytest.mark.parametrize("name", sorted(MISSPECIFIED))
def test_each_misspecified_profile_loads_with_its_settings_and_keeps_the_rest(name, tmp_path):
    path = tmp_path / f"{name}.toml"
    path.write_text(profile_text(name), encoding="utf-8")
    p = load_plant_params(path)
    for keys in MISSPECIFIED[name].values():
        for key, value in keys.items():
            assert getattr(p, key) == value
    changed = {k for keys in MISSPECIFIED[name].values() for k in keys}
    base = read_toml(path, "plant profile")
    assert {k for t in base.values() for k in t} >= changed
    assert all(getattr(p, f) == getattr(BASE, f) for f in ("kt_nm_per_a", "foot_mass_kg", "backlash_deg")
               if f not in changed)
    assert set(active(p)) == {"stribeck": {"stribeck"}, "load_friction": {"load_friction"},
                              "cogging": {"torque_ripple"},
                              "all_milder": {"stribeck", "load_friction", "torque_ripple"}}[name]


def test_unknown_misspecified_plant_is_refused_naming_the_choices():
    with pytest.raises(ValueError, match="choose from stribeck, load_friction, cogging, all_milder"):
        profile_text("bogus")


def test_install_leaves_coefficients_alone_without_stribeck_or_ripple():
    c = Plant(BASE)._c
    fresh = Coefficients(inv_j=c.inv_j, kto=c.kto, ks=c.ks, c0=c.c0, kd=c.kd, mg=c.mg, psi0=c.psi0, lo=c.lo, hi=c.hi,
                         kst=c.kst, cst=c.cst, tc=c.tc, tsx=c.tsx, tau=c.tau, ker=c.ker, bscale=c.bscale)
    install(fresh, replace(BASE, efficiency_backdriven=0.9))
    assert fresh.imp_accel is None


def test_a_run_on_a_misspecified_profile_carries_it_and_says_so(tmp_path):
    """`pafp run --plant FILE`'s bench gets the profile's imperfections; summary.json's plant record names them."""
    from host_tools.runner import RunConfig

    path = tmp_path / "stribeck.toml"
    path.write_text(profile_text("stribeck"), encoding="utf-8")
    options, record = RunConfig(plant_file=path).bench_setup()
    assert options["plant_params"].stribeck_peak_nm == 0.83
    assert record["plant"]["imperfections"] == ["stribeck"]
    assert RunConfig().bench_setup()[1]["plant"]["imperfections"] == []

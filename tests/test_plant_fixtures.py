"""Bench fixtures of the plant: torque profiles, backdrive with the motor unpowered, impulse push."""

from __future__ import annotations

import math

import pytest

from hal.virtual.plant import (
    Fixture,
    FixtureKind,
    Plant,
    TorqueProfile,
    backdrive,
    impulse,
    load_plant_params,
    spring_bench,
    suspended,
)

P = load_plant_params()


def test_torque_profile_is_piecewise_linear_and_right_continuous_at_steps() -> None:
    prof = TorqueProfile.from_points([(0.1, 0.0), (0.2, 2.0), (0.2, 5.0), (0.4, 1.0)])
    assert prof.value_at(0.0) == 0.0
    assert prof.value_at(0.15) == pytest.approx(1.0)
    assert prof.value_at(0.2) == 5.0  # value after the step
    assert prof.value_at(0.3) == pytest.approx(3.0)
    assert prof.value_at(9.0) == 1.0
    assert prof.segment(0.15)[2] == 0.2 and prof.segment(0.5)[2] == math.inf
    pulse = TorqueProfile.pulse(4.0, 0.01, 0.005)
    assert [pulse.value_at(t) for t in (0.0099, 0.01, 0.0149, 0.015)] == [0.0, 4.0, 4.0, 0.0]
    assert prof.scaled(2.0).value_at(0.3) == pytest.approx(6.0)


@pytest.mark.parametrize(
    ("points", "match"),
    [([], "at least one"), ([(0.2, 1.0), (0.1, 1.0)], "non-decreasing"), ([(0.0, math.nan)], "finite")],
)
def test_torque_profile_rejects_bad_points(points: list[tuple[float, float]], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TorqueProfile.from_points(points)


def test_fixture_validation_names_the_value() -> None:
    with pytest.raises(ValueError, match=r"load_mass_kg = -1\.0.*allowed range"):
        spring_bench(-1.0)
    with pytest.raises(ValueError, match=r"toe_lever_m = 0\.0.*allowed range"):
        backdrive([(0.0, 1.0)], toe_lever_m=0.0)
    with pytest.raises(ValueError, match="either torque_nm or toe_force_n"):
        Fixture(FixtureKind.BACKDRIVE, torque_nm=1.0, toe_force_n=2.0)
    with pytest.raises(ValueError, match="step_s"):
        Plant(P, suspended(), step_s=2e-4)
    with pytest.raises(ValueError, match="initial_angle_rad"):
        Plant(P, suspended(), initial_angle_rad=1.0)
    with pytest.raises(ValueError, match="torque_nm = '3' is not a load"):
        Fixture(FixtureKind.SUSPENDED, torque_nm="3")  # type: ignore[arg-type]


def test_backdrive_static_friction_holds_until_the_push_exceeds_breakaway() -> None:
    # a push that exactly carries the foot's weight at theta = 0 leaves it resting there (unpowered);
    # adding less than the static friction keeps it stuck, adding more lifts the toe
    lever = P.toe_lever_m
    hold_n = P.gravity_moment_nm * math.cos(0.0 + P.com_angle_at_zero_rad - math.pi / 2) / lever
    extra_n = P.static_friction_nm / lever
    weak = Plant(P, backdrive([(0.5, hold_n), (1.5, hold_n + 0.95 * extra_n)]), initial_angle_rad=0.0)
    strong = Plant(P, backdrive([(0.5, hold_n), (1.5, hold_n + 1.05 * extra_n)]), initial_angle_rad=0.0)
    for plant in (weak, strong):
        plant.set_current_command(5.0, 0.1)  # ignored: the driver is unpowered
        assert not plant.powered
    state = weak.state_at(2.0)
    assert state.current_q_a == 0.0 and state.stuck
    assert state.output_angle_rad == 0.0 and state.external_torque_nm == pytest.approx(
        P.gravity_moment_nm + 0.95 * P.static_friction_nm)
    assert strong.output_angle_rad(1.4) == 0.0  # still below breakaway at 1.4 s
    assert strong.output_angle_rad(2.0) > 0.05


def test_callable_force_matches_the_table_through_the_generic_path() -> None:
    slope = 40.0  # N/s, one linear ramp with no breakpoint inside the run
    table = Plant(P, backdrive([(0.0, 0.0), (10.0, 10 * slope)]), initial_angle_rad=0.0)
    func = Plant(P, backdrive(lambda t: slope * t), initial_angle_rad=0.0)
    for t in (0.05, 0.2, 0.45, 0.8):
        a, b = table.state_at(t), func.state_at(t)
        assert b.output_angle_rad == pytest.approx(a.output_angle_rad, abs=1e-9)
        assert b.output_velocity_rad_s == pytest.approx(a.output_velocity_rad_s, abs=1e-9)
        assert b.external_torque_nm == pytest.approx(a.external_torque_nm, abs=1e-12)


def test_impulse_gives_the_expected_change_of_momentum() -> None:
    amplitude, duration, start = 40.0, 0.004, 0.0102345
    plant = Plant(P, impulse(amplitude, duration, start), initial_angle_rad=0.0)
    ref = Plant(P, suspended(), initial_angle_rad=0.0)
    assert plant.state_at(start - 1e-6).external_torque_nm == 0.0
    assert plant.state_at(start + 1e-3).external_torque_nm == amplitude
    t_after = start + duration
    assert plant.state_at(t_after).external_torque_nm == 0.0
    dv = plant.output_velocity_rad_s(t_after) - ref.output_velocity_rad_s(t_after)
    expected = amplitude * duration / plant.output_inertia_kg_m2
    assert dv == pytest.approx(expected, rel=0.05)  # the other torques act on both over 4 ms
    after = [t_after + k * 1e-3 for k in range(1, 300)]
    assert max(plant.output_angle_rad(t) for t in after) > 0.05  # the push lifts the toe
    assert max(ref.output_angle_rad(t) for t in after) < 0.0  # without it the foot only falls


def test_set_external_torque_constant_then_none() -> None:
    plant = Plant(P, suspended(), initial_angle_rad=0.0)
    plant.set_external_torque(P.gravity_moment_nm, 0.0)  # cancels gravity at theta = 0
    assert plant.state_at(0.5).output_angle_rad == 0.0  # never broke away
    plant.set_external_torque(None, 0.5)
    assert plant.output_angle_rad(1.0) < -0.1

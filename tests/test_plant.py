"""Plant dynamics: drop test, spring-bench equilibrium, energy, current lag, saturation, laziness, time."""

from __future__ import annotations

import dataclasses
import math

import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from hal.virtual.plant import (
    Plant,
    PlantParams,
    PlantState,
    impulse,
    load_plant_params,
    spring_bench,
    suspended,
)

P = load_plant_params()


def frictionless(params: PlantParams, *, damping: bool = True) -> PlantParams:
    """The same parameters without Coulomb/static friction (and optionally without any damping)."""
    changes: dict[str, float] = {"coulomb_friction_nm": 0.0, "actuator_backdrive_torque_nm": 0.0}
    if not damping:
        changes.update(foot_damping_nm_s_per_rad=0.0, stop_damping_nm_s_per_rad=0.0)
    return dataclasses.replace(params, **changes)


def first_time_below(plant: Plant, angle_rad: float, t_end_s: float, dt_s: float = 1e-4) -> float:
    """First sampled time at which the ankle angle is <= angle_rad."""
    t = 0.0
    while t <= t_end_s:
        if plant.output_angle_rad(t) <= angle_rad:
            return t
        t = round(t + dt_s, 12)
    raise AssertionError(f"angle never reached {angle_rad} rad within {t_end_s} s")


# ------------------------------------------------------------------------------------------ drop test
def test_suspended_foot_falls_from_pi_over_5_to_the_stop_within_half_a_second() -> None:
    plant = Plant(P, suspended(), initial_angle_rad=math.pi / 5)
    t_fall = first_time_below(plant, P.stop_min_rad, 1.0)
    # lower bound: no damping, no friction and the largest gravity torque all the way down
    travel = math.pi / 5 - P.stop_min_rad
    t_min = math.sqrt(2.0 * travel * P.output_inertia_kg_m2 / P.gravity_moment_nm)
    assert 0.1 < t_min < t_fall < 0.5


def test_drop_matches_an_independent_ode_solution() -> None:
    plant = Plant(P, suspended(), initial_angle_rad=math.pi / 5)
    t_fall = first_time_below(plant, P.stop_min_rad, 1.0, dt_s=1e-4)
    j, mgd = P.output_inertia_kg_m2, P.gravity_moment_nm
    k, tc = P.foot_damping_nm_s_per_rad, P.coulomb_friction_nm
    assert mgd * math.cos(math.pi / 5) > P.static_friction_nm  # it does break away

    def rhs(_t: float, y: list[float]) -> list[float]:
        # shank vertical, COM level with the ankle at theta = 0; sliding downwards so friction is +tc
        return [y[1], (-mgd * math.sin(y[0] + P.com_angle_at_zero_rad) - k * y[1] + tc) / j]

    def hit(_t: float, y: list[float]) -> float:
        return y[0] - P.stop_min_rad

    hit.terminal = True  # type: ignore[attr-defined]
    sol = solve_ivp(rhs, (0.0, 1.0), [math.pi / 5, 0.0], events=hit, rtol=1e-10, atol=1e-12)
    t_ref = float(sol.t_events[0][0])
    assert abs(t_fall - t_ref) <= 1.5e-4  # the scan samples every 0.1 ms


# ------------------------------------------------------------------------------------- spring bench
def static_torque(params: PlantParams, load_kg: float, current_a: float, theta: float) -> float:
    """Torque on the resting foot at theta (no friction), written from the parameters independently."""
    k_l = params.spring_rate_n_per_m * params.spring_lever_m**2
    moment_arm_kg_m = params.foot_mass_kg * params.foot_com_distance_m + load_kg * params.load_lever_m
    gravity = params.gravity_m_s2 * moment_arm_kg_m
    motor = params.kt_nm_per_a * params.gearbox_ratio * params.belt_ratio * params.gearbox_efficiency \
        * params.belt_efficiency * current_a
    stop = 0.0
    if theta < params.stop_min_rad:
        stop = -params.stop_stiffness_nm_per_rad * (theta - params.stop_min_rad)
    return motor - k_l * (theta + params.spring_offset_rad) - gravity * math.cos(theta) + stop


@pytest.mark.parametrize("load_kg", P.load_masses_kg)
def test_spring_bench_settles_at_the_analytic_equilibrium_without_friction(load_kg: float) -> None:
    params = frictionless(P)
    plant = Plant(params, spring_bench(load_kg), initial_angle_rad=0.0)
    current = 2.5
    plant.set_current_command(current, 0.0)
    theta_eq = brentq(lambda th: static_torque(params, load_kg, current, th),
                      params.stop_min_rad, params.stop_max_rad)
    assert params.stop_min_rad < theta_eq < params.stop_max_rad
    state = plant.state_at(6.0)
    assert abs(state.output_angle_rad - theta_eq) < 1e-5
    assert abs(state.output_velocity_rad_s) < 1e-4


@pytest.mark.parametrize("load_kg", P.load_masses_kg)
def test_spring_bench_with_friction_sticks_inside_the_breakaway_band(load_kg: float) -> None:
    plant = Plant(P, spring_bench(load_kg), initial_angle_rad=0.3)
    current = 2.5
    plant.set_current_command(current, 0.0)
    ts = P.static_friction_nm
    lo = brentq(lambda th: static_torque(P, load_kg, current, th) + ts, P.stop_min_rad, P.stop_max_rad)
    hi = brentq(lambda th: static_torque(P, load_kg, current, th) - ts, P.stop_min_rad, P.stop_max_rad)
    state = plant.state_at(4.0)
    assert state.stuck and state.output_velocity_rad_s == 0.0
    assert min(lo, hi) <= state.output_angle_rad <= max(lo, hi)
    assert plant.output_angle_rad(5.0) == state.output_angle_rad  # stays stuck


def test_unpowered_spring_bench_rests_on_the_plantarflexion_stop() -> None:
    params = frictionless(P)
    plant = Plant(params, spring_bench(1.48), initial_angle_rad=0.2)
    below = params.stop_min_rad - 0.2
    theta_eq = brentq(lambda th: static_torque(params, 1.48, 0.0, th), below, params.stop_max_rad)
    state = plant.state_at(5.0)
    assert theta_eq < params.stop_min_rad and state.in_contact
    assert abs(state.output_angle_rad - theta_eq) < 1e-6


# ------------------------------------------------------------------------------------------- energy
@pytest.mark.parametrize("fixture", [suspended(), spring_bench(1.08)], ids=["suspended", "spring"])
def test_energy_drift_below_0_1_percent_over_10_s_without_losses(fixture: object) -> None:
    params = frictionless(P, damping=False)
    # driver unpowered (bridge open): no current at all, not even back-EMF regeneration above no-load speed
    fixture = dataclasses.replace(fixture, powered=False)  # type: ignore[type-var]
    plant = Plant(params, fixture, initial_angle_rad=math.pi / 5)  # type: ignore[arg-type]
    e0 = plant.energy_j(0.0)
    worst, kinetic_max, contacts = 0.0, 0.0, 0
    was_in_contact = False
    for ms in range(1, 10_001):
        state = plant.state_at(ms * 1e-3)
        worst = max(worst, abs(state.energy_j - e0))
        kinetic_max = max(kinetic_max, 0.5 * plant.output_inertia_kg_m2 * state.output_velocity_rad_s**2)
        contacts += state.in_contact and not was_in_contact
        was_in_contact = state.in_contact
    assert contacts >= 5  # it really bounced on the stop many times
    assert kinetic_max > 0.5
    assert worst < 1e-3 * kinetic_max


# -------------------------------------------------------------------------------------- current lag
def test_current_follows_a_step_with_the_driver_time_constant() -> None:
    plant = Plant(P, spring_bench(0.68), initial_angle_rad=0.0)
    t_cmd = 0.0100337  # off the integration grid, as a UART packet would arrive
    plant.set_current_command(4.0, t_cmd)
    tau = P.current_time_constant_s
    assert plant.current_q_a(t_cmd + tau) == pytest.approx(4.0 * (1.0 - math.exp(-1.0)), abs=1e-9)
    assert plant.current_q_a(t_cmd + 3 * tau) == pytest.approx(4.0 * (1.0 - math.exp(-3.0)), abs=1e-9)
    plant.set_current_command(-1.0, t_cmd + 3 * tau)
    i3 = 4.0 * (1.0 - math.exp(-3.0))
    expected = -1.0 + (i3 + 1.0) * math.exp(-0.5)
    assert plant.current_q_a(t_cmd + 3.5 * tau) == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("command", [50.0, -50.0])
def test_current_saturates_at_the_peak_current(command: float) -> None:
    plant = Plant(P, suspended(), initial_angle_rad=0.0)
    plant.set_current_command(command, 0.0)
    peak = P.peak_current_a
    currents = [plant.current_q_a(ms * 1e-3) for ms in range(1, 301)]
    assert max(abs(i) for i in currents) <= peak
    assert currents[-1] == pytest.approx(math.copysign(peak, command), abs=1e-6)
    assert plant.state_at(0.3).current_command_a == math.copysign(peak, command)


def test_back_emf_limits_the_current_at_speed() -> None:
    no_load_output_speed = P.supply_voltage_v / (P.ke_v_s_per_rad * P.total_ratio)
    plant = Plant(P, suspended(), initial_angle_rad=0.0, initial_velocity_rad_s=1.05 * no_load_output_speed)
    plant.set_current_command(10.0, 0.0)
    assert plant.current_q_a(P.current_time_constant_s) < 0.0  # pulled negative, not towards +10 A


# ------------------------------------------------------------------------------- power and brake
def test_unpowered_driver_forces_zero_current_and_ignores_commands() -> None:
    plant = Plant(P, suspended(), initial_angle_rad=0.0)
    plant.set_current_command(5.0, 0.0)
    assert plant.current_q_a(0.01) > 4.0
    plant.set_powered(False, 0.01)
    assert plant.current_q_a(0.01) == 0.0 and not plant.powered
    plant.set_current_command(5.0, 0.02)
    assert plant.current_q_a(0.03) == 0.0
    plant.set_powered(True, 0.03)
    plant.set_current_command(1.0, 0.03)
    assert plant.current_q_a(0.04) > 0.9


def test_brake_current_opposes_rotation() -> None:
    free = Plant(P, suspended(), initial_angle_rad=math.pi / 5)
    plant = Plant(P, suspended(), initial_angle_rad=math.pi / 5)
    plant.set_brake_current(3.0, 0.1)
    v_free = free.output_velocity_rad_s(0.1)
    assert v_free < -1.0 and plant.output_velocity_rad_s(0.1) == v_free
    state = plant.state_at(0.2)
    assert state.current_q_a > 0.5 and state.output_velocity_rad_s < 0.0  # current opposes the motion
    assert free.output_velocity_rad_s(0.2) < 3 * state.output_velocity_rad_s  # braked falls much slower


# ------------------------------------------------------------------------------------- laziness
def run_in_one_go(plant: Plant, t_end: float) -> PlantState:
    plant.set_current_command(1.5, 0.0123457)
    plant.set_current_command(-0.7, 0.0401)
    plant.advance_to(t_end)
    return plant.state_at(t_end)


def run_in_small_pieces(plant: Plant, t_end: float) -> PlantState:
    t = 0.0
    k = 0
    while t < 0.0123457:
        plant.state_at(t)
        t += 0.00037
    plant.set_current_command(1.5, 0.0123457)
    t = 0.0123457
    while t < 0.0401:
        plant.advance_to(t)
        plant.output_accel_rad_s2(t)
        k += 1
        t += 0.00011 + 0.00003 * (k % 3)
    plant.set_current_command(-0.7, 0.0401)
    t = 0.0401
    while t < t_end:
        plant.motor_angle_rad(t)
        t += 0.000731
    return plant.state_at(t_end)


@pytest.mark.parametrize("fixture", [suspended(), spring_bench(0.68), impulse(15.0, 0.0042, 0.02071)],
                         ids=["suspended", "spring", "impulse"])
def test_one_call_and_many_small_calls_give_bitwise_identical_states(fixture: object) -> None:
    t_end = 0.3456789
    a = run_in_one_go(Plant(P, fixture, initial_angle_rad=0.1), t_end)  # type: ignore[arg-type]
    b = run_in_small_pieces(Plant(P, fixture, initial_angle_rad=0.1), t_end)  # type: ignore[arg-type]
    assert a == b


def test_query_in_the_past_raises_naming_both_times() -> None:
    plant = Plant(P, suspended())
    plant.state_at(0.25)
    with pytest.raises(ValueError, match=r"0\.2.*0\.25"):
        plant.output_angle_rad(0.2)
    with pytest.raises(ValueError, match=r"0\.1.*0\.25"):
        plant.set_current_command(1.0, 0.1)
    plant.state_at(0.25)  # the same time again is fine


def test_state_relations_motor_side_and_accel() -> None:
    plant = Plant(P, suspended(), initial_angle_rad=0.3, motor_angle_offset_rad=1.25)
    plant.set_current_command(0.8, 0.0)
    t, h = 0.05, 1e-6
    v0 = plant.output_velocity_rad_s(t - h)
    s = plant.state_at(t)
    v1 = plant.output_velocity_rad_s(t + h)
    assert s.output_accel_rad_s2 == pytest.approx((v1 - v0) / (2 * h), rel=1e-4)
    assert s.motor_angle_rad == pytest.approx(P.total_ratio * s.output_angle_rad + 1.25, abs=1e-12)
    assert s.motor_velocity_rad_s == pytest.approx(P.total_ratio * s.output_velocity_rad_s, abs=1e-12)
    assert s.motor_torque_nm == pytest.approx(P.kt_nm_per_a * s.current_q_a)
    assert s.output_torque_nm == pytest.approx(s.motor_torque_nm * P.total_ratio * P.efficiency)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.t_s = 1.0  # type: ignore[misc]


@pytest.mark.parametrize("fixture", [suspended(), spring_bench(1.48)], ids=["suspended", "spring"])
def test_query_between_grid_points_matches_an_exact_partial_step(fixture: object) -> None:
    """A query inside a step is interpolated; a twin given a no-op input there integrates to it exactly."""

    def driven(t_end: float) -> Plant:
        plant = Plant(P, fixture, initial_angle_rad=math.pi / 5)  # type: ignore[arg-type]
        for k in range(int(t_end / 0.00613)):
            plant.set_current_command(12.0 * math.sin(40.0 * k * 0.00613), k * 0.00613)
        return plant

    worst_angle = worst_velocity = worst_current = 0.0
    for t in (0.0131, 0.05077, 0.1203, 0.21119, 0.3999):  # falls, hits the stop, driven back
        interpolated, exact = driven(t), driven(t)
        a = interpolated.state_at(t)
        exact.set_external_torque(None, t)  # commits an RK4 step to exactly t: the reference
        b = exact.state_at(t)
        worst_angle = max(worst_angle, abs(a.output_angle_rad - b.output_angle_rad))
        worst_velocity = max(worst_velocity, abs(a.output_velocity_rad_s - b.output_velocity_rad_s))
        worst_current = max(worst_current, abs(a.current_q_a - b.current_q_a))
    assert worst_angle < 1e-7  # the encoder resolves 1.6e-3 rad
    assert worst_velocity < 1e-4 and worst_current < 1e-9


def test_initial_current_holds_a_stuck_foot():
    """A plant started mid-run with the current that holds it (within static friction) stays; from 0 A it falls."""
    from hal.virtual.plant import Plant, load_plant_params

    p = load_plant_params()
    hold_a = 0.9 * p.gravity_moment_nm / p.output_torque_per_amp_nm  # 10 % short: friction makes up the rest
    held = Plant(p, initial_angle_rad=0.0, initial_current_a=hold_a)
    held.set_current_command(hold_a, 0.0)
    dropped = Plant(p, initial_angle_rad=0.0)
    dropped.set_current_command(hold_a, 0.0)
    assert held.output_angle_rad(0.2) == 0.0
    assert dropped.output_angle_rad(0.2) < -0.01


def test_back_emf_limit_follows_the_supply_voltage() -> None:
    # at rest the back-EMF limit is V / R: 2 V over 0.202 ohm holds the current near 9.9 A, below a 20 A command
    low = Plant(P, suspended(), initial_angle_rad=0.0)
    low.set_supply_voltage(2.0, 0.0)
    low.set_current_command(20.0, 0.0)
    full = Plant(P, suspended(), initial_angle_rad=0.0)
    full.set_current_command(20.0, 0.0)
    t = 5 * P.current_time_constant_s
    assert low.current_q_a(t) <= 2.0 / P.phase_resistance_ohm + 0.05
    assert full.current_q_a(t) == pytest.approx(20.0, abs=0.2)


@pytest.mark.parametrize("voltage", [0.0, -1.0, math.nan])
def test_supply_voltage_must_be_positive_and_finite(voltage: float) -> None:
    with pytest.raises(ValueError, match="voltage"):
        Plant(P, suspended()).set_supply_voltage(voltage, 0.0)

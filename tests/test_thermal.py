"""Winding thermal model: against the analytic step response, steady state and time constants."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.linalg import expm

from hal.virtual.plant.motors import catalogue_names, load_motor
from hal.virtual.plant.thermal import COPPER_LOSS_FACTOR, ThermalParams, WindingThermal


def _params(tempco: float | None = None) -> ThermalParams:
    p = ThermalParams.from_motor(load_motor("ak60_6"))
    return p if tempco is None else dataclasses.replace(p, copper_tempco_per_k=tempco)


def _analytic(p: ThermalParams, current_a: float, ambient_c: float, t_s: float) -> np.ndarray:
    """Exact response of the linear network (R fixed) from ambient, by the matrix exponential."""
    g1, g2 = 1 / p.winding_to_housing_k_per_w, 1 / p.housing_to_ambient_k_per_w
    cw, ch = p.winding_heat_capacity_j_per_k, p.housing_heat_capacity_j_per_k
    a = np.array([[-g1 / cw, g1 / cw], [g1 / ch, -(g1 + g2) / ch]])
    power = COPPER_LOSS_FACTOR * current_a**2 * p.resistance_ohm
    b = np.array([power / cw, 0.0])
    rise_inf = -np.linalg.solve(a, b)
    rise = (np.eye(2) - expm(a * t_s)) @ rise_inf
    return ambient_c + rise


def test_step_response_follows_the_analytic_solution() -> None:
    p = _params(tempco=0.0)
    model = WindingThermal(p, ambient_c=20.0)
    dt, current = 0.01, 15.0
    checkpoints = {500: None, 3000: None, 20000: None, 200000: None}
    for i in range(1, max(checkpoints) + 1):
        model.step(dt, current)
        if i in checkpoints:
            expected = _analytic(p, current, 20.0, i * dt)
            assert model.winding_c == pytest.approx(expected[0], rel=2e-3)
            assert model.housing_c == pytest.approx(expected[1], rel=2e-3)


def test_time_constants_match_the_eigenvalues_and_the_fast_rise() -> None:
    p = _params(tempco=0.0)
    fast, slow = p.time_constants_s()
    g1, g2 = 1 / p.winding_to_housing_k_per_w, 1 / p.housing_to_ambient_k_per_w
    cw, ch = p.winding_heat_capacity_j_per_k, p.housing_heat_capacity_j_per_k
    eig = np.linalg.eigvals(np.array([[-g1 / cw, g1 / cw], [g1 / ch, -(g1 + g2) / ch]]))
    assert sorted([fast, slow]) == pytest.approx(sorted(-1 / eig), rel=1e-9)
    assert fast < slow
    # The winding alone against a fixed housing would have tau = C_w R_wh; the fast mode sits near it.
    assert fast == pytest.approx(cw * p.winding_to_housing_k_per_w, rel=0.1)
    # The winding-to-housing difference settles with the fast constant: after 1 tau_fast (the housing
    # has barely moved) it has covered about 1 - 1/e of its steady value.
    model = WindingThermal(p, ambient_c=25.0)
    dt = fast / 2000
    for _ in range(2000):
        model.step(dt, 20.0)
    power = COPPER_LOSS_FACTOR * 20.0**2 * p.resistance_ohm
    gap_ss = power * p.winding_to_housing_k_per_w
    gap = model.winding_c - model.housing_c
    assert gap / gap_ss == pytest.approx(1 - math.exp(-1), abs=0.03)


@pytest.mark.parametrize("current_a", [3.0, 6.5, 12.0])
def test_steady_state_with_resistance_rising_matches_the_closed_form(current_a: float) -> None:
    p = _params()
    model = WindingThermal(p, ambient_c=30.0)
    expected_w, expected_h = model.steady_state_c(current_a)
    # Independent check: fixed-point iteration of T_w = T_a + P(T_w) (R_wh + R_ha).
    t_w = 30.0
    for _ in range(500):
        r = p.resistance_ohm * (1 + p.copper_tempco_per_k * (t_w - p.resistance_reference_c))
        t_w = 30.0 + COPPER_LOSS_FACTOR * current_a**2 * r * (
            p.winding_to_housing_k_per_w + p.housing_to_ambient_k_per_w)
    assert expected_w == pytest.approx(t_w, rel=1e-9)
    # The time-stepped model settles there (20 slow time constants: the rising resistance slows the
    # approach by 1 / (1 - alpha k I^2 R (R_wh + R_ha)), up to 1.5 at 12 A).
    _, slow = p.time_constants_s()
    for _ in range(int(20 * slow / 2.0)):
        model.step(2.0, current_a)
    assert model.winding_c == pytest.approx(expected_w, abs=0.05)
    assert model.housing_c == pytest.approx(expected_h, abs=0.05)
    # Hotter copper: the loss at steady state exceeds the loss at ambient.
    assert model.copper_loss_w(current_a) > COPPER_LOSS_FACTOR * current_a**2 * p.resistance_ohm


def test_resistance_rises_with_temperature_and_heats_more_than_fixed_copper() -> None:
    hot = WindingThermal(_params(), ambient_c=25.0)
    cold = WindingThermal(_params(tempco=0.0), ambient_c=25.0)
    for _ in range(3000):
        hot.step(1.0, 12.0)
        cold.step(1.0, 12.0)
    assert hot.winding_c > cold.winding_c + 1.0
    assert hot.resistance_ohm() > hot.params.resistance_ohm
    assert hot.copper_energy_j > cold.copper_energy_j


def test_runaway_above_the_critical_current_and_the_continuous_current() -> None:
    p = _params()
    model = WindingThermal(p, ambient_c=25.0)
    r_sum = p.winding_to_housing_k_per_w + p.housing_to_ambient_k_per_w
    critical = 1 / math.sqrt(COPPER_LOSS_FACTOR * p.resistance_ohm * p.copper_tempco_per_k * r_sum)
    assert model.steady_state_c(critical * 1.01) == (math.inf, math.inf)
    assert math.isfinite(model.steady_state_c(critical * 0.99)[0])
    i_cont = model.continuous_current_a()
    assert model.steady_state_c(i_cont)[0] == pytest.approx(p.max_winding_c, rel=1e-9)
    assert WindingThermal(p, ambient_c=p.max_winding_c - 100).continuous_current_a() > 0


def test_zero_current_stays_at_ambient_and_a_warm_motor_cools() -> None:
    model = WindingThermal(_params(), ambient_c=25.0)
    for _ in range(100):
        model.step(0.1, 0.0)
    assert (model.winding_c, model.housing_c) == pytest.approx((25.0, 25.0), abs=1e-9)
    model.winding_c, model.housing_c = 90.0, 60.0
    model.step(1.0, 0.0)
    assert 25.0 < model.housing_c and model.winding_c < 90.0


@pytest.mark.parametrize("name", catalogue_names())
def test_every_catalogue_motor_builds_a_thermal_model(name: str) -> None:
    p = ThermalParams.from_motor(load_motor(name))
    fast, slow = p.time_constants_s()
    assert 0 < fast < slow


def test_bad_thermal_values_are_refused() -> None:
    with pytest.raises(ValueError, match=r"winding_heat_capacity_j_per_k = -1.0 must be finite and > 0"):
        dataclasses.replace(_params(), winding_heat_capacity_j_per_k=-1.0)
    with pytest.raises(ValueError, match=r"ambient temperature 200.0 C is outside the allowed range \[-40, 80\]"):
        WindingThermal(_params(), ambient_c=200.0)

"""`pafp fit`'s least squares in each parameter's own scale (host_tools/calibration/fit_solver.py)."""

from __future__ import annotations

import numpy as np
import pytest

from host_tools.calibration.fit_solver import solve
from host_tools.calibration.plant_fit import check_params


def _valley(scale: np.ndarray):  # type: ignore[no-untyped-def]
    """Residuals of a narrow correlated valley in parameters of sizes `scale`, its floor at 0.7 scale each."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(200, 3))
    a[:, 1] = a[:, 0] + 0.05 * a[:, 1]  # the first two nearly collinear: a long valley
    noise = rng.normal(size=200)

    def fun(x: np.ndarray) -> np.ndarray:
        return a @ (x / scale - 0.7) + 1e-2 * noise
    return fun, a / scale


def test_a_valley_of_parameters_six_orders_apart_is_solved_to_its_floor():
    """The current lag (1e-3 s) beside the gravity moment (2 N m) and a tiny one: each one reaches the floor to a
    millionth of its own scale, whatever its size, from two starts, and comes back in the raw parameters. (On this
    linear valley scipy's raw-parameter solve converges too; the stopping short it did on the fit's nonlinear one is
    tests/test_plant_fit_done_when.py's kernel agreement.)"""
    scale = np.array([1e-3, 2.0, 1e-5])
    fun, jac = _valley(scale)
    lo, hi = np.zeros(3), 2 * scale
    floor = np.linalg.lstsq(jac, -fun(np.zeros(3)), rcond=None)[0]
    for start in (0.2 * scale, 1.5 * scale):
        res = solve(fun, start, lo, hi, lambda x: jac, max_nfev=100)
        assert np.all(np.abs(res.x - floor) <= 1e-6 * scale), (res.x / scale, floor / scale, res.message)


def test_the_imu_bias_is_not_a_fit_parameter():
    """Each simulation window takes its own IMU offset, which holds the bias: asking to fit it is refused, one line."""
    with pytest.raises(ValueError, match="imu_bias_deg cannot be fitted"):
        check_params(("output_inertia_kg_m2", "imu_bias_deg"), "output_inertia_kg_m2,imu_bias_deg")

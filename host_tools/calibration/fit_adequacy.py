"""`pafp fit`'s model-adequacy check: is what the fitted model leaves unexplained independent of the command?

A model that lacks an effect the bench has (a friction that depends on speed or load, a ripple with the rotor's
angle) leaves residuals that follow the input; a correct model leaves only the sensors' noise, which the command
cannot predict. For each signal (encoder angle, motor current, IMU pitch) and each segment (the fitting part, the
held-out part) the check takes the cross-covariance c(l) of the residual with the command l samples earlier, at
the lags 0..LAGS-1, and its standard deviation for a residual independent of the command when both are colored
(L. Ljung, *System Identification*, 2nd ed., 1999, section 16.6; Bartlett's formula):

    var c(l) = sum_k R_e(k) R_u(k) / N,

R_e and R_u the residual's and the command's autocovariances (pairs within one simulation window, to ``ACF_S``,
Bartlett-tapered). A whiteness test would fail on the correct model too (the windowed simulation's errors and the
IMU's noise are colored); this one does not need white residuals. (Ljung's joint chi-square over the lags was
tried first: the command is smooth, so its lags' covariance is nearly singular, and on the hand-made plant at its
true values it read 621 against a bound of 52.)

A lag fails when |c(l)| / sd exceeds ``Z_BOUND``: FAMILY_ALPHA shared over every lag of the six tests, so that, were
the bound exact, a correct model would fail one fit in a hundred or fewer. It is not exact: the experiment is closed
loop (the PD hold's part of the command follows the measured angle), and the rates on correct and on misspecified
models are what tests/benchmarks/test_bench_fit_coverage.py measures. When one fails, the fit's 95 % intervals hold
only for the model: they bound the noise's part of the error, not a bias from what the model lacks; the failing
signals and lags are listed.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

from hal.virtual.plant import PlantParams
from host_tools.calibration.fit_data import Experiment
from host_tools.calibration.fit_model import simulate, windows

__all__ = ["ACF_S", "FAMILY_ALPHA", "LAGS", "adequacy", "cross_test"]

LAGS = 26  # lags 0, 1, ..., 25 telemetry samples (0-50 ms at 500 Hz): the mechanics' and the IMU lag's span
ACF_S = 0.1  # the residual's and the command's autocovariances summed to this lag for the bound
FAMILY_ALPHA = 0.01  # a correct model's chance of failing the verdict (all six tests together)
SIGNALS = ("angle", "current", "imu")
MISSES = "the model misses something"
NOT_CHECKED = "not checked (too few samples)"
# |z| beyond which a lag fails: two-sided, FAMILY_ALPHA shared over the six tests' LAGS lags (Bonferroni)
Z_BOUND = float(NormalDist().inv_cdf(1.0 - FAMILY_ALPHA / (2 * 2 * len(SIGNALS) * LAGS)))


def _command_at(exp: Experiment, t: np.ndarray) -> np.ndarray:
    """The current command acting at times t (its job's start; 0 before the first)."""
    k = np.searchsorted(exp.t_cmd, t, side="right") - 1
    return np.where(k >= 0, exp.i_cmd[np.maximum(k, 0)], 0.0)


def _autocov(x: np.ndarray, win: np.ndarray, max_lag: int) -> np.ndarray:
    """sum over pairs in the same window of x_j x_(j+k), over len(x), for k = 0..max_lag."""
    n = len(x)
    out = np.zeros(max_lag + 1)
    for k in range(min(max_lag, n - 1) + 1):
        same = win[k:] == win[:n - k]
        out[k] = float(np.dot(x[k:][same], x[:n - k][same])) / n
    return out


def cross_test(e: np.ndarray, t: np.ndarray, win: np.ndarray, exp: Experiment, dt: float) -> dict:
    """The independence test of residual e (at times t, in simulation windows `win`) from exp's command at lags
    0..LAGS-1 samples of dt: {the largest |z| over the lags, the family's bound on it, ok, the lags (ms) beyond it,
    the correlation at each lag and its own 95 % bound}."""
    n = len(e)
    e = e - e.mean()
    k_max = max(1, int(round(ACF_S / dt)))
    r_e = _autocov(e, win, k_max) * (1.0 - np.arange(k_max + 1) / (k_max + 1))  # Bartlett-tapered
    twice = np.r_[1.0, 2.0 * np.ones(k_max)]  # k and -k
    corr, z = np.zeros(LAGS), np.zeros(LAGS)
    for lag in range(LAGS):
        u = _command_at(exp, t - lag * dt)
        u = u - u.mean()
        r_u = _autocov(u, win, k_max)
        sd = math.sqrt(max(float(np.sum(twice * r_e * r_u)), 1e-300) / n)  # of sum(e u) / n
        c = float(np.dot(e, u)) / n
        corr[lag] = c / math.sqrt(max(r_e[0] * r_u[0], 1e-300))
        z[lag] = c / sd
    bound = 1.96 * corr / np.where(z != 0.0, z, np.inf)  # each lag's own 95 % bound on the correlation
    worst = float(np.max(np.abs(z)))
    return {"max_abs_z": round(worst, 2), "z_bound": round(Z_BOUND, 2), "ok": bool(worst <= Z_BOUND),
            "lags_ms_beyond": [round(1e3 * k * dt, 1) for k in range(LAGS) if abs(z[k]) > Z_BOUND], "samples": n,
            "correlation": [round(float(x), 4) for x in corr], "bound95": [round(abs(float(x)), 4) for x in bound]}


def adequacy(base: PlantParams, v: dict[str, float], parts: dict[str, Experiment]) -> dict:
    """The check on the fitted values v for each segment in parts ({"fit": ..., "held_out": ...}): fit.json's
    ``adequacy``: {verdict, tests: {segment: {signal: cross_test's}}, failing: [segment/signal: lags]}."""
    tests: dict[str, dict[str, dict]] = {}
    max_lag_ms = math.nan
    for seg, part in parts.items():
        if len(part.t) < 4 * LAGS:
            continue
        heard = np.zeros(len(part.t), dtype=bool)
        angle, current, imu, mask = simulate(base, v, part, heard_out=heard)
        win = np.zeros(len(part.t), dtype=int)
        for w, (k, end) in enumerate(windows(part)):
            win[k:end] = w
        dt = float(np.median(np.diff(part.t)))
        max_lag_ms = round(1e3 * (LAGS - 1) * dt, 1)
        tests[seg] = {}
        for name, sim, meas, used in (("angle", angle, part.angle, mask), ("current", current, part.current,
                                                                          mask & heard), ("imu", imu, part.imu, mask)):
            if np.count_nonzero(used) >= 4 * LAGS:
                tests[seg][name] = cross_test((meas - sim)[used], part.t[used], win[used], part, dt)
    failing = [f"{seg} {name} at lags {', '.join(f'{x:g}' for x in d['lags_ms_beyond'])} ms (|z| up to "
               f"{d['max_abs_z']:g} > {d['z_bound']:g})"
               for seg, sig in tests.items() for name, d in sig.items() if not d["ok"]]
    checked = any(tests.values())
    return {"verdict": MISSES if failing else "adequate" if checked else NOT_CHECKED, "failing": failing,
            "lags": LAGS, "max_lag_ms": max_lag_ms,
            "family_alpha": FAMILY_ALPHA, "z_bound": round(Z_BOUND, 3), "tests": tests}

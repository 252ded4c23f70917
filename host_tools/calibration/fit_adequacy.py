"""`pafp fit`'s model-adequacy check: is what the fitted model leaves unexplained independent of the experiment,
and within the encoder's count?

A model that lacks an effect the bench has (a friction that depends on speed or load, a ripple with the rotor's
angle) can leave residuals that follow the input; a correct model leaves only the sensors' noise. For each signal
(encoder angle, motor current, IMU pitch), each segment (the fitting part, the held-out part) and each input the
check takes the cross-covariance c(l) of the residual with the input l earlier, at LAGS lags LAG_S apart, and
its standard deviation for a residual independent of the input when both are colored (L. Ljung, *System
Identification*, 2nd ed., 1999, section 16.6; Bartlett's formula):

    var c(l) = sum_k R_e(k) R_u(k) / N,

R_e and R_u the residual's and the input's autocovariances (pairs within one simulation window, to ``ACF_S``,
Bartlett-tapered). A whiteness test would fail on the correct model too (the windowed simulation's errors and the
IMU's noise are colored); this one does not need white residuals. (Ljung's joint chi-square over the lags was
tried first: the input is smooth, so its lags' covariance is nearly singular.)

The inputs (`inputs`): the experiment is closed loop, the PD hold's part of the command is the measured angle's,
noise included, so the command follows the angle's residual with no model error at all (tests/test_fit_adequacy.py
shows it on a seeded residual; on the benchmark's correct models the check against the command flagged 4 of 6).
Ljung's test assumes an input independent of the noise; the experiment's own reference and excitation are
(`fit_data.EXOGENOUS`, functions of time), so the check takes them when the recording carries them and the command
only when it does not (then the verdict says the bound is not exact). A residual prewhitened by its own AR model
did worse: the windowed errors are no stationary AR process.

Beside it, the resolution test (`beyond_count`): a correct model started from the encoder's reading follows the
true angle to within a fraction of a count, and the reading is the true angle rounded to a count, so the angle's
residual stays within about one count (the readings' smallest step, `fit_model.encoder_step`). It fails when more
than BEYOND_COUNT_LIMIT of the samples of both segments together lie farther. The cross-correlations above miss what
the fit absorbs into biased parameters (Stribeck friction, a loss by power direction, cogging: their residuals follow
no linear function of the excitation); those leave the simulated angle more than a count off at some starts and
reversals. The limit is not derived: 0.5 % sits between the nominal plants' shares and the misspecified ones'
(tests/benchmarks/test_bench_fit_coverage.py prints both). An encoder noisier than its count fails it too.

The verdict is the resolution test's. The cross-correlations are reported beside it (``correlation_beyond``) and
decide only where the angle never moved (no count): in make bench they reach as close to their bound on a correct
model (plant seed 11, |z| 4.06 against 4.16) as on any misspecified one, so they are no verdict.

A lag is beyond its bound when |z| exceeds the bound that shares FAMILY_ALPHA over every lag of every test
(Bonferroni). When the verdict fails, the fit's 95 % intervals hold only for the model: they bound the noise's part
of the error, not a bias from what the model lacks; what failed is listed. The rates on correct and on misspecified
models are tests/benchmarks/test_bench_fit_coverage.py's.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

from hal.virtual.plant import PlantParams
from host_tools.calibration.fit_data import WINDOW_S, Experiment
from host_tools.calibration.fit_model import encoder_step, simulate, windows

__all__ = ["ACF_S", "BEYOND_COUNT_LIMIT", "FAMILY_ALPHA", "LAGS", "LAG_S", "adequacy", "beyond_count", "cross_test",
           "inputs", "z_bound"]

# lags 0, 10, ..., 250 ms: a simulation window's span, over which the closed loop answers its reference (at lags
# to 50 ms only, a Coulomb friction three times the truth's and half its damping passed on a correct recording)
LAGS, LAG_S = 26, 0.01
ACF_S = WINDOW_S  # the residual's and the input's autocovariances summed to this lag for the bound (pairs within
# a window: the windowed errors start afresh at each)
FAMILY_ALPHA = 0.01  # a correct model's chance of failing the verdict (all its tests together)
BEYOND_COUNT_LIMIT = 0.005  # the share of the encoder residuals allowed beyond one count (see the docstring)
MISSES = "the model misses something"
NOT_CHECKED = "not checked (too few samples)"


def _held(t_sig: np.ndarray, sig: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Signal sig (set at times t_sig) as held at times t (0 before its first time)."""
    k = np.searchsorted(t_sig, t, side="right") - 1
    return np.where(k >= 0, sig[np.maximum(k, 0)], 0.0)


def inputs(exp: Experiment) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The signals the residuals are tested against: {name: (times, values)}. The experiment's own reference and
    excitation when the recording carries them (`fit_data.EXOGENOUS`, functions of time only), else the command,
    which in closed loop carries the feedback of the measured angle's noise (the bound is then not exact)."""
    if exp.exogenous and exp.t_exo is not None:
        return {name: (exp.t_exo, v) for name, v in exp.exogenous.items()}
    return {"command": (exp.t_cmd, exp.i_cmd)}


def z_bound(tests: int, alpha: float = FAMILY_ALPHA) -> float:
    """|z| beyond which a lag fails: two-sided, alpha shared over `tests` lags (Bonferroni)."""
    return float(NormalDist().inv_cdf(1.0 - alpha / (2 * tests)))


def _autocov(x: np.ndarray, win: np.ndarray, max_lag: int) -> np.ndarray:
    """sum over pairs in the same window of x_j x_(j+k), over len(x), for k = 0..max_lag."""
    n = len(x)
    out = np.zeros(max_lag + 1)
    for k in range(min(max_lag, n - 1) + 1):
        same = win[k:] == win[:n - k]
        out[k] = float(np.dot(x[k:][same], x[:n - k][same])) / n
    return out


def cross_test(e: np.ndarray, t: np.ndarray, win: np.ndarray, signal: tuple[np.ndarray, np.ndarray], dt: float,
               bound: float) -> dict:
    """The independence test of residual e (at times t, sampled every dt, in simulation windows `win`) from `signal`
    (times, values) at lags 0, LAG_S, ..., (LAGS - 1) LAG_S, each lag failing beyond |z| `bound`: {the largest |z|
    over the lags, the bound, ok, the lags (ms) beyond it, the correlation at each lag and its own 95 % bound}."""
    n = len(e)
    e = e - e.mean()
    k_max = max(1, int(round(ACF_S / dt)))
    r_e = _autocov(e, win, k_max) * (1.0 - np.arange(k_max + 1) / (k_max + 1))  # Bartlett-tapered
    twice = np.r_[1.0, 2.0 * np.ones(k_max)]  # k and -k
    corr, z = np.zeros(LAGS), np.zeros(LAGS)
    for lag in range(LAGS):
        u = _held(*signal, t - lag * LAG_S)
        u = u - u.mean()
        r_u = _autocov(u, win, k_max)
        sd = math.sqrt(max(float(np.sum(twice * r_e * r_u)), 1e-300) / n)  # of sum(e u) / n
        c = float(np.dot(e, u)) / n
        corr[lag] = c / math.sqrt(max(r_e[0] * r_u[0], 1e-300))
        z[lag] = c / sd
    own95 = 1.96 * corr / np.where(z != 0.0, z, np.inf)  # each lag's own 95 % bound on the correlation
    worst = float(np.max(np.abs(z)))
    return {"max_abs_z": round(worst, 2), "z_bound": round(bound, 2), "ok": bool(worst <= bound),
            "lags_ms_beyond": [round(1e3 * k * LAG_S, 1) for k in range(LAGS) if abs(z[k]) > bound], "samples": n,
            "correlation": [round(float(x), 4) for x in corr], "bound95": [round(abs(float(x)), 4) for x in own95]}


def beyond_count(e: np.ndarray, count: float) -> dict:
    """The resolution test of the encoder angle's residual e (rad) with the encoder's count (rad): {the share of
    samples farther than one count from the model's angle, the largest |e| in counts, the limit, ok}."""
    share = float(np.mean(np.abs(e) > count))
    return {"share_beyond_one_count": round(share, 5), "max_counts": round(float(np.max(np.abs(e))) / count, 2),
            "count_deg": round(math.degrees(count), 5), "limit": BEYOND_COUNT_LIMIT, "samples": len(e),
            "ok": share <= BEYOND_COUNT_LIMIT}


def adequacy(base: PlantParams, v: dict[str, float], parts: dict[str, Experiment]) -> dict:
    """The check on the fitted values v for each segment in parts ({"fit": ..., "held_out": ...}): fit.json's
    ``adequacy``: {verdict, against (the inputs tested), tests: {segment: {signal: {input: cross_test's}}},
    resolution: beyond_count's over both segments (and each one's share), failing: [what failed the verdict, one line
    each], correlation_beyond: [the cross-correlations beyond their bound, one line each]}. The verdict is the
    resolution test's; the cross-correlations decide only when there is no count to test against (see the
    docstring)."""
    residual: dict[str, dict[str, tuple]] = {}
    counts: dict[str, float] = {}
    for seg, part in parts.items():
        if len(part.t) < 4 * LAGS:
            continue
        heard = np.zeros(len(part.t), dtype=bool)
        angle, current, imu, mask = simulate(base, v, part, heard_out=heard)
        win = np.zeros(len(part.t), dtype=int)
        for w, (k, end) in enumerate(windows(part)):
            win[k:end] = w
        dt = float(np.median(np.diff(part.t)))
        counts[seg] = encoder_step(part)
        residual[seg] = {name: ((meas - sim)[used], part.t[used], win[used], dt)
                         for name, sim, meas, used in (("angle", angle, part.angle, mask),
                                                       ("current", current, part.current, mask & heard),
                                                       ("imu", imu, part.imu, mask))
                         if np.count_nonzero(used) >= 4 * LAGS}
    against = inputs(next(iter(parts.values())))
    family = LAGS * len(against) * sum(len(r) for r in residual.values())
    bound = z_bound(max(family, 1))
    tests = {seg: {name: {u: cross_test(e, t, win, sig, dt, bound) for u, sig in against.items()}
                   for name, (e, t, win, dt) in r.items()} for seg, r in residual.items()}
    # the resolution test over both segments together (one test, all the samples: the held-out quarter alone is few)
    angle = {seg: r["angle"][0] for seg, r in residual.items() if "angle" in r and counts[seg] > 0.0}
    resolution = {}
    if angle:
        count = min(counts[seg] for seg in angle)
        resolution = beyond_count(np.concatenate(list(angle.values())), count)
        resolution["segments"] = {seg: round(float(np.mean(np.abs(e) > count)), 5) for seg, e in angle.items()}
    beyond = [f"{seg} {name} against {u} at lags {', '.join(f'{x:g}' for x in d['lags_ms_beyond'])} ms (|z| up to "
              f"{d['max_abs_z']:g} > {d['z_bound']:g})"
              for seg, sig in tests.items() for name, by in sig.items() for u, d in by.items() if not d["ok"]]
    failing = []
    if resolution and not resolution["ok"]:
        d = resolution
        failing.append(f"angle beyond the encoder's count: {100 * d['share_beyond_one_count']:.2f} % of its samples "
                       f"more than one count ({d['count_deg']:g} deg) from the model's (limit {100 * d['limit']:g} %; "
                       f"up to {d['max_counts']:g} counts; " + ", ".join(f"{seg} {100 * x:.2f} %" for seg, x in
                                                                        d["segments"].items()) + ")")
    if not resolution:  # no encoder count to test against (the angle never moved): the cross-correlations decide
        failing = beyond
    checked = any(tests.values())
    return {"verdict": MISSES if failing else "adequate" if checked else NOT_CHECKED, "failing": failing,
            "decided_by": "resolution" if resolution else "cross-correlation", "correlation_beyond": beyond,
            "against": list(against), "lags": LAGS, "max_lag_ms": round(1e3 * (LAGS - 1) * LAG_S, 1),
            "family_alpha": FAMILY_ALPHA, "tests_in_family": family, "z_bound": round(bound, 3), "tests": tests,
            "resolution": resolution}

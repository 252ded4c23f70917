"""`pafp fit`'s engine: grey-box identification of the bench's plant model from what a bench measures.

The data are `fit_data`'s (commands, replies, encoder, IMU, current; never the emulator's truth), the model
`fit_model`'s windowed simulation of the bench's own plant. `scipy.optimize.least_squares` minimises its
residuals within bounds (`PARAMS`): a first solution without the backlash and the current lag, the backlash's
profile, each signal weighed by its own residual RMS, then all of them together (`fit_plant`; docs/calibration.md
says why in this order), and the rotor's Kt/J_m by its profile along the others' solution (`fit_profiles`). The
Jacobian at the solution gives 95 % intervals (with the rotor side's interval, and through serial mode the writes'
arrival the record leaves unknown, carried into them: `fit_profiles`, `fit_consider`) and the identifiability verdict:
a parameter whose column is
(nearly) a combination of the others' (variance inflation, from the normalised Jacobian's conditioning) is reported
"not identifiable", not given a confident number. Every fit ends with the model-adequacy check (`fit_adequacy`):
whether its angle stays within the encoder's count of the readings (the verdict) and its residuals' correlation with
the experiment's reference and excitation; when the model misses something the intervals hold only for the model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hal.virtual.plant import PlantParams
from host_tools.calibration import fit_solver as solver
from host_tools.calibration.fit_adequacy import adequacy
from host_tools.calibration.fit_consider import Solution, stuck_starts_term, timing_term
from host_tools.calibration.fit_data import STALL_BOUND_S, Experiment
from host_tools.calibration.fit_memo import one_fit
from host_tools.calibration.fit_model import (
    DEFAULT_FIT,
    FREE_IMU_OFFSET,
    PARAMS,
    SIGMA,
    base_values,
    fit_percentages,
    noise_scales,
    residuals,
    rotor_side_sd,
    window_ids,
)
from host_tools.calibration.fit_profiles import (
    BACKLASH_ABS_CI_DEG,
    backlash_profile,
    backlash_valley,
    cost_unit,
    rotor_profile,
)

__all__ = ["COLLINEARITY_LIMIT", "FitResult", "check_params", "fit_plant"]


@dataclass
class FitResult:
    """The fitted values, their 95 % intervals and verdicts, and the fit percentages."""

    names: tuple[str, ...]
    values: dict[str, float]
    start: dict[str, float]
    ci95: dict[str, float]  # half-width
    collinearity: dict[str, float]  # sqrt of the diagonal of the normalised inverse: 1 = independent
    identifiable: dict[str, bool]
    correlations: np.ndarray
    fit_pct: dict[str, dict[str, float]]  # segment -> signal -> %
    nfev: int
    cost: float
    wall_s: float
    span_s: tuple[float, float]
    message: str
    fixed_checks: dict[str, float]  # parameters kept fixed: their collinearity with the fitted ones
    jac_names: tuple[str, ...] = ()  # the parameters of the Jacobian (and `correlations`), in its order
    noise_scales: dict[str, float] = field(default_factory=dict)  # signal -> the residual scale it was weighed by
    unheard: dict[str, int] = field(default_factory=dict)  # segment -> used samples without a simulated current
    # the part of each 95 % half-width that is the rotor side's (Kt/J_m) interval (`rotor_profile`)
    rotor_ci95: dict[str, float] = field(default_factory=dict)
    rotor_sd: float = 0.0  # the tolerance table's relative spread of Kt/J_m, the profile's prior (`rotor_side_sd`)
    # the part of each 95 % half-width that is the writes' arrival the record leaves unknown (`timing_term`): 0 when the
    # timing is exact (the virtual bench)
    timing_ci95: dict[str, float] = field(default_factory=dict)
    arrival_window_ms: float = 0.0  # the median window the record leaves a write's arrival (`fit_data.arrival_bounds`)
    # segment -> samples left out as a stall's (`Experiment.stalled`), and the bound that says so (ms; 0: none)
    stalled: dict[str, int] = field(default_factory=dict)
    stall_bound_ms: float = 0.0
    # the part of each 95 % half-width that is the encoder's count at the windows that start stuck (`stuck_starts_term`)
    stuck_ci95: dict[str, float] = field(default_factory=dict)
    # the model-adequacy check (`fit_adequacy.adequacy`): the resolution test's verdict, the cross-correlations too
    adequacy: dict = field(default_factory=dict)


COLLINEARITY_LIMIT = 20.0  # above this the parameter's column is nearly a combination of the others
HELD_OUT_EVERY = 4  # one stretch in four is held out of the fit and used to check it
REL_CI_LIMIT = 0.5  # a 95 % half-width above half the value (for parameters whose scale is their value)
_ZERO_OK = {"imu_bias_deg", "encoder_offset_deg", "backlash_deg", "coulomb_friction_nm", "static_friction_nm",
            "foot_damping_nm_s_per_rad"}  # may be near 0: judged on collinearity and an absolute CI
_ABS_CI = {"imu_bias_deg": 0.5, "encoder_offset_deg": 0.5, "backlash_deg": BACKLASH_ABS_CI_DEG,
           "coulomb_friction_nm": 0.05, "static_friction_nm": 0.1, "foot_damping_nm_s_per_rad": 0.1}


def _collinearity(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(collinearity index per column, correlation matrix) of a Jacobian (columns normalised to unit length)."""
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1e-300
    jn = jac / norms
    info = jn.T @ jn
    inv = np.linalg.pinv(info)
    d = np.sqrt(np.clip(np.diag(inv), 0, None))
    safe = np.where(d > 0, d, 1.0)
    corr = inv / np.outer(safe, safe)
    return d, corr


def check_params(names: tuple[str, ...], given: str = "") -> None:
    """ValueError (one line, naming `given`: the option's text) unless `names` are fit parameters that the least
    squares can fit: at least one besides the profiled backlash and rotor side."""
    where = f"--params {given!r}" if given else "--params"
    unknown = [n for n in names if n not in PARAMS]
    if unknown or not names:
        raise ValueError(f"{where}: {unknown[0] if unknown else 'empty'} is not a fit parameter: choose from "
                         f"{', '.join(PARAMS)}")
    if FREE_IMU_OFFSET and "imu_bias_deg" in names:
        raise ValueError(f"{where}: imu_bias_deg cannot be fitted: each simulation window takes its own IMU offset "
                         "(the bias drifts), which holds the bias's part")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"{where}: {repeated[0]} is named {names.count(repeated[0])} times: name each parameter once")
    if not set(names) - {"backlash_deg", "rotor_accel_scale"}:
        raise ValueError(f"{where}: backlash_deg and rotor_accel_scale are profiled with other parameters fitted: "
                         "name at least one more")


def fit_plant(base: PlantParams, exp: Experiment, names: tuple[str, ...] = DEFAULT_FIT,
              max_nfev: int = 60) -> FitResult:
    """Least squares on the windowed simulation error over the fitting part of the experiment (`fit_parts`: one
    stretch in HELD_OUT_EVERY is held out to check the fit); a simulation asked for again is taken from the fit's
    memo (`fit_memo`)."""
    with one_fit():
        return _fit_plant(base, exp, names, max_nfev)


def _fit_plant(base: PlantParams, exp: Experiment, names: tuple[str, ...], max_nfev: int) -> FitResult:
    """`fit_plant`'s work."""
    import time

    check_params(names)
    wall0 = time.perf_counter()
    t0, t1 = float(exp.t[0]), float(exp.t[-1])
    fit_part, held, left_out = fit_parts(exp)
    start = base_values(base)
    # the encoder's zero is where the foot was at power-up: set at its zero mark by eye, within a degree or so
    # (the offset starts at 0), unless the IMU's absolute pitch over the first 0.2 s says it was further off than
    # the offset's bounds (a serial bench's foot may have hung on its stop): then +-4 deg around the IMU's figure
    first = exp.t < exp.t[0] + 0.2
    zero = round(math.degrees(float(np.median((exp.imu - exp.angle)[first]))), 3)
    zero = zero if abs(zero) > PARAMS["encoder_offset_deg"].hi else 0.0
    start["encoder_offset_deg"] = zero
    all_names = tuple(names)
    # the rotor's Kt/J_m is fitted by its profile after the least squares (`rotor_profile`), never in them
    names = ls_names = tuple(n for n in names if n != "rotor_accel_scale")
    scan = "backlash_deg" in names  # profiled first, then in the least squares (`backlash_profile`)
    # the first solution leaves out the backlash and the driver's current lag: both shape the current at each
    # reversal, so with the backlash at a start far from the bench's the lag runs off to make up for it (seen:
    # 0.28 ms for 1.14 ms with a backlash of 0.55 deg for none) and the second fit starts from there
    first_names = tuple(n for n in names if n not in ("backlash_deg", "current_time_constant_s"))
    if not first_names:  # only the lag (and the backlash) asked for: the lag alone first
        first_names = tuple(n for n in names if n != "backlash_deg")
    scales = dict(SIGMA)

    def values(names: tuple[str, ...], x: np.ndarray) -> dict[str, float]:
        return {**start, **{n: float(v) for n, v in zip(names, x, strict=True)}}

    def bounds(names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) bounds of `names` (the encoder offset's about its start)."""
        return tuple(np.array([getattr(PARAMS[n], side) + (zero if n == "encoder_offset_deg" else 0.0) for n in names])
                     for side in ("lo", "hi"))  # type: ignore[return-value]

    def solve(names: tuple[str, ...], x0: np.ndarray | None = None) -> tuple[object, np.ndarray, np.ndarray]:
        """least_squares over `names` from x0 (default: their start values): (result, steps, upper bounds)."""
        lo, hi = bounds(names)
        if x0 is None:
            x0 = np.clip(np.array([start[n] for n in names]), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
        scale = solver.scales(x0, lo, hi)
        steps = np.array([FIXED_STEPS.get(n, SECANT_STEP * float(c)) for n, c in zip(names, scale, strict=True)])

        def fun(x: np.ndarray) -> np.ndarray:
            return residuals(base, values(names, x), fit_part, scales)

        res = solver.solve(fun, x0, lo, hi, lambda x: _secant_jacobian(fun, np.asarray(x, dtype=float), steps, hi)[0],
                           max_nfev, scale=scale)
        return res, steps, hi

    res, steps, hi = solve(first_names)
    names = first_names
    profile: tuple[float, float, bool] | None = None
    if scan:  # over the whole grid, the others at their fit (from a start far off, the grid misleads: not before)
        profile = backlash_profile(base, values(names, res.x), fit_part, scales, len(names))
        start = {**start, "backlash_deg": profile[0]}
    # the three signals weighed by their own residual size at this first solution (the maximum-likelihood weights),
    # then everything fitted again from it, the backlash with the others: it and the driver's current lag trade
    # off against each other (both shape the current at each reversal), so neither is right fitted alone
    scales = noise_scales(residuals(base, values(names, res.x), fit_part, scales), scales)
    first = values(first_names, res.x)
    # none at all is a model of its own: any gap, however small, frees the rotor until the next command (a period's
    # dead time at each reversal), so a profile at 0 keeps it there (the solver's interior start would be 5e-9 deg)
    names = tuple(n for n in ls_names if n != "backlash_deg" or start["backlash_deg"] > 0.0)
    res, steps, hi = solve(names, np.array([first[n] for n in names]))
    # the weights again at this solution and the fit again with them: taken at the first solution alone (without the
    # backlash and the lag), they carried where that one stopped into the answer (the hand-made plant's 10 s
    # recording under two BLAS set-ups: the angle's scale 9 % apart, damping and Coulomb friction 0.04 half-widths)
    scales = noise_scales(residuals(base, values(names, res.x), fit_part, scales), scales)
    res, steps, hi = solve(names, np.asarray(res.x, dtype=float))
    x_fit, nfev, cost, message = np.asarray(res.x, dtype=float), int(res.nfev), float(res.cost), str(res.message)
    if "backlash_deg" in names:  # the backlash's valley, found on a fine grid, then the others fitted again in it
        fitted = values(names, x_fit)
        best = backlash_valley(base, fitted, fit_part, scales)
        if best != fitted["backlash_deg"]:
            rest = tuple(n for n in names if n != "backlash_deg")
            start = {**start, "backlash_deg": best}
            again, _, _ = solve(rest, np.array([fitted[n] for n in rest]))
            refit = values(rest, again.x)
            x_fit = np.array([refit[n] for n in names])
            nfev, cost, message = nfev + int(again.nfev), float(again.cost), str(again.message)
    rotor = None
    if "rotor_accel_scale" in all_names and values(names, x_fit)["backlash_deg"] > 0.0 and rotor_side_sd(base) > 0:
        # the rotor's Kt/J_m from its own profile, the others moved with it (with no backlash nothing crosses it)
        jac1, r1 = _secant_jacobian(lambda x: residuals(base, values(names, x), fit_part, scales), x_fit, steps, hi)
        rotor = rotor_profile(base, values(names, x_fit), fit_part, scales,
                               Solution(names, jac1, np.linalg.pinv(jac1.T @ jac1), r1, *bounds(names)))
        start = {**start, "rotor_accel_scale": rotor.best}
        x_fit = np.array([rotor.values[n] for n in names])
    if profile is not None:  # the interval from the profile on a finer grid about the fit, the others at theirs
        profile = backlash_profile(base, values(names, x_fit), fit_part, scales, len(names),
                                    around=values(names, x_fit)["backlash_deg"])
    jac, r = _secant_jacobian(lambda x: residuals(base, values(names, x), fit_part, scales), x_fit,
                              steps, hi)
    n, cost = jac.shape[1], 0.5 * float(np.dot(r, r))
    bread = np.linalg.pinv(jac.T @ jac)
    clusters = np.tile(window_ids(fit_part), 3)
    cov = _covariance(jac, r, clusters)
    v = values(names, x_fit)
    sol = Solution(names, jac, bread, r, *bounds(names))
    # the rotor side's interval carried into the others' as a consider term: their shift at its interval's ends
    rotor_shift = np.zeros(n) if rotor is None else rotor.shift95 / 1.96
    cov = cov + np.outer(rotor_shift, rotor_shift)
    timing = timing_term(base, v, fit_part, scales, sol)
    stuck = stuck_starts_term(base, v, fit_part, scales, sol)
    cov = cov + timing + stuck
    ci = 1.96 * np.sqrt(np.clip(np.diag(cov), 0, None))
    coll, corr = _collinearity(jac)
    ident = {}
    norms = np.linalg.norm(jac, axis=0)
    for k, name in enumerate(names):
        if name == "backlash_deg":
            continue  # judged on its profile (below)
        ok = coll[k] <= COLLINEARITY_LIMIT and norms[k] > 1e-9 * max(1.0, float(norms.max()))
        if name in _ZERO_OK:
            ok = ok and ci[k] <= _ABS_CI[name]
        else:
            ok = ok and ci[k] <= REL_CI_LIMIT * abs(v[name])
        ident[name] = bool(ok)
    # a column made of a switching step is no slope: what it gives is not an identification
    lo_b, hi_b = bounds(names)
    fun_ci = lambda x: residuals(base, values(names, x), fit_part, scales)  # noqa: E731
    for k in _switching_columns(fun_ci, x_fit, steps, lo_b, hi_b, jac, r,
                                [k for k, nm in enumerate(names) if ident.get(nm)]):
        ident[names[k]] = False
    fixed_checks = {}
    if "torque_constant_scale" not in names:  # the one a current-only torque measure cannot separate
        h = 1e-2
        plus = residuals(base, {**v, "torque_constant_scale": v["torque_constant_scale"] + h}, fit_part, scales)
        col = ((plus - residuals(base, v, fit_part, scales)) / h)[:, None]
        c_all, _ = _collinearity(np.hstack([jac, col]))
        fixed_checks["torque_constant_scale"] = float(c_all[-1])
    pct, unheard = {}, {}
    for label, part in (("fit", fit_part), ("held_out", held)):
        pct[label], unheard[label] = fit_percentages(base, v, part)
    ci95 = {nm: float(ci[k]) for k, nm in enumerate(names)}
    collinearity = {nm: float(coll[k]) for k, nm in enumerate(names)}
    rotor_ci95 = {nm: 1.96 * abs(float(rotor_shift[k])) for k, nm in enumerate(names)}
    timing_ci95 = {nm: 1.96 * math.sqrt(max(float(timing[k, k]), 0.0)) for k, nm in enumerate(names)}
    stuck_ci95 = {nm: 1.96 * math.sqrt(max(float(stuck[k, k]), 0.0)) for k, nm in enumerate(names)}
    if profile is not None:  # its interval from the profile (a secant over its switching steps is no curvature),
        # with the rotor side's, the timing's and the stuck starts' parts in quadrature (when it is in the Jacobian)
        rb = rotor_ci95.get("backlash_deg", 0.0)
        ci95["backlash_deg"] = math.sqrt(profile[1] ** 2 + rb ** 2 + timing_ci95.get("backlash_deg", 0.0) ** 2
                                         + stuck_ci95.get("backlash_deg", 0.0) ** 2)
        ident["backlash_deg"] = profile[2] and ci95["backlash_deg"] <= _ABS_CI["backlash_deg"]
        collinearity.setdefault("backlash_deg", math.nan)  # not in the Jacobian when fixed at 0
    if "rotor_accel_scale" in all_names:  # its value and interval are its profile's (none: the base's, its spread)
        v["rotor_accel_scale"] = 1.0 if rotor is None else rotor.best
        ci95["rotor_accel_scale"] = rotor_ci95["rotor_accel_scale"] = \
            1.96 * rotor_side_sd(base) if rotor is None else rotor.half
        timing_ci95["rotor_accel_scale"] = stuck_ci95["rotor_accel_scale"] = 0.0
        collinearity["rotor_accel_scale"] = math.nan
        ident["rotor_accel_scale"] = rotor is not None and rotor.identified
    # what the fit started from
    start = {**start, **{n: base_values(base)[n] for n in ("backlash_deg", "rotor_accel_scale")}}
    return FitResult(all_names, v, start, ci95, collinearity, ident, corr, pct, nfev,
                     cost, time.perf_counter() - wall0, (t0, t1), message,
                     fixed_checks, tuple(names), scales, unheard, rotor_ci95, rotor_side_sd(base), timing_ci95,
                     0.0 if exp.bounds is None else 1e3 * float(np.median(exp.bounds[:, 1] - exp.bounds[:, 0])),
                     left_out, 0.0 if exp.bounds is None else 1e3 * STALL_BOUND_S, stuck_ci95,
                     adequacy(base, v, {"fit": fit_part, "held_out": held}))


def _covariance(jac: np.ndarray, r: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """The parameters' covariance from the secant Jacobian and the residuals: the larger (element by element) of
    the AR(1)-inflated least-squares one (`cost_unit`) and the cluster-robust ("sandwich") one with each
    simulation window as a cluster (the errors within a window are one trajectory's, correlated, whatever their
    shape)."""
    n = jac.shape[1]
    bread = np.linalg.pinv(jac.T @ jac)
    scores = jac * r[:, None]
    meat = np.zeros((n, n))
    for c in np.unique(clusters):
        g = scores[clusters == c].sum(axis=0)
        meat += np.outer(g, g)
    return np.maximum(cost_unit(r, n) * bread, bread @ meat @ bread)


SECANT_STEP = 0.02  # of each parameter's scale: the step of the Jacobian the solver and the intervals use
BACKLASH_STEP_DEG = 0.1  # the backlash's: its residuals move in steps as each reversal's crossing ends a period later
# the encoder offset's: it acts through gravity's shape alone (mgd sin(theta) per radian of offset, a few mN m over the
# sweep for 0.1 deg), so a step of 2 % of its scale (0.008 deg) moved the cost less than one crossing ending a period
# later does: its column was a switching's jump, its interval narrow and wrong (on `--plant-seed 7`'s default
# experiment: 0.06 deg, 4.9 half-widths off)
ENCODER_OFFSET_STEP_DEG = 0.25
FIXED_STEPS = {"backlash_deg": BACKLASH_STEP_DEG, "encoder_offset_deg": ENCODER_OFFSET_STEP_DEG}


def _secant_jacobian(fun, x: np.ndarray, steps: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Jacobian from forward steps `steps`, the residuals at x); a step that would pass the upper bound goes back.

    The solver's own Jacobian takes tiny steps (1e-3 relative): the simulation's stick-slip and backlash switch
    discretely, so a tiny step that flips one of them gives a column made of the jump -- and an interval that
    is confidently narrow and wrong (seen: an encoder offset 85 half-widths off; a Coulomb friction column 3.8
    times too steep), and a solver that stops early. Steps of 2 % of each parameter's scale (the backlash:
    BACKLASH_STEP_DEG) average over many switchings: the solver and the intervals both use them.
    """
    r0 = fun(x)
    cols = []
    for k in range(len(x)):
        h = float(steps[k])
        if x[k] + h > hi[k]:
            h = -h
        xk = x.copy()
        xk[k] += h
        cols.append((fun(xk) - r0) / h)
    return np.column_stack(cols), r0


SWITCHING_RATIO = 10.0  # forward and backward secants this far apart in size: a switching step, not a slope


def _switching_columns(fun, x: np.ndarray, steps: np.ndarray, lo: np.ndarray, hi: np.ndarray, jac: np.ndarray,
                       r0: np.ndarray, which: list[int]) -> list[int]:
    """The columns among `which` of the secant Jacobian `jac` (`_secant_jacobian`'s, at x with residuals r0) that
    are a switching step: the secant the other way differs in size by more than SWITCHING_RATIO (one simulation
    each). A solution parked next to a stick-slip switching gives a column of its jump and an interval confidently
    narrow: on a recording of holds only the output inertia's forward secant moved the encoder's residuals by 557
    noise units, the backward one by 2.6, and it came out "identified" at +- 0.02 % (docs/calibration.md, "A verdict
    the secant can fool")."""
    out = []
    for k in which:
        h = float(steps[k])
        if x[k] + h > hi[k]:
            h = -h  # as `_secant_jacobian` stepped
        if not lo[k] <= x[k] - h <= hi[k]:
            continue
        xk = x.copy()
        xk[k] -= h
        fwd, back = float(np.linalg.norm(jac[:, k])), float(np.linalg.norm((r0 - fun(xk)) / h))
        if max(fwd, back) > SWITCHING_RATIO * min(fwd, back):
            out.append(k)
    return out


def fit_parts(exp: Experiment) -> tuple[Experiment, Experiment, dict[str, int]]:
    """(the fitting part, the held-out part, the samples left out of each as a stall's) of a recording; a ValueError
    naming the recording when a stall leaves too little of it to fit (`pafp fit` checks it before the fit)."""
    # the windows of a stall (`Experiment.stalled`) are left out of both parts, counted as the samples without a
    # simulated current are
    stalled = exp.stalled()
    fit_part, held = exp.interleave(HELD_OUT_EVERY, drop=stalled)
    all_fit, all_held = exp.interleave(HELD_OUT_EVERY)
    left_out = {"fit": len(all_fit.t) - len(fit_part.t), "held_out": len(all_held.t) - len(held.t)}
    if stalled.any() and (len(fit_part.t) < 100 or len(held.t) < 25):
        raise ValueError(f"{exp.source}: the link stalled through too much of the run to fit: "
                         f"{int(np.count_nonzero(stalled))} of {len(exp.t)} samples are in windows whose writes' "
                         f"arrivals are unknown by more than {1e3 * STALL_BOUND_S:g} ms on average "
                         "(docs/calibration.md, Stalled stretches)")
    return fit_part, held, left_out

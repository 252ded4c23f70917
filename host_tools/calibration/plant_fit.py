"""`pafp fit`'s engine: grey-box identification of the bench's plant model from what a bench measures.

The data are `fit_data`'s (commands, replies, encoder, IMU, current; never the emulator's truth), the model
`fit_model`'s windowed simulation of the bench's own plant. `scipy.optimize.least_squares` minimises its
residuals within bounds (`PARAMS`): a first solution without the backlash and the current lag, the backlash's
profile, each signal weighed by its own residual RMS, then all of them together (`fit_plant`; docs/calibration.md
says why in this order), and the rotor's Kt/J_m by its profile along the others' solution (`_rotor_profile`). The
Jacobian at the solution gives 95 % intervals (with the rotor side's interval, and through serial mode the writes'
arrival the record leaves unknown, carried into them: `_rotor_profile`, `_timing`) and the identifiability verdict:
a parameter whose column is
(nearly) a combination of the others' (variance inflation, from the normalised Jacobian's conditioning) is reported
"not identifiable", not given a confident number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hal.virtual.plant import PlantParams
from host_tools.calibration.fit_data import STALL_BOUND_S, Experiment
from host_tools.calibration.fit_model import (
    DEFAULT_FIT,
    PARAMS,
    SIGMA,
    base_values,
    encoder_step,
    fit_percentages,
    noise_scales,
    residuals,
    rotor_side_sd,
    stuck_starts,
    window_ids,
)

__all__ = ["COLLINEARITY_LIMIT", "FitResult", "fit_plant"]


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
    # the part of each 95 % half-width that is the rotor side's (Kt/J_m) interval (`_rotor_profile`)
    rotor_ci95: dict[str, float] = field(default_factory=dict)
    rotor_sd: float = 0.0  # the tolerance table's relative spread of Kt/J_m, the profile's prior (`rotor_side_sd`)
    # the part of each 95 % half-width that is the writes' arrival the record leaves unknown (`_timing`): 0 when the
    # timing is exact (the virtual bench)
    timing_ci95: dict[str, float] = field(default_factory=dict)
    arrival_window_ms: float = 0.0  # the median window the record leaves a write's arrival (`fit_data.arrival_bounds`)
    # segment -> samples left out as a stall's (`Experiment.stalled`), and the bound that says so (ms; 0: none)
    stalled: dict[str, int] = field(default_factory=dict)
    stall_bound_ms: float = 0.0
    # the part of each 95 % half-width that is the encoder's count at the windows that start stuck (`_stuck_starts`)
    stuck_ci95: dict[str, float] = field(default_factory=dict)


# the solver stops when the cost (in units of the noise scales: 0.5 per sample's unit error) changes by less than this
# fraction (about 0.01 on the default experiment, against one interval's 1.92) or the step by less than this fraction
# of the parameters' scale (intervals are >= 0.1 % of their values). scipy's 1e-8 took 438 simulations on
# `--plant-seed 7`'s default experiment; 1e-5 took 288 but stopped short on the 10 s experiment of seed 21 (its static
# friction 2.29 half-widths off, -0.23 with 1e-6, -0.48 with 1e-8)
SOLVER_TOL = 1e-6
COLLINEARITY_LIMIT = 20.0  # above this the parameter's column is nearly a combination of the others
HELD_OUT_EVERY = 4  # one stretch in four is held out of the fit and used to check it
REL_CI_LIMIT = 0.5  # a 95 % half-width above half the value (for parameters whose scale is their value)
_ZERO_OK = {"imu_bias_deg", "encoder_offset_deg", "backlash_deg", "coulomb_friction_nm", "static_friction_nm",
            "foot_damping_nm_s_per_rad"}  # may be near 0: judged on collinearity and an absolute CI
_ABS_CI = {"imu_bias_deg": 0.5, "encoder_offset_deg": 0.5, "backlash_deg": 0.5, "coulomb_friction_nm": 0.05,
           "static_friction_nm": 0.1, "foot_damping_nm_s_per_rad": 0.1}


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


def fit_plant(base: PlantParams, exp: Experiment, names: tuple[str, ...] = DEFAULT_FIT,
              held_out: float = 0.2, max_nfev: int = 60) -> FitResult:
    """Least squares on the windowed simulation error over the first (1 - held_out) of the experiment."""
    import time

    from scipy.optimize import least_squares

    unknown = [n for n in names if n not in PARAMS]
    if unknown:
        raise ValueError(f"--params: {unknown[0]!r} is not a fit parameter: one of {', '.join(PARAMS)}")
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
    # the rotor's Kt/J_m is fitted by its profile after the least squares (`_rotor_profile`), never in them
    names = ls_names = tuple(n for n in names if n != "rotor_accel_scale")
    if not set(names) - {"backlash_deg"}:
        raise ValueError("--params: backlash_deg and rotor_accel_scale are profiled with other parameters fitted: "
                         "name at least one more")
    scan = "backlash_deg" in names  # profiled first, then in the least squares (`_backlash_profile`)
    # the first solution leaves out the backlash and the driver's current lag: both shape the current at each
    # reversal, so with the backlash at a start far from the bench's the lag runs off to make up for it (seen:
    # 0.28 ms for 1.14 ms with a backlash of 0.55 deg for none) and the second fit starts from there
    first_names = tuple(n for n in names if n not in ("backlash_deg", "current_time_constant_s"))
    if not first_names:  # only the lag (and the backlash) asked for: the lag alone first
        first_names = tuple(n for n in names if n != "backlash_deg")
    scales = dict(SIGMA)
    last: list[tuple[tuple[str, ...], np.ndarray, np.ndarray]] = []

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
        scale = np.maximum(np.abs(x0), 0.05 * (hi - lo))
        steps = np.array([FIXED_STEPS.get(n, SECANT_STEP * float(c)) for n, c in zip(names, scale, strict=True)])

        def fun(x: np.ndarray) -> np.ndarray:
            if last and last[0][0] == names and np.array_equal(last[0][1], x):
                return last[0][2]
            r = residuals(base, values(names, x), fit_part, scales)
            last[:] = [(names, np.array(x), r)]
            return r

        res = least_squares(fun, x0, bounds=(lo, hi), x_scale=scale, max_nfev=max_nfev, method="trf",
                            ftol=SOLVER_TOL, xtol=SOLVER_TOL,
                            jac=lambda x: _secant_jacobian(fun, np.asarray(x, dtype=float), steps, hi)[0])
        return res, steps, hi

    res, steps, hi = solve(first_names)
    names = first_names
    profile: tuple[float, float, bool] | None = None
    if scan:  # over the whole grid, the others at their fit (from a start far off, the grid misleads: not before)
        profile = _backlash_profile(base, values(names, res.x), fit_part, scales, len(names))
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
    x_fit, nfev, cost, message = np.asarray(res.x, dtype=float), int(res.nfev), float(res.cost), str(res.message)
    if "backlash_deg" in names:  # the backlash's valley, found on a fine grid, then the others fitted again in it
        fitted = values(names, x_fit)
        best = _backlash_valley(base, fitted, fit_part, scales)
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
        rotor = _rotor_profile(base, values(names, x_fit), fit_part, scales,
                               _Solution(names, jac1, np.linalg.pinv(jac1.T @ jac1), r1, *bounds(names)))
        start = {**start, "rotor_accel_scale": rotor.best}
        x_fit = np.array([rotor.values[n] for n in names])
    if profile is not None:  # the interval from the profile on a finer grid about the fit, the others at theirs
        profile = _backlash_profile(base, values(names, x_fit), fit_part, scales, len(names),
                                    around=values(names, x_fit)["backlash_deg"])
    jac, r = _secant_jacobian(lambda x: residuals(base, values(names, x), fit_part, scales), x_fit,
                              steps, hi)
    n, cost = jac.shape[1], 0.5 * float(np.dot(r, r))
    bread = np.linalg.pinv(jac.T @ jac)
    clusters = np.tile(window_ids(fit_part), 3)
    cov = _covariance(jac, r, clusters)
    v = values(names, x_fit)
    sol = _Solution(names, jac, bread, r, *bounds(names))
    # the rotor side's interval carried into the others' as a consider term: their shift at its interval's ends
    rotor_shift = np.zeros(n) if rotor is None else rotor.shift95 / 1.96
    cov = cov + np.outer(rotor_shift, rotor_shift)
    timing = _timing(base, v, fit_part, scales, sol)
    stuck = _stuck_starts(base, v, fit_part, scales, sol)
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
                     left_out, 0.0 if exp.bounds is None else 1e3 * STALL_BOUND_S, stuck_ci95)


MOVED_NFEV = 10  # at most this many simulations per trust-region pass of `_moved_solution` (two passes a point)
MOVED_TOL = 1e-4  # their cost and step tolerance (the solution's own is SOLVER_TOL: these are a profile point's)


@dataclass
class _Solution:
    """What the consider terms reuse from the least-squares solution: its parameters, their secant Jacobian,
    (J'J)^-1, the residuals there and the bounds."""

    names: tuple[str, ...]
    jac: np.ndarray
    bread: np.ndarray
    r0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def _linear_shift(sol: _Solution, v: dict[str, float], fun) -> np.ndarray:
    """The linear shift -(J'J)^-1 J' (r_p(x) - r(x)) of the least-squares solution when the residuals become
    `fun`'s (`fun(values)`: the perturbed problem's residuals at those parameter values), kept within the bounds."""
    x = np.array([v[n] for n in sol.names])
    dr = fun(v) - sol.r0
    return np.clip(x - sol.bread @ (sol.jac.T @ dr), sol.lo, sol.hi) - x


def _moved_solution(sol: _Solution, start: dict[str, float], fun, valley=None) -> tuple[dict[str, float], np.ndarray]:
    """(the least-squares solution when the residuals become `fun`'s, found by few simulations; its residuals).

    A trust-region least squares (scipy's "trf", within the bounds, at most MOVED_NFEV simulations) over the
    solution's parameters but the backlash, on the solution's own secant Jacobian (not recomputed: a simulation a
    step), from `start`; then the backlash's valley on its grid (`valley(values)`: the backlash of least cost with
    the others at those values) and the same least squares again from there. On residuals linear in the parameters
    it is the least-squares solution; where they are not, each accepted step lowers the moved problem's cost, so it
    never ends where a Newton step on the solution's Jacobian alone would have taken it uphill. The backlash's
    column is made of steps (each reversal's crossing ends on a whole period): the valley's grid follows it, a
    secant step cannot.
    """
    from scipy.optimize import least_squares

    free = [k for k, n in enumerate(sol.names) if n != "backlash_deg"]
    names = tuple(sol.names[k] for k in free)
    jac, lo, hi = sol.jac[:, free], sol.lo[free], sol.hi[free]

    def solve(w: dict[str, float]) -> tuple[dict[str, float], np.ndarray]:
        x0 = np.clip(np.array([w[n] for n in names]), lo, hi)
        res = least_squares(lambda x: fun({**w, **{n: float(a) for n, a in zip(names, x, strict=True)}}), x0,
                            jac=lambda x: jac, bounds=(lo, hi), x_scale=np.maximum(np.abs(x0), 0.05 * (hi - lo)),
                            max_nfev=MOVED_NFEV, method="trf", ftol=MOVED_TOL, xtol=MOVED_TOL)
        return {**w, **{n: float(a) for n, a in zip(names, res.x, strict=True)}}, np.asarray(res.fun)

    w, r = dict(start), None
    if names:
        w, r = solve(w)
    if valley is not None and "backlash_deg" in sol.names:
        w["backlash_deg"] = valley(w)
        w, r = solve(w) if names else (w, None)
    return w, (fun(w) if r is None else r)


ROTOR_STEP = 0.05  # the rotor side's profile grid (relative Kt/J_m)
ROTOR_POINTS = 9  # at most this many profile points (the base's, 1.0, included)


def _covariance(jac: np.ndarray, r: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """The parameters' covariance from the secant Jacobian and the residuals: the larger (element by element) of
    the AR(1)-inflated least-squares one (`_cost_unit`) and the cluster-robust ("sandwich") one with each
    simulation window as a cluster (the errors within a window are one trajectory's, correlated, whatever their
    shape)."""
    n = jac.shape[1]
    bread = np.linalg.pinv(jac.T @ jac)
    scores = jac * r[:, None]
    meat = np.zeros((n, n))
    for c in np.unique(clusters):
        g = scores[clusters == c].sum(axis=0)
        meat += np.outer(g, g)
    return np.maximum(_cost_unit(r, n) * bread, bread @ meat @ bread)


def _cost_unit(r: np.ndarray, n: int) -> float:
    """One unit of chi-square in the least-squares cost (0.5 sum r^2) at residuals r with n parameters: the residual
    variance, inflated for the residuals' lag-1 correlation (m samples of AR(1) residuals carry m (1 - rho) /
    (1 + rho) of information), as the Jacobian's intervals are."""
    m = len(r)
    s2 = float(np.dot(r, r)) / max(1, m - n)
    rho = float(np.clip(np.dot(r[1:], r[:-1]) / max(float(np.dot(r, r)), 1e-300), 0.0, 0.999))
    return s2 * (1.0 + rho) / (1.0 - rho)


def _parabola(x: np.ndarray, y: np.ndarray) -> float:
    """The vertex of the parabola through three points (x ascending), within them; the middle one's x when it is
    not convex."""
    a, b, _ = np.polyfit(x, y, 2)
    return float(np.clip(-b / (2 * a), x[0], x[2])) if a > 0 else float(x[1])


@dataclass
class _RotorProfile:
    """`_rotor_profile`'s result: the rotor's Kt/J_m relative to the base's, its 95 % half-width, whether it is
    identified, the other parameters' values there, and their shift at the interval's farther-moving end (one
    vector over the solution's names)."""

    best: float
    half: float
    identified: bool
    values: dict[str, float]
    shift95: np.ndarray


def _rotor_profile(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                   sol: _Solution) -> _RotorProfile:
    """The rotor's acceleration per ampere (Kt / J_m, relative to the base's) from the cost's profile over it.

    The rotor alone carries itself across the backlash at each reversal, so Kt/J_m shapes the current there, and
    the least squares cannot follow it: with the backlash it makes a narrow valley whose floor moves in steps (each
    crossing ends on a whole command period; docs/calibration.md, The rotor side). A profile can: at each point of a
    grid (ROTOR_STEP) the other parameters are the solution moved to that Kt/J_m (`_moved_solution` from the
    base's solution: the backlash's valley searched, the others by a trust region on the solution's Jacobian). The
    tolerance table's spread (`rotor_side_sd`) is a prior: its penalty, in units of the cost's chi-square
    (`_cost_unit`), is added, so a record that cannot tell the rotor side keeps about the base's. The grid walks
    from the base's on outwards while an end of it is within the interval (where the penalised cost is within the
    95 % quantile of chi-square(1) / 2 of its least), at most ROTOR_POINTS points. The best is the vertex of the
    parabola through the best point and its neighbours; the others there, and at the interval's ends, lie linearly
    between the grid's moved solutions. The interval's ends are where the cost crosses its level, linearly between
    points, and at least half a grid step from the best (the profile is sampled no finer). It is identified when
    the cost without the prior closes such an interval inside the grid. The others' shift to the interval's ends
    (the larger of the two, its sign with it) is what `fit_plant` carries into their intervals.
    """
    sd = rotor_side_sd(base)

    points = {0: (sol.r0, dict(v))}  # grid index -> (residuals, moved values)

    def add(k: int) -> bool:
        scale = 1.0 + k * ROTOR_STEP
        if k in points or not PARAMS["rotor_accel_scale"].lo <= scale <= PARAMS["rotor_accel_scale"].hi \
                or len(points) >= ROTOR_POINTS:
            return False
        moved = {"rotor_accel_scale": scale}
        w, r = _moved_solution(sol, v, lambda w: residuals(base, {**w, **moved}, part, scales),
                               lambda w: _backlash_valley(base, {**w, **moved}, part, scales))
        points[k] = (r, w)
        return True

    unit = _cost_unit(sol.r0, len(sol.names))

    def penalised(k: int) -> float:
        return 0.5 * float(np.dot(points[k][0], points[k][0])) + 0.5 * unit * (k * ROTOR_STEP / sd) ** 2

    def within(k: int) -> bool:
        return penalised(k) - min(penalised(j) for j in points) <= 0.5 * 3.841 * unit

    add(-1)
    add(1)
    # on outwards while an end of the grid is within the interval: first in the units of the base's residuals, then
    # of the best point's (the base's carry the misfit of a rotor side that is off)
    for _ in range(2):
        while True:
            ks = sorted(points)
            if not ((within(ks[0]) and add(ks[0] - 1)) or (within(ks[-1]) and add(ks[-1] + 1))):
                break
        unit = _cost_unit(points[min(points, key=penalised)][0], len(sol.names))
    best = min(points, key=penalised)
    offset = best * ROTOR_STEP
    if best - 1 in points and best + 1 in points:
        offset = _parabola(np.array([(best + d) * ROTOR_STEP for d in (-1, 0, 1)]),
                           np.array([penalised(best + d) for d in (-1, 0, 1)]))
    ks = sorted(points)
    grid = np.array([k * ROTOR_STEP for k in ks])
    along = np.array([[points[k][1][n] for n in sol.names] for k in ks])

    def at(x: float) -> dict[str, float]:  # the others along the grid's moved solutions, linearly between points
        return {**v, **{n: float(np.interp(x, grid, along[:, j])) for j, n in enumerate(sol.names)}}

    def data(k: int) -> float:
        return 0.5 * float(np.dot(points[k][0], points[k][0]))

    def end(step: int, cost=penalised) -> tuple[float, bool]:
        """Where `cost` crosses its interval's level on that side, linearly between points; False: not in the grid."""
        low = min(points, key=cost)
        level = cost(low) + 0.5 * 3.841 * unit
        k = low
        while k + step in points and cost(k + step) <= level:
            k += step
        if k + step not in points:
            return k * ROTOR_STEP, False
        y0, y1 = cost(k), cost(k + step)
        return (k + step * (level - y0) / (y1 - y0)) * ROTOR_STEP, True

    (lower, _), (upper, _) = end(-1), end(1)
    # the profile is sampled every ROTOR_STEP: a best between samples is known to about half a step either way
    lower, upper = min(lower, offset - ROTOR_STEP / 2), max(upper, offset + ROTOR_STEP / 2)
    half = max(offset - lower, upper - offset)
    there = at(offset)
    ends = [np.array([at(x)[n] - there[n] for n in sol.names]) for x in (upper, lower)]
    shift95 = np.where(np.abs(ends[0]) >= np.abs(ends[1]), ends[0], ends[1])
    # identified when the data alone (the cost without the prior) close an interval inside the walked grid
    identified = end(-1, data)[1] and end(1, data)[1]
    return _RotorProfile(1.0 + offset, half, bool(identified), there, shift95)


DRAWS = 16  # draws of each drawn consider term (`_drawn`): its half-widths' part to about 18 % (sqrt(1/2K))
TIMING_SEED = 21  # the seeds of the draws: the same recording gives the same intervals
STUCK_SEED = 22


def _drawn(sol: _Solution, v: dict[str, float], draws) -> np.ndarray:
    """The covariance a consider term adds: the mean outer product of the least-squares solution's linear shift
    (`_linear_shift`) over `draws`, residual functions each of one draw of what the record leaves unknown (the
    draws' mean included: the record cannot exclude it)."""
    out = np.zeros((len(sol.names), len(sol.names)))
    for fun in draws:
        shift = _linear_shift(sol, v, fun)
        out += np.outer(shift, shift)
    return out / DRAWS


def _timing(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
            sol: _Solution) -> np.ndarray:
    """The covariance the writes' unknown arrival adds to the fitted parameters (zeros when the timing is exact).

    Through serial mode the record dates each write (a command and the request after it) at COMMAND_DELAY_S after
    its job, later when a late reply shows it (`fit_data._late_commands`), and bounds it only to a window
    (`fit_data.arrival_bounds`: about 0.6 ms through a pty) within which the link's per-frame delay is unknown.
    Each of DRAWS draws puts every write at an independent uniform point of its window (the least the record says):
    `_drawn`.
    """
    if part.bounds is None or not np.any(part.bounds[:, 1] > part.bounds[:, 0]):
        return np.zeros((len(sol.names), len(sol.names)))
    rng = np.random.default_rng(TIMING_SEED)
    lo, hi = part.bounds[:, 0], part.bounds[:, 1]
    # writes whose windows overlap (a stall: each may have waited behind the one before) are one burst, late together
    burst = np.r_[0, np.cumsum(part.t_cmd[1:] + lo[1:] > np.maximum.accumulate(part.t_cmd + hi)[:-1])]
    drawn = [part.shifted(lo + rng.uniform(0.0, 1.0, int(burst[-1]) + 1)[burst] * (hi - lo)) for _ in range(DRAWS)]
    return _drawn(sol, v, (lambda w, d=d: residuals(base, w, d, scales) for d in drawn))


def _stuck_starts(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                  sol: _Solution) -> np.ndarray:
    """The covariance the encoder's count at the windows that start stuck adds to the fitted parameters.

    A window that starts stuck (`fit_model.stuck_starts`) starts at its encoder reading, which places the foot only
    to its count (`fit_model.encoder_step`: 0.09 deg for 4000 counts a turn); where in it the foot sits moves the
    angle after the breakaway and, through gravity, the breakaway itself, by up to a count, and the record does not
    say where (docs/calibration.md, The encoder's count at a stuck start). Each of DRAWS draws starts every such
    window at an independent uniform point within a count about its reading: `_drawn`. Zeros with no such window.
    """
    ks, q = stuck_starts(part), encoder_step(part)
    if not len(ks) or q <= 0.0:
        return np.zeros((len(sol.names), len(sol.names)))
    rng = np.random.default_rng(STUCK_SEED)
    drawn = []
    for _ in range(DRAWS):
        shift = np.zeros(len(part.t))
        shift[ks] = rng.uniform(-q / 2, q / 2, len(ks))
        drawn.append(replace(part, start_shift=shift))
    return _drawn(sol, v, (lambda w, d=d: residuals(base, w, d, scales) for d in drawn))


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


VALLEY_GRIDS = ((0.04, 4), (0.01, 4))  # `_backlash_valley`'s grids: (step in deg, steps either side of the best)


def _backlash_cost(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                   backlash_deg: float) -> float:
    """The least-squares cost with the backlash at `backlash_deg` and the other parameters held at v."""
    return 0.5 * float(np.sum(residuals(base, {**v, "backlash_deg": backlash_deg}, part, scales) ** 2))


def _backlash_valley(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                     grids: tuple[tuple[float, int], ...] = VALLEY_GRIDS) -> float:
    """The backlash of least cost about v's, the other parameters held at v (a coarse-to-fine grid).

    The backlash's valley is narrow: each reversal's crossing ends on a whole command period, and the measured
    current, which resolves the crossing's length, moves the cost in steps a few hundredths of a degree wide (on
    `--plant-seed 7`'s default experiment the cost doubles 0.06 deg from its floor). The least squares' secant step
    (BACKLASH_STEP_DEG) cannot follow it and stops on the valley's wall, where the current lag and the Coulomb
    friction make up for the crossings it times wrong (docs/calibration.md)."""
    def cost(b: float) -> float:
        return _backlash_cost(base, v, part, scales, b)

    best = float(v["backlash_deg"])
    costs = {best: cost(best)}
    for step, points in grids:
        centre = best
        for k in range(-points, points + 1):
            b = round(centre + k * step, 6)
            if 0.0 < b <= PARAMS["backlash_deg"].hi and b not in costs:
                costs[b] = cost(b)
        best = min(costs, key=costs.__getitem__)
    return best


BACKLASH_GRID_DEG = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 5.0)


def _backlash_profile(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float], n: int,
                      around: float | None = None) -> tuple[float, float, bool]:
    """(best backlash, 95 % half-width, identified) from the cost over a grid of backlash values, the other
    parameters held at `v` (a conditional profile: the others are fitted again at the best, not at each point).

    Backlash acts through a dead time at each reversal: the simulation error moves in steps as it grows, which
    a finite-difference Jacobian sees as zero or as a spurious slope; a scan over the whole range does not.
    The interval is where the cost stays within the 95 % quantile of chi-square(1) / 2, in units of the
    residual variance inflated for the residuals' lag-1 correlation (as the Jacobian's intervals); identified
    when that interval closes inside the grid and is no wider than `_ABS_CI`.
    """
    grid = np.array(BACKLASH_GRID_DEG if around is None else
                    sorted(set(np.clip(around + np.linspace(-0.5, 0.5, 11), 0.0, PARAMS["backlash_deg"].hi))))
    cost = np.array([_backlash_cost(base, v, part, scales, float(b)) for b in grid])
    k = int(np.argmin(cost))
    threshold = 0.5 * 3.841 * _cost_unit(residuals(base, v, part, scales), n)
    best = float(grid[k])
    if 0 < k < len(grid) - 1:  # the parabola through the best and its neighbours
        best = _parabola(grid[k - 1:k + 2], cost[k - 1:k + 2])
    inside = cost - cost[k] <= threshold
    lo_i, hi_i = k, k
    while lo_i > 0 and inside[lo_i - 1]:
        lo_i -= 1
    while hi_i < len(grid) - 1 and inside[hi_i + 1]:
        hi_i += 1
    closed = (lo_i > 0 or grid[0] == 0.0) and hi_i < len(grid) - 1
    lower = float(grid[lo_i - 1]) if lo_i > 0 else float(grid[0])  # the interval reaches the first point outside it
    upper = float(grid[hi_i + 1]) if hi_i < len(grid) - 1 else float(grid[-1])
    half = max(best - lower, upper - best)
    return best, half, bool(closed and half <= _ABS_CI["backlash_deg"])


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

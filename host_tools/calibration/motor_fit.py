"""`pafp fit LOG.csv`'s engine: a motor's own parameters from a bench log that pafp did not make (csv_log.BenchLog).

The model is the rotor alone (docs/csv_fit.md):

    J dw/dt = Kt i - Tc sign(w) - b w - T_load,      di/dt = (i_command(t - d) - i) / tau

with i the measured q current, T_load the torque sensor's reading (0 without one). The mechanical part is linear in
(Kt, J, Tc, b): integrated over short windows where the shaft turns one way faster than a threshold (the Coulomb term's
sign known, sticking left out), it is ordinary least squares on

    integral(T_load) = Kt integral(i) - J (w_end - w_start) - Tc sign(w) window - b integral(w)

(integrated, not differentiated: no acceleration is estimated from noisy samples). Without a torque sensor only the
ratios to Kt are in the data: J, Tc and b come out per ampere (A s^2/rad, A, A s/rad), in N m units with --kt. The
current lag is a first-order lag of the command, held between samples and d samples late (d = 0..3): its time constant
minimises the measured current's squared error. Intervals are 95 % from the residuals, taken as independent between
windows (and samples, for the lag): with coloured noise they are too narrow, and they are conditional on this model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar

from host_tools.calibration.csv_log import BenchLog

__all__ = ["MotorFit", "fit_motor"]

Z95 = 1.96
REL_CI_LIMIT = 0.5  # a 95 % half-width above half the value: not identifiable
COLLINEARITY_LIMIT = 20.0  # a column (nearly) a combination of the others
MIN_WINDOWS = 20
MAX_DELAY_SAMPLES = 3
# 7-point quadratic Savitzky-Golay filters (A. Savitzky, M. J. E. Golay, Anal. Chem. 36 (1964) 1627-1639, tables I and
# III): the first derivative and the smoothed value at the middle point. Short, so that they follow the fastest motion;
# written out rather than scipy.signal.savgol_filter, whose import costs seconds on a busy machine
SG_DERIVATIVE = np.arange(-3.0, 4.0) / 28.0
SG_SMOOTH = np.array([-2.0, 3.0, 6.0, 7.0, 6.0, 3.0, -2.0]) / 21.0


@dataclass
class MotorFit:
    """The identified values (rotor side, SI), their 95 % half-widths and verdicts."""

    values: dict[str, float]
    ci95: dict[str, float]
    identifiable: dict[str, bool]
    units: dict[str, str]
    notes: dict[str, str] = field(default_factory=dict)  # parameter -> why it is missing or not identifiable
    windows: int = 0
    min_speed_rad_s: float = 0.0
    period_s: float = 0.0
    fit_pct: dict[str, float] = field(default_factory=dict)  # "mechanics", "current" -> %
    delay_samples: int = 0


def _uniform(log: BenchLog, gear_ratio: float) -> dict[str, np.ndarray | float | None]:
    """The log on a uniform grid at its median period, rotor side (linear interpolation), samples inside a gap longer
    than 3 periods marked."""
    t = log.t
    period = float(np.median(np.diff(t)))
    grid = t[0] + period * np.arange(int((t[-1] - t[0]) / period) + 1)
    out: dict[str, np.ndarray | float | None] = {"period": period}
    scales = (("current", 1.0), ("position", gear_ratio), ("speed", gear_ratio), ("torque", 1.0 / gear_ratio))
    for role, scale in scales:
        v = getattr(log, role)
        out[role] = None if v is None else np.interp(grid, t, v) * scale
    k = np.searchsorted(t, grid, side="right")
    k = np.clip(k, 1, len(t) - 1)
    out["gap"] = (t[k] - t[k - 1]) > 3.0 * period
    return out


def _speed(u: dict) -> np.ndarray:
    """Shaft speed: the position's Savitzky-Golay derivative, or the speed column smoothed the same way (the first and
    last 3 samples, which the filter does not reach, are marked as a gap)."""
    if u["position"] is not None:
        w = np.convolve(u["position"], SG_DERIVATIVE[::-1], mode="same") / u["period"]
    else:
        w = np.convolve(u["speed"], SG_SMOOTH, mode="same")
    u["gap"][:3] = u["gap"][-3:] = True
    return w


def _ols(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(coefficients, 95 % half-widths, collinearity index per column, fit %) of y = x c."""
    norms = np.linalg.norm(x, axis=0)
    norms[norms == 0.0] = 1.0
    xn = x / norms
    c, *_ = np.linalg.lstsq(xn, y, rcond=None)
    r = y - xn @ c
    dof = max(1, len(y) - x.shape[1])
    inv = np.linalg.pinv(xn.T @ xn)
    sd = np.sqrt(np.clip(np.diag(inv), 0.0, None) * float(r @ r) / dof)
    fit = 100.0 * (1.0 - float(np.linalg.norm(r)) / max(float(np.linalg.norm(y - y.mean())), 1e-300))
    return c / norms, Z95 * sd / norms, np.sqrt(np.clip(np.diag(inv), 0.0, None)), fit


def _windows(w: np.ndarray, gap: np.ndarray, n: int, min_speed: float) -> list[int]:
    """Starts of the non-overlapping windows of n + 1 samples that turn one way above min_speed, without a gap."""
    starts = []
    for k in range(0, len(w) - n, n):
        seg = w[k:k + n + 1]
        if not gap[k:k + n + 1].any() and (seg.min() > min_speed or seg.max() < -min_speed):
            starts.append(k)
    return starts


def fit_motor(log: BenchLog, *, gear_ratio: float = 1.0, kt_nm_per_a: float | None = None, window_s: float = 0.01,
              min_speed_rad_s: float | None = None) -> MotorFit:
    """Identify Kt (with a torque sensor), J, Tc, b and the current lag; ValueError when the log moves too little."""
    u = _uniform(log, gear_ratio)
    period = float(u["period"])  # type: ignore[arg-type]
    n = max(3, round(window_s / period))
    w = _speed(u)
    floor = 0.05 * float(np.percentile(np.abs(w), 95))
    min_speed = floor if min_speed_rad_s is None else min_speed_rad_s
    starts = _windows(w, u["gap"], n, min_speed)  # type: ignore[arg-type]
    if len(starts) < MIN_WINDOWS:
        raise ValueError(f"{log.path}: {len(starts)} windows of {n * period * 1e3:.3g} ms where the shaft turns one "
                         f"way faster than {min_speed:.4g} rad/s: at least {MIN_WINDOWS} needed (more motion, or a "
                         "lower --min-speed)")
    idx = np.array(starts)[:, None] + np.arange(n + 1)[None, :]
    wts = np.full(n + 1, period)
    wts[[0, -1]] *= 0.5  # trapezoid weights over a window's samples

    def integral(v: np.ndarray) -> np.ndarray:
        return v[idx] @ wts

    sgn = np.sign(w[idx[:, 0]])
    d_w = w[idx[:, -1]] - w[idx[:, 0]]
    int_w = (u["position"][idx[:, -1]] - u["position"][idx[:, 0]]) if u["position"] is not None else integral(w)
    cols = [-d_w, -sgn * n * period, -int_w]
    names = ["rotor_inertia_kg_m2", "coulomb_friction_nm", "viscous_friction_nm_s_per_rad"]
    units = {"kt_nm_per_a": "N m/A", "rotor_inertia_kg_m2": "kg m^2", "coulomb_friction_nm": "N m",
             "viscous_friction_nm_s_per_rad": "N m s/rad", "current_time_constant_s": "s"}
    notes: dict[str, str] = {}
    if u["torque"] is not None:
        x = np.column_stack([integral(u["current"])] + cols)
        c, ci, col, fit = _ols(x, integral(u["torque"]))
        names = ["kt_nm_per_a"] + names
    else:  # integral(i) = (J d_w + Tc sign T + b integral(w)) / Kt
        c, ci, col, fit = _ols(-np.column_stack(cols), integral(u["current"]))
        scale = kt_nm_per_a if kt_nm_per_a is not None else 1.0
        c, ci = c * scale, ci * scale
        notes["kt_nm_per_a"] = "no torque column: Kt is not in the data" + (
            f" (--kt {kt_nm_per_a:g} taken)" if kt_nm_per_a is not None else "")
        if kt_nm_per_a is None:
            units.update(rotor_inertia_kg_m2="A s^2/rad (J/Kt)", coulomb_friction_nm="A (Tc/Kt)",
                         viscous_friction_nm_s_per_rad="A s/rad (b/Kt)")
    values = {k: float(v) for k, v in zip(names, c, strict=True)}
    half = {k: float(v) for k, v in zip(names, ci, strict=True)}
    ok = {k: bool(abs(half[k]) <= REL_CI_LIMIT * abs(values[k]) and col[j] <= COLLINEARITY_LIMIT)
          for j, k in enumerate(names)}
    result = MotorFit(values, half, ok, units, notes, len(starts), min_speed, period, {"mechanics": fit})
    if log.command is not None:
        _fit_lag(result, log)
    else:
        result.notes["current_time_constant_s"] = "no command column: the current lag is not in the data"
    return result


def _lagged(cmd: np.ndarray, i0: float, decay: np.ndarray) -> np.ndarray:
    """The first-order lag of a held command: i[k+1] = cmd[k] + (i[k] - cmd[k]) decay[k], from i[0] = i0 (decay[k] =
    exp(-(t[k+1] - t[k]) / tau): the log's own sample times, jitter included).

    Vectorised in blocks: i[k] = P_k (i[s] + sum_j (1 - decay_j) cmd_j / P_(j+1)) with P the product of the decays since
    the block's start s, a block ending before P falls below e^-600 (1 / P stays below e^646, no overflow).
    """
    n = len(cmd)
    la = np.log(np.clip(decay[:n - 1], 1e-20, None))  # below 1e-20 the old current is gone to rounding anyway
    c = (1.0 - np.exp(la)) * cmd[:n - 1]
    big_l = np.concatenate([[0.0], np.cumsum(la)])  # log of the product of the decays up to each sample
    starts = np.flatnonzero(np.diff(np.floor(-big_l / 600.0)) != 0) + 1
    y = np.empty(n)
    y[0] = i0
    for s, e in zip(np.concatenate([[0], starts]), np.concatenate([starts, [n]]), strict=True):
        rel = big_l[s:e] - big_l[s]
        acc = np.cumsum(np.exp(-rel[1:]) * c[s:e - 1])
        y[s + 1:e] = np.exp(rel[1:]) * (y[s] + acc)
        if e < n:
            y[e] = y[e - 1] * np.exp(la[e - 1]) + c[e - 1]
    return y


def _fit_lag(result: MotorFit, log: BenchLog) -> None:
    """The current lag's time constant and whole-sample delay, by least squares on the measured current (at the log's
    own sample times: the command is held from the sample that logs it)."""
    assert log.command is not None
    dt = np.diff(log.t)
    period = float(np.median(dt))
    lo, hi = math.log(period / 20.0), math.log(0.2)
    cur = log.current

    def simulate(tau: float, d: int) -> np.ndarray:
        m = len(cur) - d
        return _lagged(log.command[:m], float(cur[d]), np.exp(-dt[d:] / tau))

    def sse(log_tau: float, d: int) -> float:
        r = cur[d:] - simulate(math.exp(log_tau), d)
        return float(r @ r)

    # the delay from a coarse grid of time constants, then the time constant of the best delay refined between the
    # grid's neighbours of its best point
    grid = np.linspace(lo, hi, 9)
    coarse = {(d, k): sse(g, d) for d in range(MAX_DELAY_SAMPLES + 1) for k, g in enumerate(grid)}
    d, k = min(coarse, key=coarse.__getitem__)
    res = minimize_scalar(sse, bounds=(grid[max(0, k - 1)], grid[min(8, k + 1)]), args=(d,), method="bounded",
                          options={"xatol": 1e-3})
    tau = math.exp(res.x)
    h = 1e-3 * tau  # the sensitivity of the simulated current to tau, for its interval
    sens = (simulate(tau + h, d) - simulate(tau - h, d)) / (2.0 * h)
    s2 = res.fun / max(1, len(sens) - 2)
    half = Z95 * math.sqrt(s2 / max(float(sens @ sens), 1e-300))
    result.values["current_time_constant_s"] = tau
    result.ci95["current_time_constant_s"] = half
    result.identifiable["current_time_constant_s"] = bool(half <= REL_CI_LIMIT * tau and lo + 0.05 < res.x < hi - 0.05)
    result.delay_samples = d
    spread = float(np.linalg.norm(cur[d:] - cur[d:].mean()))
    result.fit_pct["current"] = 100.0 * (1.0 - math.sqrt(res.fun) / max(spread, 1e-300))
    if not result.identifiable["current_time_constant_s"]:
        result.notes["current_time_constant_s"] = (f"at the edge of [{period / 20:.3g}, 0.2] s or interval too wide: "
                                                   "the log's period does not resolve the lag")


PROFILE_KEYS = {"kt_nm_per_a": "[motor] kt_nm_per_a", "rotor_inertia_kg_m2": "[motor] rotor_inertia_kg_m2",
                "current_time_constant_s": "[driver] current_time_constant_s"}
"""The identified parameters that are a plant profile's keys as they stand (the friction figures there are the
ankle's, through the transmission: not the rotor's)."""


def report(log: BenchLog, r: MotorFit, gear_ratio: float) -> tuple[dict, str]:
    """(fit.json's content, fit.md's text) of a CSV log's fit."""
    params = {k: {"value": r.values[k], "ci95_half_width": r.ci95[k], "identifiable": r.identifiable[k],
                  "unit": r.units.get(k, ""), "profile_key": PROFILE_KEYS.get(k), "note": r.notes.get(k, "")}
              for k in r.values}
    missing = {k: v for k, v in r.notes.items() if k not in r.values}
    doc = {"log": str(log.path), "rows": len(log.t), "period_s": r.period_s,
           "columns": {c.role: {"header": c.header, "unit": c.unit, "from": c.source} for c in log.columns.values()},
           "gear_ratio": gear_ratio, "frame": "rotor" if gear_ratio == 1.0 else f"rotor (log's shaft / {gear_ratio:g})",
           "windows": r.windows, "min_speed_rad_s": r.min_speed_rad_s, "fit_percent": r.fit_pct,
           "command_delay_samples": r.delay_samples if "current_time_constant_s" in r.values else None,
           "params": params, "not_in_the_data": missing,
           "model": "J dw/dt = Kt i - Tc sign(w) - b w - T_load; di/dt = (i_cmd(t - d) - i) / tau (docs/csv_fit.md)"}
    lines = [f"# Motor fit of {log.path.name}", "",
             f"{len(log.t)} rows at {r.period_s * 1e3:.3g} ms; {r.windows} windows turning faster than "
             f"{r.min_speed_rad_s:.3g} rad/s; rotor side" + (f" (the log's shaft x {gear_ratio:g})" if gear_ratio != 1
                                                              else "") + ".", "",
             "| parameter | value | 95 % ± | unit | verdict |", "|---|---|---|---|---|"]
    for k, p in params.items():
        verdict = "identified" if p["identifiable"] else "NOT IDENTIFIABLE"
        lines.append(f"| {k} | {p['value']:.5g} | {p['ci95_half_width']:.2g} | {p['unit']} | {verdict}"
                     + (f": {p['note']}" if p["note"] else "") + " |")
    for k, why in missing.items():
        lines.append(f"| {k} | — | — | | {why} |")
    lines += ["", "Fit % (1 - |residual| / |signal - mean|): " + ", ".join(f"{k} {v:.1f}" for k, v in r.fit_pct.items())
              + ".", "", "The intervals take the residuals as independent between windows (samples, for the lag) and "
              "are conditional on the model (docs/csv_fit.md): stiction, cogging, a torque-dependent friction or a "
              "load the sensor does not see bias them without widening them."]
    return doc, "\n".join(lines) + "\n"

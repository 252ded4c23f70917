"""`pafp fit`'s engine: grey-box identification of the bench's plant model from what a bench measures.

The data (`load_experiment`): the current commands the firmware sent (decoded from the motor port's writes
in record.bin, each at its job's time) and, from telemetry.csv, the encoder angle, the IMU pitch and the
motor's measured current, over the span the supervisor was in RUN. Never the emulator's truth.

The model is the plant of the virtual bench itself (`hal.virtual.plant.Plant`, the code the bench runs),
driven by the recorded commands. Its simulation error is taken over windows of ``WINDOW_S``: each window
starts from the measured angle and velocity (the suspended foot under gravity is not self-regulating, so
one 30 s open-loop simulation drifts with any error in the gravity moment; windows keep the error about
the dynamics), and the residuals are the encoder angle, the measured current and the IMU pitch (through
a first-order lag and a bias), each divided by its noise scale. `scipy.optimize.least_squares` minimises
them within bounds (`PARAMS`). The Jacobian at the solution gives 95 % intervals and the identifiability
verdict: a parameter whose column is (nearly) a combination of the others' (variance inflation, from the
normalised Jacobian's conditioning) is reported "not identifiable", not given a confident number.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hal.record.format import Kind
from hal.record.replay import RecordReader
from hal.virtual.plant import Plant, PlantParams, load_plant_params, suspended
from host_tools.recording import RECORD_NAME

__all__ = ["PARAMS", "Experiment", "FitParam", "fit_percentage", "load_experiment", "plant_with", "simulate"]

BACKLASH_DEG = 0.55  # the maker's figure (profiles/bench_imperfections.toml [gearbox_backlash]) for a base without the key
WINDOW_S = 0.25  # each simulated window starts from the measured state (docs/calibration.md: why this short)
SKIP_S = 0.01  # residuals skip the first samples of a window (the current state starts at the command)
# below this the encoder cannot tell motion from rest over the velocity's span (0.09 deg counts, ~30 ms): a window
# starts at rest, so a foot held by static friction starts stuck, not sliding on a velocity made of count noise
REST_RAD_S = 0.03
SIGMA = {"angle": math.radians(0.1), "current": 0.1, "imu": math.radians(0.3)}  # residual scales (rad, A, rad)


@dataclass(frozen=True)
class FitParam:
    """One fitted parameter: its name, unit, bounds and the plant-profile keys it sets."""

    name: str
    unit: str
    lo: float
    hi: float
    meaning: str


PARAMS: dict[str, FitParam] = {p.name: p for p in (
    FitParam("output_inertia_kg_m2", "kg m^2", 0.005, 0.5, "inertia at the ankle: foot + reflected transmission"),
    FitParam("foot_damping_nm_s_per_rad", "N m s/rad", 0.0, 5.0, "viscous damping at the ankle"),
    FitParam("coulomb_friction_nm", "N m", 0.0, 2.0, "kinetic (Coulomb) friction at the ankle"),
    FitParam("static_friction_nm", "N m", 0.0, 4.0, "breakaway friction at the ankle (>= Coulomb)"),
    FitParam("gravity_moment_nm", "N m", 0.3, 6.0, "m g d of the foot"),
    FitParam("backlash_deg", "deg", 0.0, 5.0, "gearbox free play at the actuator output"),
    FitParam("torque_constant_scale", "", 0.6, 1.4, "Kt relative to the base profile's"),
    FitParam("current_time_constant_s", "s", 1e-4, 0.01, "driver current lag"),
    FitParam("imu_lag_s", "s", 1e-4, 0.1, "IMU pitch lag (first order, with the frame hold)"),
    FitParam("imu_bias_deg", "deg", -6.0, 6.0, "IMU pitch bias"),
    FitParam("encoder_offset_deg", "deg", -4.0, 4.0, "true angle minus the encoder's at power-up"),
)}
# backlash is not fitted by default: its effect (a dead time at each reversal of the command) moves the
# residuals in steps a finite-difference Jacobian sees as zero or as a spurious slope (docs/calibration.md)
DEFAULT_FIT = ("output_inertia_kg_m2", "foot_damping_nm_s_per_rad", "coulomb_friction_nm", "static_friction_nm",
               "gravity_moment_nm", "current_time_constant_s", "imu_lag_s", "imu_bias_deg", "encoder_offset_deg")


def base_values(p: PlantParams) -> dict[str, float]:
    """The fit parameters' values of a plant profile (the start of the search; measurement ones at 0)."""
    return {"output_inertia_kg_m2": p.output_inertia_kg_m2, "foot_damping_nm_s_per_rad": p.foot_damping_nm_s_per_rad,
            "coulomb_friction_nm": p.coulomb_friction_nm, "static_friction_nm": p.static_friction_nm,
            "gravity_moment_nm": p.gravity_moment_nm, "backlash_deg": BACKLASH_DEG if p.backlash_deg is None else p.backlash_deg, "torque_constant_scale": 1.0,
            "current_time_constant_s": p.current_time_constant_s, "imu_lag_s": 0.0195, "imu_bias_deg": 0.0,
            "encoder_offset_deg": 0.0}


def plant_with(base: PlantParams, v: dict[str, float]) -> PlantParams:
    """The base profile with the fit parameters' values in it (the keys each one sets)."""
    g, m = base.gravity_m_s2, base.foot_mass_kg
    d = v["gravity_moment_nm"] / (m * g)
    reflected = base.reflected_inertia_kg_m2
    jc = max(1e-5, v["output_inertia_kg_m2"] - reflected - m * d * d)
    scale = v["torque_constant_scale"]
    tc = v["coulomb_friction_nm"]
    ts = max(v["static_friction_nm"], tc)
    return replace(base, foot_inertia_kg_m2=jc, foot_com_distance_m=d,
                   foot_damping_nm_s_per_rad=v["foot_damping_nm_s_per_rad"], coulomb_friction_nm=tc,
                   actuator_backdrive_torque_nm=ts / base.belt_ratio, kt_nm_per_a=base.kt_nm_per_a * scale,
                   ke_v_s_per_rad=base.ke_v_s_per_rad * scale, current_time_constant_s=v["current_time_constant_s"],
                   backlash_deg=v["backlash_deg"])


@dataclass
class Experiment:
    """What the bench measured: commands (time, A, brake) and samples (time, encoder, IMU, current)."""

    t_cmd: np.ndarray
    i_cmd: np.ndarray
    t: np.ndarray
    angle: np.ndarray
    imu: np.ndarray
    current: np.ndarray
    source: str
    vel: np.ndarray  # the encoder angle's velocity (`encoder_velocity`)

    def interleave(self, every: int, window_s: float = 4 * WINDOW_S) -> tuple[Experiment, Experiment]:
        """(the fitting part, the held-out part): every `every`-th stretch of window_s is held out.

        Stretches are whole numbers of simulation windows, so each is simulated from its own start."""
        k = ((self.t - self.t[0]) // window_s).astype(int)
        held = (k % every) == every - 1
        return self._select(~held), self._select(held)

    def _select(self, keep: np.ndarray) -> Experiment:
        return Experiment(self.t_cmd, self.i_cmd, self.t[keep], self.angle[keep], self.imu[keep], self.current[keep],
                          self.source, self.vel[keep])

    def span(self, t0: float, t1: float) -> Experiment:
        """The part between t0 and t1 (s)."""
        k = (self.t >= t0) & (self.t < t1)
        c = (self.t_cmd >= t0 - 0.01) & (self.t_cmd < t1)
        return Experiment(self.t_cmd[c], self.i_cmd[c], self.t[k], self.angle[k], self.imu[k], self.current[k],
                          self.source, self.vel[k])


def encoder_velocity(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """The encoder angle's velocity: a Savitzky-Golay derivative over about 30 ms (the counts' steps smoothed)."""
    if len(t) < 17:
        return np.zeros_like(t)
    from scipy.signal import savgol_filter

    return savgol_filter(angle, 15, 2, deriv=1, delta=float(np.median(np.diff(t))))


def _commands(record: Path) -> tuple[np.ndarray, np.ndarray]:
    """(times, currents) of the SetCurrent commands the firmware wrote, up to the first brake or stop."""
    from protocol import vesc

    reader = RecordReader(record)
    f_cpu = int(reader.header["f_cpu_hz"])
    dec = vesc.Decoder(direction="to-motor")
    times, currents = [], []
    key = Kind.WRITE << 2
    for s in reader.sections():
        for accepted, data in s.outputs.get(key, ()):
            for msg in dec.feed(data[:accepted]):
                if isinstance(msg, vesc.SetCurrent):
                    times.append(s.start / f_cpu)
                    currents.append(msg.current_a)
                elif isinstance(msg, vesc.SetCurrentBrake):
                    return np.array(times), np.array(currents)
    return np.array(times), np.array(currents)


def load_experiment(run_dir: Path) -> Experiment:
    """The commands (record.bin) and the measurements (telemetry.csv) of a run, over its RUN span.

    ValueError (one line, naming the file) when a file is missing, damaged or holds too little.
    """
    record, tel = run_dir / RECORD_NAME, run_dir / "telemetry.csv"
    for f in (record, tel):
        if not f.is_file():
            raise ValueError(f"{f}: not found (pafp fit reads a run directory with record.bin and telemetry.csv: "
                             "`pafp run --experiment sysid`, or any serial run)")
    t_cmd, i_cmd = _commands(record)
    cols = ("time_s", "encoder_angle_rad", "imu_pitch_rad", "current_meas_a", "supervisor_state_name")
    rows: list[tuple[float, float, float, float]] = []
    with tel.open(encoding="utf-8", newline="") as f:
        reader = csv.DictReader(f)
        missing = [c for c in cols if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{tel}: not a telemetry table (no column {missing[0]!r})")
        started = False
        for line, r in enumerate(reader, start=2):
            if r["supervisor_state_name"] != "RUN":
                if started:
                    break  # the first RUN span only (a fault ends the experiment)
                continue
            started = True
            try:
                rows.append((float(r["time_s"]), float(r["encoder_angle_rad"]), float(r["imu_pitch_rad"]),
                             float(r["current_meas_a"])))
            except ValueError:
                raise ValueError(f"{tel}: line {line} is not numeric") from None
    if len(rows) < 100 or len(t_cmd) < 100:
        raise ValueError(f"{run_dir}: too short to fit: {len(rows)} samples in RUN and {len(t_cmd)} current "
                         "commands (at least 100 of each; run `pafp run --experiment sysid`)")
    a = np.array(rows)
    return Experiment(t_cmd, i_cmd, a[:, 0], a[:, 1], a[:, 2], a[:, 3], str(run_dir),
                      encoder_velocity(a[:, 0], a[:, 1]))


COMMAND_DELAY_S = 1.5e-4  # a command reaches the motor this long after its job starts (frame at 921600 baud)


def simulate(base: PlantParams, v: dict[str, float], exp: Experiment,
             window_s: float = WINDOW_S) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(angle as the encoder reads it, current as the firmware last heard it, IMU pitch, used-sample mask)
    simulated at exp.t, each window of window_s from the measured state.

    The measured current a telemetry sample carries is the motor's reply to the previous period's request,
    and the driver reports the mean current since the request before (ak60_meter.py, as VESC's
    ``read_reset_avg``): the model takes the exact mean of the first-order lag over that interval.
    """
    params = plant_with(base, v)
    offset = math.radians(v["encoder_offset_deg"])
    backlash = math.radians(v["backlash_deg"])
    bias = math.radians(v["imu_bias_deg"])
    lag = max(1e-6, v["imu_lag_s"])
    n = len(exp.t)
    angle, current, imu = np.zeros(n), np.zeros(n), np.zeros(n)
    mask = np.ones(n, dtype=bool)
    vel = exp.vel
    fixture = suspended()
    lo, hi = params.stop_min_rad, params.stop_max_rad
    t_cmd, i_cmd = exp.t_cmd, exp.i_cmd
    n_cmd = len(t_cmd)
    k = 0
    while k < n:
        t0 = float(exp.t[k])
        end = max(int(np.searchsorted(exp.t, t0 + window_s)), k + 1)
        start_angle = min(hi, max(lo, exp.angle[k] + offset))
        v0 = float(vel[k])
        plant = Plant(params, fixture, initial_angle_rad=start_angle,
                      initial_velocity_rad_s=0.0 if abs(v0) < REST_RAD_S else v0, start_time_s=t0,
                      backlash_rad=backlash, initial_current_a=float(exp.current[k]))
        c = int(np.searchsorted(t_cmd, t0, side="right")) - 1
        if c >= 0:
            plant.set_current_command(float(i_cmd[c]), t0)
        c += 1
        tau = params.current_time_constant_s
        peak = params.peak_current_a
        t_last = t0
        i_last = plant.current_q_a(t0)
        heard = prev_heard = i_last  # the mean currents the last two replies carried
        target = max(-peak, min(peak, float(i_cmd[c - 1]))) if c >= 1 else 0.0
        filt = exp.imu[k] - bias
        t_prev = t0
        for j in range(k, end):
            tj = float(exp.t[j])
            while c < n_cmd and t_cmd[c] <= tj:
                ta = float(t_cmd[c]) + COMMAND_DELAY_S
                if ta > tj:
                    break
                i_now = plant.current_q_a(ta)
                span = ta - t_last
                mean = target + (i_last - target) * (tau / span) * (1.0 - math.exp(-span / tau)) if span > 0 else i_now
                prev_heard, heard = heard, mean
                t_last, i_last = ta, i_now
                target = max(-peak, min(peak, float(i_cmd[c])))
                plant.set_current_command(float(i_cmd[c]), ta)
                c += 1
            th = plant.output_angle_rad(tj)
            angle[j] = th - offset
            current[j] = prev_heard
            filt += (th - filt) * (1.0 - math.exp(-(tj - t_prev) / lag))
            t_prev = tj
            imu[j] = filt + bias
            if tj - t0 < SKIP_S:
                mask[j] = False
        k = end
    return angle, current, imu, mask


def window_ids(exp: Experiment, window_s: float = WINDOW_S) -> np.ndarray:
    """The simulation window of each used sample (as `simulate` cuts them), in the order `residuals` lists them."""
    ids = np.zeros(len(exp.t), dtype=int)
    k, w = 0, 0
    while k < len(exp.t):
        end = max(int(np.searchsorted(exp.t, exp.t[k] + window_s)), k + 1)
        ids[k:end] = w
        k, w = end, w + 1
    mask = exp.t - exp.t[ids_start(ids)] >= SKIP_S
    return ids[mask]


def ids_start(ids: np.ndarray) -> np.ndarray:
    """For each sample, the index of its window's first sample."""
    first = np.r_[0, np.flatnonzero(np.diff(ids)) + 1]
    return first[ids]


def residuals(base: PlantParams, v: dict[str, float], exp: Experiment) -> np.ndarray:
    """The scaled simulation errors: encoder angle, measured current and IMU pitch, on the used samples."""
    angle, current, imu, mask = simulate(base, v, exp)
    return np.concatenate([(angle - exp.angle)[mask] / SIGMA["angle"], (current - exp.current)[mask] / SIGMA["current"],
                           (imu - exp.imu)[mask] / SIGMA["imu"]])


def fit_percentage(y: np.ndarray, y_hat: np.ndarray) -> float:
    """100 (1 - |y - y_hat| / |y - mean y|), as MATLAB's compare reports it (-inf..100).

    >>> round(fit_percentage(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0])), 1)
    100.0
    """
    den = float(np.linalg.norm(y - np.mean(y)))
    if den == 0.0:
        return float("nan")
    return 100.0 * (1.0 - float(np.linalg.norm(y - y_hat)) / den)


def load_base(path: Path | None) -> PlantParams:
    """The plant profile the fit starts from and whose other keys it keeps (default: the packaged one)."""
    return load_plant_params(path)



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
    fit_part, held = exp.interleave(HELD_OUT_EVERY)
    start = base_values(base)
    lo = np.array([PARAMS[n].lo for n in names])
    hi = np.array([PARAMS[n].hi for n in names])
    x0 = np.clip(np.array([start[n] for n in names]), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
    scale = np.maximum(np.abs(x0), 0.05 * (hi - lo))

    def values(x: np.ndarray) -> dict[str, float]:
        return {**start, **{n: float(v) for n, v in zip(names, x, strict=True)}}

    def fun(x: np.ndarray) -> np.ndarray:
        return residuals(base, values(x), fit_part)

    res = least_squares(fun, x0, bounds=(lo, hi), x_scale=scale, diff_step=1e-3, max_nfev=max_nfev,
                        method="trf")
    jac = np.asarray(res.jac)
    m, n = jac.shape
    s2 = 2.0 * float(res.cost) / max(1, m - n)
    r = np.asarray(res.fun)
    rho = float(np.clip(np.dot(r[1:], r[:-1]) / max(float(np.dot(r, r)), 1e-300), 0.0, 0.999))
    inflation = (1.0 + rho) / (1.0 - rho)  # AR(1) residuals: m samples carry m (1 - rho) / (1 + rho) of information
    bread = np.linalg.pinv(jac.T @ jac)
    # cluster-robust ("sandwich") covariance with each simulation window as a cluster: the errors within a
    # window are one trajectory's, correlated, whatever their shape; the larger of the two is reported
    clusters = np.tile(window_ids(fit_part), 3)
    scores = jac * r[:, None]
    meat = np.zeros((n, n))
    for c in np.unique(clusters):
        g = scores[clusters == c].sum(axis=0)
        meat += np.outer(g, g)
    cov = np.maximum(inflation * s2 * bread, bread @ meat @ bread)
    ci = 1.96 * np.sqrt(np.clip(np.diag(cov), 0, None))
    coll, corr = _collinearity(jac)
    v = values(res.x)
    ident = {}
    norms = np.linalg.norm(jac, axis=0)
    for k, name in enumerate(names):
        ok = coll[k] <= COLLINEARITY_LIMIT and norms[k] > 1e-9 * max(1.0, float(norms.max()))
        if name in _ZERO_OK:
            ok = ok and ci[k] <= _ABS_CI[name]
        else:
            ok = ok and ci[k] <= REL_CI_LIMIT * abs(v[name])
        ident[name] = bool(ok)
    fixed_checks = {}
    if "torque_constant_scale" not in names:  # the one a current-only torque measure cannot separate
        h = 1e-2
        plus = residuals(base, {**v, "torque_constant_scale": v["torque_constant_scale"] + h}, fit_part)
        col = ((plus - res.fun) / h)[:, None]
        c_all, _ = _collinearity(np.hstack([jac, col]))
        fixed_checks["torque_constant_scale"] = float(c_all[-1])
    pct = {}
    for label, part in (("fit", fit_part), ("held_out", held)):
        a, c, i, mask = simulate(base, v, part)
        pct[label] = {"angle": fit_percentage(part.angle[mask], a[mask]),
                      "current": fit_percentage(part.current[mask], c[mask]),
                      "imu": fit_percentage(part.imu[mask], i[mask])}
    return FitResult(tuple(names), v, start, {nm: float(ci[k]) for k, nm in enumerate(names)},
                     {nm: float(coll[k]) for k, nm in enumerate(names)}, ident, corr, pct, int(res.nfev),
                     float(res.cost), time.perf_counter() - wall0, (t0, t1), str(res.message),
                     fixed_checks)

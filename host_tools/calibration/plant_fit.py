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

BACKLASH_DEG = 0.55  # the maker's (bench_imperfections.toml [gearbox_backlash]) for a base without the key
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
    # at most 0.8 ms: the record shows the firmware reading most replies one 1 ms period after their request, so the
    # request (after the command, with its own wire time) arrived sooner; a longer delay would also leave samples
    # whose reply's request has not yet arrived in the simulation, which then carry the measured current (no error)
    FitParam("command_delay_s", "s", 0.0, 8e-4, "when a command reaches the motor after its job's start"),
    FitParam("imu_lag_s", "s", 1e-4, 0.1, "IMU pitch lag (first order, with the frame hold)"),
    FitParam("imu_bias_deg", "deg", -6.0, 6.0, "IMU pitch bias"),
    FitParam("encoder_offset_deg", "deg", -4.0, 4.0, "true angle minus the encoder's at power-up"),
)}
# backlash is not in the least squares: its effect (a dead time at each reversal of the command) moves the
# residuals in steps a finite-difference Jacobian sees as zero or as a spurious slope; it is profiled over a grid
# (`_backlash_profile`, docs/calibration.md)
DEFAULT_FIT = ("output_inertia_kg_m2", "foot_damping_nm_s_per_rad", "coulomb_friction_nm", "static_friction_nm",
               "gravity_moment_nm", "backlash_deg", "current_time_constant_s", "imu_lag_s", "imu_bias_deg",
               "encoder_offset_deg")


def base_values(p: PlantParams) -> dict[str, float]:
    """The fit parameters' values of a plant profile (the start of the search; measurement ones at 0)."""
    return {"output_inertia_kg_m2": p.output_inertia_kg_m2, "foot_damping_nm_s_per_rad": p.foot_damping_nm_s_per_rad,
            "coulomb_friction_nm": p.coulomb_friction_nm, "static_friction_nm": p.static_friction_nm,
            "gravity_moment_nm": p.gravity_moment_nm,
            "backlash_deg": BACKLASH_DEG if p.backlash_deg is None else p.backlash_deg, "torque_constant_scale": 1.0,
            "current_time_constant_s": p.current_time_constant_s, "command_delay_s": COMMAND_DELAY_S,
            "imu_lag_s": 0.0195, "imu_bias_deg": 0.0,
            "encoder_offset_deg": 0.0}


def plant_with(base: PlantParams, v: dict[str, float]) -> PlantParams:
    """The base profile with the fit parameters' values in it (the keys each one sets)."""
    g, m = base.gravity_m_s2, base.foot_mass_kg
    d = v["gravity_moment_nm"] / (m * g)
    reflected = base.reflected_inertia_kg_m2
    jc = max(1e-5, v["output_inertia_kg_m2"] - reflected - m * d * d)
    scale = v["torque_constant_scale"]
    backdrive = max(v["static_friction_nm"], v["coulomb_friction_nm"]) / base.belt_ratio
    tc = min(v["coulomb_friction_nm"], backdrive * base.belt_ratio)  # the same product the profile's check takes
    return replace(base, foot_inertia_kg_m2=jc, foot_com_distance_m=d,
                   foot_damping_nm_s_per_rad=v["foot_damping_nm_s_per_rad"], coulomb_friction_nm=tc,
                   actuator_backdrive_torque_nm=backdrive, kt_nm_per_a=base.kt_nm_per_a * scale,
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
    t_req: np.ndarray  # when each feedback request reached the motor at COMMAND_DELAY_S (the averages reset there)
    req_of: np.ndarray  # per sample: the request whose reply its current is (index into t_req; -1: none yet)
    angle_from_reply: bool = False  # the encoder angle is the motor reply's position (serial mode's `--encoder motor`)

    def interleave(self, every: int, window_s: float = 4 * WINDOW_S) -> tuple[Experiment, Experiment]:
        """(the fitting part, the held-out part): every `every`-th stretch of window_s is held out.

        Stretches are whole numbers of simulation windows, so each is simulated from its own start."""
        k = ((self.t - self.t[0]) // window_s).astype(int)
        held = (k % every) == every - 1
        return self._select(~held), self._select(held)

    def _select(self, keep: np.ndarray) -> Experiment:
        return Experiment(self.t_cmd, self.i_cmd, self.t[keep], self.angle[keep], self.imu[keep], self.current[keep],
                          self.source, self.vel[keep], self.t_req, self.req_of[keep], self.angle_from_reply)

    def span(self, t0: float, t1: float) -> Experiment:
        """The part between t0 and t1 (s)."""
        k = (self.t >= t0) & (self.t < t1)
        c = (self.t_cmd >= t0 - 0.01) & (self.t_cmd < t1)
        return Experiment(self.t_cmd[c], self.i_cmd[c], self.t[k], self.angle[k], self.imu[k], self.current[k],
                          self.source, self.vel[k], self.t_req, self.req_of[k], self.angle_from_reply)


def encoder_velocity(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """The encoder angle's velocity: a Savitzky-Golay derivative over about 30 ms (the counts' steps smoothed)."""
    if len(t) < 17:
        return np.zeros_like(t)
    from scipy.signal import savgol_filter

    return savgol_filter(angle, 15, 2, deriv=1, delta=float(np.median(np.diff(t))))


COMMAND_DELAY_S = 1.5e-4  # a command reaches the motor this long after its job starts (frame at 921600 baud)
_COMMAND_FRAME_BYTES = 10  # a SetCurrent frame: start, length, id, 4 bytes, CRC, end
FREE_V0 = True  # each moving window's initial velocity is projected out (`_project_initial_velocity`)
FREE_IMU_OFFSET = True  # each window's IMU offset is projected out (the bias drifts over the experiment)


@dataclass
class _Wire:
    """What the motor port carried: the current commands, the feedback requests and when replies came in."""

    t_cmd: np.ndarray  # job start of each SetCurrent (s)
    i_cmd: np.ndarray  # its current (A)
    t_req: np.ndarray  # when each feedback request reached the motor at COMMAND_DELAY_S (s)
    t_req_job: np.ndarray  # the job start that sent it (s)
    t_reply: np.ndarray  # job starts whose read brought a feedback reply (s)


def _wire(record: Path) -> _Wire:
    """The motor port's traffic in a record, up to the first brake or stop.

    A write is the command frame then (usually) a feedback request: the request reaches the motor
    COMMAND_DELAY_S plus its own frame's wire time after the job's start (`simulate` moves it by a fitted
    `command_delay_s`'s difference); the driver's averages (``avg_iq``) reset there. A reply is the firmware's
    from the job whose read decoded it.
    """
    from protocol import vesc
    from protocol.vesc_values import Values, ValuesSelective

    reader = RecordReader(record)
    f_cpu = int(reader.header["f_cpu_hz"])
    baud = float(reader.header.get("ports", {}).get("motor", {}).get("baud", 921600))
    to_motor, from_motor = vesc.Decoder(direction="to-motor"), vesc.Decoder(direction="from-motor")
    times, currents, t_req, t_req_job, t_reply = [], [], [], [], []
    write_key, read_key = Kind.WRITE << 2, Kind.READ << 2
    for s in reader.sections():
        t = s.start / f_cpu
        for data in s.inputs.get(read_key, ()):
            if any(isinstance(m, (Values, ValuesSelective)) for m in from_motor.feed(data)):
                t_reply.append(t)
        for accepted, data in s.outputs.get(write_key, ()):
            sent = data[:accepted]
            for msg in to_motor.feed(sent):
                if isinstance(msg, vesc.SetCurrent):
                    times.append(t)
                    currents.append(msg.current_a)
                elif isinstance(msg, (vesc.GetValues, vesc.GetValuesSelective)) and times and times[-1] == t:
                    frame = len(sent) - _COMMAND_FRAME_BYTES  # the request's frame follows the command's
                    t_req.append(t + COMMAND_DELAY_S + 10.0 * max(frame, 0) / baud)
                    t_req_job.append(t)
                elif isinstance(msg, vesc.SetCurrentBrake):
                    return _Wire(*(np.array(x) for x in (times, currents, t_req, t_req_job, t_reply)))
    return _Wire(*(np.array(x) for x in (times, currents, t_req, t_req_job, t_reply)))


def _reply_requests(t: np.ndarray, w: _Wire) -> np.ndarray:
    """Per sample: the request the current it carries answers (-1: none). A sample shows the last reply the
    firmware read at or before it, and a reply answers the last request sent before the job that read it
    (a full GET_VALUES reply takes most of a period, so the next period sends no request)."""
    if len(w.t_reply) == 0 or len(w.t_req_job) == 0:
        return np.full(len(t), -1)
    reply = np.searchsorted(w.t_reply, t, side="right") - 1
    answered = np.searchsorted(w.t_req_job, w.t_reply, side="left") - 1
    return np.where(reply >= 0, answered[np.maximum(reply, 0)], -1)


def load_experiment(run_dir: Path) -> Experiment:
    """The commands (record.bin) and the measurements (telemetry.csv) of a run, over its RUN span.

    ValueError (one line, naming the file) when a file is missing, damaged or holds too little.
    """
    record, tel = run_dir / RECORD_NAME, run_dir / "telemetry.csv"
    for f in (record, tel):
        if not f.is_file():
            raise ValueError(f"{f}: not found (pafp fit reads a run directory with record.bin and telemetry.csv: "
                             "`pafp run --experiment sysid`, or any serial run)")
    w = _wire(record)
    t_cmd, i_cmd = w.t_cmd, w.i_cmd
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
                      encoder_velocity(a[:, 0], a[:, 1]), w.t_req, _reply_requests(a[:, 0], w),
                      _encoder_source(run_dir) == "motor")


def _encoder_source(run_dir: Path) -> str:
    """Where a serial run's encoder angle came from (summary.json's ``encoder_source``; "" for the virtual bench,
    whose encoder reads the plant at the job's time). ValueError (one line) for a damaged summary."""
    import json

    summary = run_dir / "summary.json"
    if not summary.is_file():
        return ""
    try:
        return str(json.loads(summary.read_text(encoding="utf-8")).get("encoder_source", ""))
    except (ValueError, AttributeError):
        raise ValueError(f"{summary}: not a run summary (not a JSON object)") from None




def simulate(base: PlantParams, v: dict[str, float], exp: Experiment, window_s: float = WINDOW_S,
             free_v0: bool = FREE_V0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(angle as the encoder reads it, current as the firmware last heard it, IMU pitch, used-sample mask)
    simulated at exp.t, each window of window_s from the measured state.

    The measured current a telemetry sample carries is the mean the driver reported (``avg_iq``, reset at
    each request: ak60_meter.py, as VESC's ``read_reset_avg``) in the last reply the firmware read: the mean
    between the two requests before it (`Experiment.req_of`). As the driver's meter does, the mean integrates
    the first-order lag towards the command from the plant's current at each event (a command or a request
    reaching the motor): while the rotor crosses the backlash the plant's current falls towards 0
    (hal/virtual/plant/model.py, Plant._cross_gap) and each event restarts the integral from it.
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
    delay = v.get("command_delay_s", COMMAND_DELAY_S)
    t_cmd, i_cmd, t_req, req_of = exp.t_cmd, exp.i_cmd, exp.t_req + (delay - COMMAND_DELAY_S), exp.req_of
    n_cmd, n_req = len(t_cmd), len(t_req)
    tau = params.current_time_constant_s
    peak = params.peak_current_a
    k = 0
    while k < n:
        t0 = float(exp.t[k])
        end = max(int(np.searchsorted(exp.t, t0 + window_s)), k + 1)
        start_angle = min(hi, max(lo, exp.angle[k] + offset))
        v0 = float(vel[k])
        moving = abs(v0) >= REST_RAD_S
        i0 = float(exp.current[k])
        plant = Plant(params, fixture, initial_angle_rad=start_angle, initial_velocity_rad_s=v0 if moving else 0.0,
                      start_time_s=t0, backlash_rad=backlash, initial_current_a=i0)
        c = int(np.searchsorted(t_cmd, t0 - delay, side="right")) - 1  # the command acting at t0
        if c >= 0:
            plant.set_current_command(float(i_cmd[c]), t0)
        target = max(-peak, min(peak, float(i_cmd[c - 1]))) if c >= 1 else 0.0
        c += 1
        r = int(np.searchsorted(t_req, t0, side="right"))  # the next request to reach the motor
        means: dict[int, float] = {}  # request index -> the mean its reply carries
        positions: dict[int, float] = {}  # request index -> the output angle its reply carries
        r_prev = r - 1
        t_mark = float(t_req[r_prev]) if r_prev >= 0 else t0  # the driver's averages reset here
        acc = i0 * (t0 - t_mark)  # before t0 the current is taken as the measured one
        t_last, i_last = t0, i0
        # the IMU's lag state: following the start's motion (its offset at the start is the window's own, below)
        filt = start_angle - lag * (v0 if moving else 0.0)
        t_prev = t0
        for j in range(k, end):
            tj = float(exp.t[j])
            while True:  # the events up to tj, in time order: commands arriving, requests arriving
                ta = float(t_cmd[c]) + delay if c < n_cmd else math.inf
                tr = float(t_req[r]) if r < n_req else math.inf
                te = min(ta, tr)
                if te > tj:
                    break
                span = te - t_last
                if span > 0:
                    acc += target * span + (i_last - target) * tau * -math.expm1(-span / tau)
                    i_last, t_last = plant.current_q_a(te), te
                if tr <= ta:
                    means[r] = acc / (te - t_mark) if te > t_mark else i_last
                    positions[r] = plant.output_angle_rad(te)
                    acc, t_mark = 0.0, te
                    r += 1
                else:
                    plant.set_current_command(float(i_cmd[c]), te)
                    target = max(-peak, min(peak, float(i_cmd[c])))
                    c += 1
            th = plant.output_angle_rad(tj)
            q = int(req_of[j])
            # through serial mode the encoder angle is the position of the last reply read, taken when its request
            # reached the motor; on the virtual bench the encoder reads the plant at the sample's time
            angle[j] = (positions.get(q, th) if exp.angle_from_reply else th) - offset
            heard = means.get(q)
            # None: its request reached the motor before this window (only within SKIP_S of its start, unused)
            current[j] = exp.current[j] if heard is None else heard
            filt += (th - filt) * (1.0 - math.exp(-(tj - t_prev) / lag))
            t_prev = tj
            imu[j] = filt + bias
            if tj - t0 < SKIP_S:
                mask[j] = False
        if free_v0 and moving:
            _project_initial_velocity(exp, k, end, t0, angle, imu, mask, params)
        if FREE_IMU_OFFSET:
            used = mask[k:end]
            if used.any():  # the IMU's bias drifts (Gauss-Markov, tau ~10 s): each window's own offset
                imu[k:end] += float(np.mean((exp.imu[k:end] - imu[k:end])[used]))
        k = end
    return angle, current, imu, mask


def _project_initial_velocity(exp: Experiment, k: int, end: int, t0: float, angle: np.ndarray, imu: np.ndarray,
                              mask: np.ndarray, params: PlantParams) -> None:
    """Correct window [k, end)'s simulation for the least-squares initial velocity (in place).

    The window starts at the encoder's velocity estimate, which a smoothing derivative attenuates at the
    chirp's and the PRBS's frequencies (a 15-sample quadratic Savitzky-Golay slope keeps 89 % of a 12 Hz
    sine's): a start that is systematically too slow, which the fit made up for with a longer mechanical
    time constant (inertia up, damping down: the bias docs/calibration.md used to report). Each moving window's
    initial velocity is instead a nuisance parameter, eliminated by variable projection: a velocity error dv
    moves the angle by dv * tm * (1 - exp(-t / tm)) (tm = J / b, the free motion's decay), the projection takes
    the dv that best explains the window's encoder residual, as MATLAB's ``compare`` estimates initial
    conditions. The IMU, which sees the same angle through a lag of a few tens of ms, gets the same shift.
    """
    tm = params.output_inertia_kg_m2 / max(params.foot_damping_nm_s_per_rad, 1e-9)
    t = exp.t[k:end] - t0
    sens = tm * -np.expm1(-t / tm)
    used = mask[k:end]
    ss = float(np.dot(sens[used], sens[used]))
    if ss <= 0.0:
        return
    dv = -float(np.dot((angle[k:end] - exp.angle[k:end])[used], sens[used])) / ss
    angle[k:end] += dv * sens
    imu[k:end] += dv * sens


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
    jac_names: tuple[str, ...] = ()  # the parameters of the Jacobian (and `correlations`), in its order


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
    # the encoder's zero is where the foot was at power-up: set at its zero mark by eye, within a degree or so
    # (the offset starts at 0), unless the IMU's absolute pitch over the first 0.2 s says it was further off than
    # the offset's bounds (a serial bench's foot may have hung on its stop): then +-4 deg around the IMU's figure
    first = exp.t < exp.t[0] + 0.2
    zero = round(math.degrees(float(np.median((exp.imu - exp.angle)[first]))), 3)
    zero = zero if abs(zero) > PARAMS["encoder_offset_deg"].hi else 0.0
    start["encoder_offset_deg"] = zero
    all_names = tuple(names)
    scan = "backlash_deg" in names  # profiled, not in the least squares (`_backlash_profile`)
    names = tuple(n for n in names if n != "backlash_deg")
    lo = np.array([PARAMS[n].lo + (zero if n == "encoder_offset_deg" else 0.0) for n in names])
    hi = np.array([PARAMS[n].hi + (zero if n == "encoder_offset_deg" else 0.0) for n in names])
    x0 = np.clip(np.array([start[n] for n in names]), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
    scale = np.maximum(np.abs(x0), 0.05 * (hi - lo))

    def values(x: np.ndarray) -> dict[str, float]:
        return {**start, **{n: float(v) for n, v in zip(names, x, strict=True)}}

    def fun(x: np.ndarray) -> np.ndarray:
        return residuals(base, values(x), fit_part)

    res = least_squares(fun, x0, bounds=(lo, hi), x_scale=scale, diff_step=1e-3, max_nfev=max_nfev,
                        method="trf")
    profile: tuple[float, float, bool] | None = None
    if scan:  # over the whole grid, the others at their fit (from a start far off, the grid misleads: not before)
        profile = _backlash_profile(base, values(res.x), fit_part, res)
        if abs(profile[0] - start["backlash_deg"]) > BACKLASH_REFIT_DEG:  # the others again, at the profile's best
            start = {**start, "backlash_deg": profile[0]}
            res = least_squares(fun, res.x, bounds=(lo, hi), x_scale=scale, diff_step=1e-3, max_nfev=max_nfev,
                                method="trf")
            profile = _backlash_profile(base, values(res.x), fit_part, res, around=profile[0])
    jac, r = _secant_jacobian(lambda x: residuals(base, values(x), fit_part), np.asarray(res.x), scale)
    m, n = jac.shape
    s2 = float(np.dot(r, r)) / max(1, m - n)
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
    if profile is not None:
        v["backlash_deg"] = profile[0]
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
        col = ((plus - residuals(base, v, fit_part)) / h)[:, None]
        c_all, _ = _collinearity(np.hstack([jac, col]))
        fixed_checks["torque_constant_scale"] = float(c_all[-1])
    pct = {}
    for label, part in (("fit", fit_part), ("held_out", held)):
        a, c, i, mask = simulate(base, v, part)
        pct[label] = {"angle": fit_percentage(part.angle[mask], a[mask]),
                      "current": fit_percentage(part.current[mask], c[mask]),
                      "imu": fit_percentage(part.imu[mask], i[mask])}
    ci95 = {nm: float(ci[k]) for k, nm in enumerate(names)}
    collinearity = {nm: float(coll[k]) for k, nm in enumerate(names)}
    if profile is not None:  # its interval from the profile; not in the Jacobian, so no collinearity index
        ci95["backlash_deg"], collinearity["backlash_deg"], ident["backlash_deg"] = profile[1], math.nan, profile[2]
    start = {**start, "backlash_deg": base_values(base)["backlash_deg"]}  # what the fit started from
    return FitResult(all_names, v, start, ci95, collinearity, ident, corr, pct, int(res.nfev),
                     float(res.cost), time.perf_counter() - wall0, (t0, t1), str(res.message),
                     fixed_checks, tuple(names))


SECANT_STEP = 0.02  # of each parameter's scale: the step of the Jacobian the intervals come from


def _secant_jacobian(fun, x: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Jacobian from forward steps of SECANT_STEP x each parameter's scale, the residuals at x).

    The solver's own Jacobian takes tiny steps (1e-3 relative): the simulation's stick-slip and backlash switch
    discretely, so a tiny step that flips one of them gives a column made of the jump -- and an interval that
    is confidently narrow and wrong (seen: an encoder offset 85 half-widths off; a Coulomb friction column 3.8
    times too steep). A step of 2 % of the scale averages over many switchings: the intervals are taken from it.
    """
    r0 = fun(x)
    cols = []
    for k in range(len(x)):
        h = SECANT_STEP * float(scale[k])
        xk = x.copy()
        xk[k] += h
        cols.append((fun(xk) - r0) / h)
    return np.column_stack(cols), r0


BACKLASH_GRID_DEG = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 5.0)
BACKLASH_REFIT_DEG = 0.1  # the others are fitted again when the profile's best is further than this from the start


def _backlash_profile(base: PlantParams, v: dict[str, float], part: Experiment, res: object,
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
    cost = np.array([0.5 * float(np.sum(residuals(base, {**v, "backlash_deg": float(b)}, part) ** 2)) for b in grid])
    k = int(np.argmin(cost))
    r = np.asarray(res.fun)  # type: ignore[attr-defined]
    m, n = len(r), len(np.asarray(res.x))  # type: ignore[attr-defined]
    s2 = float(np.dot(r, r)) / max(1, m - n)
    rho = float(np.clip(np.dot(r[1:], r[:-1]) / max(float(np.dot(r, r)), 1e-300), 0.0, 0.999))
    threshold = 0.5 * 3.841 * s2 * (1.0 + rho) / (1.0 - rho)
    best = float(grid[k])
    if 0 < k < len(grid) - 1:  # the parabola through the best and its neighbours
        x, y = grid[k - 1:k + 2], cost[k - 1:k + 2]
        a = np.polyfit(x, y, 2)
        if a[0] > 0:
            best = float(np.clip(-a[1] / (2 * a[0]), x[0], x[2]))
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

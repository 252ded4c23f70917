"""`pafp fit`'s model: the fit parameters and the windowed simulation of the bench that the fit minimises.

The model is the plant of the virtual bench itself (`hal.virtual.plant.Plant`, the code the bench runs),
driven by the recorded commands. Its simulation error is taken over windows of ``WINDOW_S``: each window
starts from the measured angle and velocity (the suspended foot under gravity is not self-regulating, so
one 30 s open-loop simulation drifts with any error in the gravity moment; windows keep the error about
the dynamics), and the residuals are the encoder angle, the measured current and the IMU pitch (through
a first-order lag and a bias), each divided by its noise scale (`residuals`). What a window does not know of its
start is a nuisance, taken from its own data: the initial velocity and, in a moving window, where in its count the
angle starts (`_project_initial_velocity`, `_project_along`), whether a foot
the encoder shows at rest is stuck or at the turn of a slide (`_slow_start`), the IMU's offset and its lag's start
state (`_project_imu_start`). The plant places its friction's switchings (reversal, stick, breakaway) where they
happen inside its 0.1 ms step (`Plant(located_switching=True)`); the bench's plant switches on the grid, which made
the cost jump as a parameter moved a switching across a grid point (docs/calibration.md, "Rounding").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hal.virtual.plant import PlantParams, load_plant_params
from host_tools.calibration.fit_data import COMMAND_DELAY_S, WINDOW_S, Experiment
from host_tools.calibration.fit_memo import recall, remembered
from host_tools.calibration.fit_window import Events, run_plant, window_key

__all__ = ["DEFAULT_FIT", "IMU_FRAME_AGE_S", "PARAMS", "SIGMA", "FitParam", "base_values", "encoder_step",
           "fit_percentage", "fit_percentages", "noise_scales", "plant_with", "residuals", "rotor_side_sd", "simulate",
           "stuck_starts", "windows"]

BACKLASH_DEG = 0.55  # the maker's (bench_imperfections.toml [gearbox_backlash]) for a base without the key

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
    # the rotor's acceleration per ampere (Kt / J_m): it alone carries the rotor across the backlash at each
    # reversal (the output's torque per ampere and inertia are fitted); it makes a narrow valley with the backlash
    # that least squares cannot follow, so it is fitted by its profile (`fit_profiles.rotor_profile`), never in the
    # least squares
    FitParam("rotor_accel_scale", "", 0.7, 1.3, "the rotor's Kt/J_m relative to the base profile's"),
    FitParam("current_time_constant_s", "s", 1e-4, 0.01, "driver current lag"),
    # at most 0.8 ms: the record shows the firmware reading most replies one 1 ms period after their request, so the
    # request (after the command, with its own wire time) arrived sooner; a longer delay would also leave samples
    # whose reply's request has not yet arrived in the simulation, which then carry the measured current (no error)
    FitParam("command_delay_s", "s", 0.0, 8e-4, "when a command reaches the motor after its job's start"),
    FitParam("imu_lag_s", "s", 1e-4, 0.1, "IMU pitch lag (first order, with the frame hold)"),
    FitParam("imu_bias_deg", "deg", -6.0, 6.0, "IMU pitch bias"),
    FitParam("encoder_offset_deg", "deg", -4.0, 4.0, "true angle minus the encoder's at power-up"),
)}
# backlash is not in the first least squares: its effect (a dead time at each reversal of the command) moves the
# residuals in steps a finite-difference Jacobian sees as zero or as a spurious slope; it is profiled over a grid
# (`backlash_profile`, docs/calibration.md)
DEFAULT_FIT = ("output_inertia_kg_m2", "foot_damping_nm_s_per_rad", "coulomb_friction_nm", "static_friction_nm",
               "gravity_moment_nm", "backlash_deg", "current_time_constant_s", "imu_lag_s", "encoder_offset_deg",
               "rotor_accel_scale")


def base_values(p: PlantParams) -> dict[str, float]:
    """The fit parameters' values of a plant profile (the start of the search; measurement ones at 0)."""
    return {"output_inertia_kg_m2": p.output_inertia_kg_m2, "foot_damping_nm_s_per_rad": p.foot_damping_nm_s_per_rad,
            "coulomb_friction_nm": p.coulomb_friction_nm, "static_friction_nm": p.static_friction_nm,
            "gravity_moment_nm": p.gravity_moment_nm,
            "backlash_deg": BACKLASH_DEG if p.backlash_deg is None else p.backlash_deg, "torque_constant_scale": 1.0,
            "rotor_accel_scale": 1.0, "current_time_constant_s": p.current_time_constant_s,
            "command_delay_s": COMMAND_DELAY_S,
            "imu_lag_s": 0.0195, "imu_bias_deg": 0.0,
            "encoder_offset_deg": 0.0}


def plant_with(base: PlantParams, v: dict[str, float]) -> PlantParams:
    """The base profile with the fit parameters' values in it (the keys each one sets)."""
    g, m = base.gravity_m_s2, base.foot_mass_kg
    d = v["gravity_moment_nm"] / (m * g)
    # the rotor's Kt/J_m relative to the base's (with Kt's scale): J_m moves, and the reflected inertia with it; the
    # foot's part takes up the difference (the output inertia is the fitted one)
    j_m = base.rotor_inertia_kg_m2 / v.get("rotor_accel_scale", 1.0)
    reflected = base.reflected_inertia_kg_m2 + (j_m - base.rotor_inertia_kg_m2) * base.total_ratio ** 2
    jc = max(1e-5, v["output_inertia_kg_m2"] - reflected - m * d * d)
    scale = v["torque_constant_scale"]
    backdrive = max(v["static_friction_nm"], v["coulomb_friction_nm"]) / base.belt_ratio
    tc = min(v["coulomb_friction_nm"], backdrive * base.belt_ratio)  # the same product the profile's check takes
    return replace(base, foot_inertia_kg_m2=jc, foot_com_distance_m=d,
                   foot_damping_nm_s_per_rad=v["foot_damping_nm_s_per_rad"], coulomb_friction_nm=tc,
                   actuator_backdrive_torque_nm=backdrive, kt_nm_per_a=base.kt_nm_per_a * scale,
                   ke_v_s_per_rad=base.ke_v_s_per_rad * scale, rotor_inertia_kg_m2=j_m,
                   current_time_constant_s=v["current_time_constant_s"], backlash_deg=v["backlash_deg"])


def rotor_side_sd(base: PlantParams, path: Path | None = None) -> float:
    """The relative spread of the bench's rotor acceleration per ampere (Kt / J_m) about the base profile's: the
    RMS deviation from the base of Kt and of J_m drawn within their tolerances (profiles/plant_tolerances.toml),
    in quadrature (drawn independently). The tolerance table's Kt range is not centred on the packaged 0.078 N m/A
    (0.068-0.080: the mean 5 % below), so the RMS about the base takes in that offset: 7.4 % for the packaged
    profile. 0 when the table gives neither."""
    from hal.virtual.plant.draw import load_tolerances

    tol = {t.name: t for t in load_tolerances(path)}
    total = 0.0
    for key in ("kt_nm_per_a", "rotor_inertia_kg_m2"):
        if key in tol:
            x0 = float(getattr(base, key))
            lo, hi = tol[key].bounds(x0)
            total += ((hi - lo) ** 2 / 12.0 + (0.5 * (lo + hi) - x0) ** 2) / (x0 * x0)
    return math.sqrt(total)


FREE_V0 = True  # each moving window's initial velocity is projected out (`_project_initial_velocity`)
# each window's IMU offset (its bias drifts over the experiment) and the transient of its lag's unknown start state
# are projected out (`_project_imu_start`)
FREE_IMU_OFFSET = True


@remembered
def simulate(base: PlantParams, v: dict[str, float], exp: Experiment, window_s: float = WINDOW_S,
             free_v0: bool = FREE_V0, heard_out: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(angle as the encoder reads it, current as the firmware last heard it, IMU pitch, used-sample mask)
    simulated at exp.t, each window of window_s from the measured state.

    A sample whose reply answers a request that reached the motor before its window (or that the simulation
    has not reached yet) has no simulated current: it carries the measured one, and `heard_out` (a boolean
    array of len(exp.t), when given) is False there, so that `residuals` leaves it out of the current's errors.

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
    lo, hi = params.stop_min_rad, params.stop_max_rad
    ev = Events(exp, v.get("command_delay_s", COMMAND_DELAY_S), params)
    angle_of = exp.req_of if exp.angle_req_of is None else exp.angle_req_of  # the reply whose position the encoder is

    def run_window(k: int, end: int, t0: float, v_start: float, project: bool = False) -> None:
        """Simulate window [k, end) from the measured angle at t0, at v_start (0: stuck), into the arrays; with
        `project`, its start velocity's error projected out along the free motion's analytic response."""
        start = exp.angle[k] + offset + (0.0 if exp.start_shift is None else float(exp.start_shift[k]))
        c = ev.acting(t0)
        if exp.angle_from_reply and c >= 0:  # a reply's angle has the rotor's place in the backlash in it: the
            # output is half the gap (through the belt) behind it on the side the command acting pushes
            start -= 0.5 * backlash / params.belt_ratio * float(np.sign(exp.i_cmd[c]))
        start_angle = min(hi, max(lo, start))
        th, angle[k:end], current[k:end], heard[k:end] = recall(
            window_key(ev, k, end, t0, v_start, start_angle, c, backlash), ev.keep,
            lambda: run_plant(ev, params, backlash, k, end, t0, v_start, start_angle, c))
        angle[k:end] -= offset
        # the IMU's lag, its state following the start's motion (its offset and its transient are the window's own:
        # projected out below), integrated exactly for an input linear between samples (as the sensor's model)
        filt = start_angle - lag * v_start
        t_prev, u_prev = t0, start_angle
        out_imu = []
        for tj, thj in zip(ev.ts[k:end], th.tolist(), strict=True):
            if tj > t_prev:
                h = tj - t_prev
                slope = (thj - u_prev) / h
                filt = thj - slope * lag + (filt - u_prev + slope * lag) * math.exp(-h / lag)
            t_prev, u_prev = tj, thj
            out_imu.append(filt + bias)
        imu[k:end] = out_imu
        mask[k:end] = exp.t[k:end] - exp.t[k] >= SKIP_S
        if project:
            _project_initial_velocity(exp, k, end, t0, angle, imu, mask, params, lag)

    heard = np.zeros(n, dtype=bool) if heard_out is None else heard_out
    for k, end in windows(exp, window_s):
        t0 = float(exp.t[k])
        if exp.angle_from_reply and angle_of[k] >= 0:  # the start angle is a reply's: the plant's when its request
            t0 = min(t0, float(ev.t_req[angle_of[k]]))  # reached the motor, some 2 ms before the sample
        v0 = float(vel[k])
        if abs(v0) >= REST_RAD_S:
            run_window(k, end, t0, v0, project=free_v0)
        else:
            v_start = _slow_start(exp, k, v0)
            if free_v0 and v_start != 0.0:  # sliding: its start velocity's error projected out along the
                # simulation's own response to it (a foot that sticks soon after its start responds little; the free
                # motion's analytic response gave a hold-only recording's inertia a confident wrong number); the
                # moved run is the simulation's alone (projected itself, it would take most of the response out)
                w = slice(k, end)
                run_window(k, end, t0, v_start + math.copysign(SLOW_STEP_RAD_S, v_start))
                moved_angle, moved_imu = angle[w].copy(), imu[w].copy()
                run_window(k, end, t0, v_start)
                _project_along(exp, k, end, angle, imu, mask, (moved_angle - angle[w]) / SLOW_STEP_RAD_S,
                               (moved_imu - imu[w]) / SLOW_STEP_RAD_S)
            else:
                run_window(k, end, t0, v_start)
        frames = recall(("frames", id(exp.t), id(exp.imu), k, end), (exp.t, exp.imu),
                        lambda k=k, end=end: _frame_times(exp, k, end))  # the data's alone
        imu[k:end] = np.interp(frames, exp.t[k:end], imu[k:end])
        if FREE_IMU_OFFSET:
            _project_imu_start(exp, k, end, imu, mask, np.exp(-(frames - t0) / lag))
    return angle, current, imu, mask


def windows(exp: Experiment, window_s: float = WINDOW_S) -> list[tuple[int, int]]:
    """The simulation windows: (first sample, end) of each, window_s from its first sample's time."""
    out, k = [], 0
    while k < len(exp.t):
        end = max(int(np.searchsorted(exp.t, exp.t[k] + window_s)), k + 1)
        out.append((k, end))
        k = end
    return out


def stuck_starts(exp: Experiment, window_s: float = WINDOW_S) -> np.ndarray:
    """The first samples of the windows that start stuck (the encoder at rest and not moving within SLIDE_LOOK_S:
    `_slow_start`)."""
    return np.array([k for k, _ in windows(exp, window_s)
                     if abs(float(exp.vel[k])) < REST_RAD_S and _slow_start(exp, k, float(exp.vel[k])) == 0.0],
                    dtype=int)


def encoder_step(exp: Experiment) -> float:
    """The encoder readings' resolution (rad): their smallest step (0 when they never move)."""
    steps = np.abs(np.diff(exp.angle))
    steps = steps[steps > 1e-12]
    return float(steps.min()) if len(steps) else 0.0


SLOW_STEP_RAD_S = 0.03  # a slow start's response to its velocity: the window simulated this much faster
SLIDE_LOOK_S = 0.03  # a start below REST_RAD_S slides the way the encoder moves within this, if it does
SLIDE_CREEP_RAD_S = 1e-3  # the sliding start's speed when the encoder's velocity is the other way or none


def _slow_start(exp: Experiment, k: int, v0: float) -> float:
    """The start velocity (rad/s; 0: stuck) of a window whose encoder velocity v0 is below REST_RAD_S.

    The encoder cannot tell a foot that rests from one at the turn of a slow slide. When it moves within
    SLIDE_LOOK_S the window starts sliding that way (at v0 when v0 has that sign, else barely: a foot that is in
    fact held by static friction then sticks within a fraction of a millisecond, its start as a stuck one);
    otherwise it starts stuck. Started stuck, a foot that was sliding at the turn (a reversal in the PRBS) stays
    held until the torque passes the static friction, many times the Coulomb friction: one such window had 16
    times the encoder error of the others and carried a third of the encoder's cost (docs/calibration.md).
    The choice is the data's alone, so it does not switch with the parameters (no step in the Jacobian)."""
    look = exp.angle[k:int(np.searchsorted(exp.t, exp.t[k] + SLIDE_LOOK_S, side="right"))] - exp.angle[k]
    moved = np.flatnonzero(look)
    if not len(moved):
        return 0.0
    way = math.copysign(1.0, float(look[moved[0]]))
    return v0 if v0 * way > 0.0 else way * SLIDE_CREEP_RAD_S


def _project_initial_velocity(exp: Experiment, k: int, end: int, t0: float, angle: np.ndarray, imu: np.ndarray,
                              mask: np.ndarray, params: PlantParams, lag_s: float = 0.0) -> None:
    """Correct window [k, end)'s simulation for the least-squares initial velocity (in place).

    The window starts at the encoder's velocity estimate, which a smoothing derivative attenuates at the
    chirp's and the PRBS's frequencies (a 15-sample quadratic Savitzky-Golay slope keeps 89 % of a 12 Hz
    sine's): a start that is systematically too slow, which the fit made up for with a longer mechanical
    time constant (inertia up, damping down: the bias docs/calibration.md used to report). Each moving window's
    initial velocity is instead a nuisance parameter, eliminated by variable projection: a velocity error dv
    moves the angle by dv * tm * (1 - exp(-t / tm)) (tm = J / b, the free motion's decay), the projection takes
    the dv that best explains the window's encoder residual, as MATLAB's ``compare`` estimates initial
    conditions. The IMU, which sees the same angle through a lag of a few tens of ms, gets the shift lagged.
    """
    tm = params.output_inertia_kg_m2 / max(params.foot_damping_nm_s_per_rad, 1e-9)
    t = exp.t[k:end] - t0
    sens = tm * -np.expm1(-t / tm)
    # the IMU sees the shift through its lag: L[tm (1 - e^(-t/tm))] = tm (1 - tm/(tm - lag) e^(-t/tm)) plus a multiple
    # of e^(-t/lag), which `_project_imu_start` takes out with the lag's start state
    lag = max(1e-6, lag_s)
    lagged = tm * (1.0 - tm / (tm - lag) * np.exp(-t / tm)) if abs(tm - lag) > 1e-9 * tm else sens
    _project_along(exp, k, end, angle, imu, mask, sens, lagged)


def _project_along(exp: Experiment, k: int, end: int, angle: np.ndarray, imu: np.ndarray, mask: np.ndarray,
                   sens: np.ndarray, sens_imu: np.ndarray) -> None:
    """Correct window [k, end)'s simulation (in place) by the start-velocity error dv and the start-angle error that
    best explain its encoder residual, given the angle's and the IMU's responses per unit of start velocity.

    A moving window starts at its encoder reading, which places the foot only to its count (0.09 deg), and where in
    the count it sits is not random along a sweep: the angle's level is projected out with the velocity (as
    ``compare`` estimates both initial conditions). The IMU's offset is its own window's (`_project_imu_start`), so
    the level moves only the angle. Left at the reading, the level's error bent the start velocity and, at the turns
    of the default experiment's sweep, took seed 7's encoder offset 0.20 deg low on average over eight noise seeds,
    outside its interval on four (docs/calibration.md, "A moving window's start angle"). A window that starts stuck
    keeps its reading: its count is a consider term (`fit_consider.stuck_starts_term`)."""
    used = mask[k:end]
    if np.count_nonzero(used) >= 3:
        basis = np.column_stack([sens, np.ones(end - k)])
        coef = np.linalg.lstsq(basis[used], (exp.angle[k:end] - angle[k:end])[used], rcond=None)[0]
        angle[k:end] += basis @ coef
        imu[k:end] += coef[0] * sens_imu
        return
    ss = float(np.dot(sens[used], sens[used]))
    if ss <= 0.0:
        return
    dv = -float(np.dot((angle[k:end] - exp.angle[k:end])[used], sens[used])) / ss
    angle[k:end] += dv * sens
    imu[k:end] += dv * sens_imu


def _project_imu_start(exp: Experiment, k: int, end: int, imu: np.ndarray, mask: np.ndarray,
                       decay: np.ndarray) -> None:
    """Add to window [k, end)'s simulated IMU pitch (in place) the offset and the lag's start transient (`decay`:
    e^(-t/lag) at each sample's frame) that best explain the recorded pitch on the used samples.

    The IMU's bias drifts (Gauss-Markov, tau ~10 s): each window has its own offset. Its lag's state at the window's
    start is the pitch's whole past, which the window's start (an angle and a velocity) does not give: taken as the
    start's ramp, its error decays as e^(-t/lag) over the first tens of ms (SKIP_S keeps 10) and, weighed as data,
    pulled the mechanical parameters (on the ideal bench, `--ideal all`, `--plant-seed 7`'s default experiment: the
    Coulomb friction +5.4 %, 1.6 half-widths off, with it; docs/calibration.md)."""
    used = mask[k:end]
    if np.count_nonzero(used) < 3:
        if used.any():
            imu[k:end] += float(np.mean((exp.imu[k:end] - imu[k:end])[used]))
        return
    basis = np.column_stack([np.ones(end - k), decay])
    coef = np.linalg.lstsq(basis[used], (exp.imu[k:end] - imu[k:end])[used], rcond=None)[0]
    imu[k:end] += basis @ coef


# a telemetry sample's IMU pitch is the last UART-RVC frame the firmware read: the lagged pitch when the frame left
# the sensor, its 19 bytes' wire time at 115200 baud (1.65 ms) and half the IMU task's 2 ms poll (1 ms) before the
# first sample that shows it, then held until the next frame (100 Hz); the frames are where the recorded pitch changes
IMU_FRAME_AGE_S = 2.7e-3


def _frame_times(exp: Experiment, k: int, end: int) -> np.ndarray:
    """Per sample of window [k, end): when the IMU frame it carries left the sensor (its frame's first sample less
    IMU_FRAME_AGE_S; a frame is where the recorded pitch changes, as the firmware read it; not before the window).

    The simulated pitch is interpolated there, the lag integrated exactly for an input linear between samples as
    the sensor's model does (hal/virtual/devices/bno08x.py): taken at the sample at or after that time and lagged as
    a step at each sample, it led the sensor by about a millisecond, which the IMU lag made up for."""
    t = exp.t[k:end]
    y = exp.imu[k:end]
    new = np.r_[True, y[1:] != y[:-1]]
    first = np.maximum.accumulate(np.where(new, np.arange(len(t)), 0))
    return np.maximum(t[first] - IMU_FRAME_AGE_S, t[0])


def window_ids(exp: Experiment, window_s: float = WINDOW_S) -> np.ndarray:
    """The simulation window of each used sample (as `simulate` cuts them), in the order `residuals` lists them."""
    ids = np.zeros(len(exp.t), dtype=int)
    for w, (k, end) in enumerate(windows(exp, window_s)):
        ids[k:end] = w
    mask = exp.t - exp.t[ids_start(ids)] >= SKIP_S
    return ids[mask]


def ids_start(ids: np.ndarray) -> np.ndarray:
    """For each sample, the index of its window's first sample."""
    first = np.r_[0, np.flatnonzero(np.diff(ids)) + 1]
    return first[ids]


def residuals(base: PlantParams, v: dict[str, float], exp: Experiment,
              scales: dict[str, float] | None = None) -> np.ndarray:
    """The scaled simulation errors: encoder angle, measured current and IMU pitch, on the used samples, each
    divided by its scale (`SIGMA` unless given: `noise_scales`)."""
    s = SIGMA if scales is None else scales
    heard = np.zeros(len(exp.t), dtype=bool)
    angle, current, imu, mask = simulate(base, v, exp, heard_out=heard)
    # a sample without a simulated current (it carries the measured one) has no current error: 0, not counted
    current_error = np.where(heard, current - exp.current, 0.0)
    return np.concatenate([(angle - exp.angle)[mask] / s["angle"], current_error[mask] / s["current"],
                           (imu - exp.imu)[mask] / s["imu"]])


def fit_percentages(base: PlantParams, v: dict[str, float], exp: Experiment) -> tuple[dict[str, float], int]:
    """({signal: fit percentage} of the simulation on exp, the used samples without a simulated current).

    The current's percentage leaves those samples out (they carry the measured current: no error)."""
    heard = np.zeros(len(exp.t), dtype=bool)
    a, c, i, mask = simulate(base, v, exp, heard_out=heard)
    used = mask & heard
    return ({"angle": fit_percentage(exp.angle[mask], a[mask]), "current": fit_percentage(exp.current[used], c[used]),
             "imu": fit_percentage(exp.imu[mask], i[mask])}, int(np.count_nonzero(mask & ~heard)))


def noise_scales(r: np.ndarray, scales: dict[str, float]) -> dict[str, float]:
    """Each signal's residual RMS (rad, A, rad) from residuals `r` scaled by `scales`: the noise scales that weigh
    the three signals by their own size (the maximum-likelihood weights for independent Gaussian errors)."""
    out = {}
    for name, part in zip(SIGMA, np.split(r, 3), strict=True):
        part = part[part != 0.0]  # a current error left out (`residuals`) is exactly 0
        out[name] = scales[name] * max(float(np.sqrt(np.mean(part ** 2))) if len(part) else 1.0, 1e-3)
    return out


def fit_percentage(y: np.ndarray, y_hat: np.ndarray) -> float:
    """100 (1 - |y - y_hat| / |y - mean y|), as MATLAB's compare reports it (-inf..100).

    >>> round(fit_percentage(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0])), 1)
    100.0
    """
    if len(y) == 0:  # a part without samples (a short gait recording's held-out part): no figure, no warning
        return float("nan")
    den = float(np.linalg.norm(y - np.mean(y)))
    if den == 0.0:
        return float("nan")
    return 100.0 * (1.0 - float(np.linalg.norm(y - y_hat)) / den)


def load_base(path: Path | None) -> PlantParams:
    """The plant profile the fit starts from and whose other keys it keeps (default: the packaged one)."""
    return load_plant_params(path)

"""Backdrive: driver unpowered, a push at the toe moves the foot to +16 deg and -16 deg; tau_b from the encoder.

Protocol (docs/bench.md): the foot starts at 0 deg held by a toe force that balances gravity there;
from t = 50 ms a push of amplitude A ramps in over T_r (A = 15 N, T_r = 0.1 s nominal, each varied
uniformly by +-10 % per trial from numpy's Generator(seed)). The encoder (VirtualEncoderTimer,
4000 counts/rev at the ankle, 16 bits) is read at 1 kHz until the foot reaches 16 deg. The angular
acceleration is the double difference of the unwrapped counts, (c[k+1] - 2 c[k] + c[k-1]) 2 pi /
(4000 dt^2), low-passed by a zero-phase 2nd-order Butterworth at ALPHA_CUTOFF_HZ (offline, filtfilt).
Backdrive torque tau_b = J_total alpha / eta with J_total = J_m N^2 + J_out N_belt^2 + J_pulley.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.signal import butter, filtfilt

from hal.virtual.plant import Plant, PlantParams, TorqueProfile, backdrive, load_plant_params
from hal.virtual.timer import VirtualEncoderTimer
from host_tools.benchtests.output import BenchResult, Figure

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
#: The report's belt ratio as it states it (3.2): 4.6 (the pitch diameters give 14/3).
REPORT_BELT_RATIO = 4.6
READINGS = {"driver": "unpowered", "imu": "n/a"}
logger = logging.getLogger(__name__)

TARGET_RAD = math.radians(16.0)
SAMPLE_S = 1e-3
CYCLES_PER_S = 1_000_000  # the timer's clock for this test: one cycle = 1 us
PUSH_START_S = 0.05
PUSH_AMPLITUDE_N = 15.0
PUSH_RAMP_S = 0.1
VARIATION = 0.10
ALPHA_CUTOFF_HZ = 20.0
MAX_TRIAL_S = 2.0
#: Report: mean peak backdrive torque, printed in N*mm (dorsiflexion, plantarflexion).
REPORT_NMM = {"dorsiflexion": 2.06, "plantarflexion": 2.14}


def alpha_from_counts(counts: np.ndarray, dt_s: float, counts_per_rev: int, cutoff_hz: float) -> np.ndarray:
    """Angular acceleration [rad/s^2] from unwrapped counts: double difference, zero-phase low-pass."""
    rad = 2.0 * math.pi / counts_per_rev
    raw = np.zeros(len(counts))
    raw[1:-1] = (counts[2:] - 2 * counts[1:-1] + counts[:-2]) * rad / dt_s**2
    b, a = butter(2, cutoff_hz, fs=1.0 / dt_s)
    if len(raw) <= 3 * max(len(a), len(b)):
        return raw
    return filtfilt(b, a, raw)


def trial(p: PlantParams, direction: int, amplitude_n: float, ramp_s: float) -> dict[str, np.ndarray]:
    """One push (+1 dorsiflexion, -1 plantarflexion): time, angle, counts, true and encoder alpha."""
    # balances gravity at 0 deg, m g d sin(psi0): all of m g d with the COM level, nothing hanging (eq 3.55)
    hold_n = p.gravity_moment_nm * math.sin(p.com_angle_at_zero_rad) / p.toe_lever_m
    force = TorqueProfile.from_points([(0.0, hold_n), (PUSH_START_S, hold_n),
                                       (PUSH_START_S + ramp_s, hold_n + direction * amplitude_n)])
    plant = Plant(p, backdrive(force), initial_angle_rad=0.0)
    clock = {"c": 0}
    enc = VirtualEncoderTimer(lambda: clock["c"], lambda c: plant.output_angle_rad(c / CYCLES_PER_S))
    modulus = enc.arr + 1
    t, ang, cnt, acc = [], [], [], []
    unwrapped, prev = 0, 0
    n_max = int(MAX_TRIAL_S / SAMPLE_S)
    for k in range(n_max + 1):
        clock["c"] = k * (CYCLES_PER_S // 1000)
        raw = enc.cnt()
        unwrapped += (raw - prev + modulus // 2) % modulus - modulus // 2
        prev = raw
        s = plant.state_at(clock["c"] / CYCLES_PER_S)
        t.append(s.t_s)
        ang.append(s.output_angle_rad)
        cnt.append(unwrapped)
        acc.append(s.output_accel_rad_s2)
        if direction * s.output_angle_rad >= TARGET_RAD:
            break
    counts = np.asarray(cnt, dtype=np.int64)
    alpha_enc = alpha_from_counts(counts.astype(float), SAMPLE_S, enc.counts_per_rev, ALPHA_CUTOFF_HZ)
    return {"t_s": np.asarray(t), "angle_rad": np.asarray(ang), "counts": counts,
            "alpha_true": np.asarray(acc), "alpha_enc": alpha_enc}


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None,
        trials: int | None = None) -> BenchResult:
    """Ten pushes each way (three with quick), seeded +-10 % variation; mean peak tau_b per direction."""
    p = params if params is not None else load_plant_params()
    n_trials = trials if trials is not None else (3 if quick else 10)
    if n_trials < 1:
        raise ValueError(f"trials = {n_trials!r} outside the allowed range [1, 1000]")
    rng = np.random.default_rng(seed)
    j_total = p.reflected_inertia_kg_m2  # J_m N^2 + sum J_i N_i^2
    eta = p.efficiency
    cols: dict[str, list[float]] = {k: [] for k in ("trial", "direction", "t_s", "angle_deg", "counts",
                                                    "alpha_true_rad_s2", "alpha_enc_rad_s2", "tau_b_nm")}
    peaks: dict[str, list[float]] = {"dorsiflexion": [], "plantarflexion": []}
    peaks_true: dict[str, list[float]] = {"dorsiflexion": [], "plantarflexion": []}
    traces = []
    for name, direction in (("dorsiflexion", 1), ("plantarflexion", -1)):
        for k in range(n_trials):
            amp = PUSH_AMPLITUDE_N * rng.uniform(1 - VARIATION, 1 + VARIATION)
            ramp = PUSH_RAMP_S * rng.uniform(1 - VARIATION, 1 + VARIATION)
            tr = trial(p, direction, amp, ramp)
            tau = j_total * tr["alpha_enc"] / eta
            peaks[name].append(float(np.max(np.abs(tau))))
            peaks_true[name].append(float(np.max(np.abs(j_total * tr["alpha_true"] / eta))))
            traces.append((name, tr["t_s"], tau))
            m = len(tr["t_s"])
            cols["trial"] += [k] * m
            cols["direction"] += [direction] * m
            cols["t_s"] += list(tr["t_s"])
            cols["angle_deg"] += list(np.degrees(tr["angle_rad"]))
            cols["counts"] += list(tr["counts"])
            cols["alpha_true_rad_s2"] += list(tr["alpha_true"])
            cols["alpha_enc_rad_s2"] += list(tr["alpha_enc"])
            cols["tau_b_nm"] += list(tau)
    # At breakaway the static friction (maker's back-drive torque x belt ratio) gives way to the kinetic
    # one: the net torque on the output jumps by their difference, whatever the push. The peak tau_b the
    # report's definition gives can therefore not be below J_total (T_static - T_kinetic) / (J_out eta).
    floor_nm = j_total * (p.static_friction_nm - p.coulomb_friction_nm) / (p.output_inertia_kg_m2 * eta)
    push = (f"assumed: a push of {PUSH_AMPLITUDE_N:g} N at the toe ({p.toe_lever_m:g} m) ramped in over "
            f"{PUSH_RAMP_S:g} s, +-{VARIATION:.0%} per trial (the report gives no force)")
    figures = []
    for name in peaks:
        mean_nm = float(np.mean(peaks[name]))
        true_nm = float(np.mean(peaks_true[name]))
        logger.info("backdrive %s: mean peak tau_b %.3f N m (plant alpha: %.3f N m)", name, mean_nm, true_nm)
        figures += [
            Figure(f"mean peak tau_b, {name}, report read as N*m", "N*m",
                   f"\"{REPORT_NMM[name]} Nmm\" (4.2.1) read as {REPORT_NMM[name]} N*m", REPORT_NMM[name], mean_nm,
                   f"plant's own alpha gives {true_nm:.3g} N*m; the reading the physics supports", basis=push),
            Figure(f"mean peak tau_b, {name}, report read as N*mm", "N*m",
                   f"\"{REPORT_NMM[name]} Nmm\" (4.2.1) = {REPORT_NMM[name] / 1000:g} N*m", REPORT_NMM[name] / 1000,
                   mean_nm, f"would need alpha = {REPORT_NMM[name] / 1000 * eta / j_total:.2g} rad/s^2, below the "
                   f"breakaway floor {floor_nm:.2g} N*m by {floor_nm / (REPORT_NMM[name] / 1000):.0f}x", basis=push),
        ]
    figures.append(Figure("least peak tau_b at breakaway (any push)", "N*m", "2.06 / 2.14 \"Nmm\" (4.2.1)", None,
                          floor_nm, "J_total (T_static - T_kinetic) / (J_out eta): the N*mm reading is below it",
                          basis="predicted"))
    # The report's own J_total: "the reflected inertia for the motor, the input pulley" (3.8.1) through the
    # belt's 4.6 (eqs 2.8-2.10): no 6:1 planetary, so the belt's efficiency only.
    j_report = (p.rotor_inertia_kg_m2 + p.actuator_output_inertia_kg_m2) * REPORT_BELT_RATIO**2
    eta_report = p.belt_efficiency
    report_j = (f"assumed: the report's J_total = (J_m + J_input pulley) x 4.6^2 = {j_report:.3g} kg*m^2 (3.8.1, "
                f"eqs 2.8-2.10: no planetary), eta = belt {eta_report:g}; the push as above")
    for name in peaks:
        alpha = [x * eta / j_total for x in peaks[name]]  # each trial's peak alpha from the encoder
        tau_r = float(np.mean([a_k * j_report / eta_report for a_k in alpha]))
        need = REPORT_NMM[name] / 1000 * eta_report / j_report
        figures.append(Figure(
            f"mean peak tau_b, {name}, report's J_total (no planetary)", "N*m",
            f"\"{REPORT_NMM[name]} Nmm\" (4.2.1) = {REPORT_NMM[name] / 1000:g} N*m", REPORT_NMM[name] / 1000, tau_r,
            f"in N*mm the report's figure needs alpha = {need:.2g} rad/s^2: 16 deg in "
            f"{math.sqrt(2 * math.radians(16.0) / need):.2f} s, an ordinary push; neither unit is excluded",
            basis=report_j))

    def plot(fig: object) -> None:
        ax1, ax2 = fig.subplots(2, 1)  # type: ignore[attr-defined]
        colors = {"dorsiflexion": "tab:blue", "plantarflexion": "tab:orange"}
        for k, (name, t, tau) in enumerate(traces):
            ax1.plot(t, tau, color=colors[name], lw=0.8, label=name if k % n_trials == 0 else None)
        ax1.set_xlabel("time [s]")
        ax1.set_ylabel("τ_b = J_total α_enc / η [N·m]")
        ax1.set_title(f"Backdrive, driver unpowered: {n_trials} pushes each way (seed {seed})")
        ax1.legend(fontsize=8)
        x = np.arange(n_trials)
        for off, name in ((-0.2, "dorsiflexion"), (0.2, "plantarflexion")):
            ax2.bar(x + off, peaks[name], width=0.4, color=colors[name], label=f"{name} peak")
            ax2.axhline(REPORT_NMM[name], color=colors[name], ls="--", lw=0.8,
                        label=f"report {REPORT_NMM[name]} (read as N·m)")
        ax2.set_xlabel("trial")
        ax2.set_ylabel("peak τ_b [N·m]")
        ax2.legend(fontsize=7)

    columns = {k: np.asarray(v) for k, v in cols.items()}
    return BenchResult("backdrive", figures, columns, plot,
                       {"seed": seed, "trials": n_trials, "j_total_kg_m2": j_total, "efficiency": eta,
                        "report_j_total_kg_m2": j_report, "report_efficiency": eta_report,
                        "push_amplitude_n": PUSH_AMPLITUDE_N, "push_ramp_s": PUSH_RAMP_S,
                        "variation": VARIATION, "alpha_cutoff_hz": ALPHA_CUTOFF_HZ, "target_deg": 16.0,
                        "peaks_nm": peaks, "peaks_true_alpha_nm": peaks_true})

"""Loading: spring bench (215 N/m at 0.15 m) with 0.68/1.08/1.48 kg, the cascade PID tracking theta0 sin(wt).

Protocol (docs/bench.md): the plant on the spring_bench fixture (T_l = -k_l (theta + theta0), the load
hung at 0.15 m) is driven at 1 kHz by firmware.control.pid.CascadeController with the gains of
profiles/firmware.toml, fed the plant's true angle and velocity (no encoder/IMU, no RTOS, no UART),
its current command applied at once with plant.set_current_command. Reference theta0 sin(wt),
theta0 = pi/6 (the spring offset for which 2 k_l theta0 = 5.068 N*m, the report's target). The report
gives no w, but its speed range: "the ankle speed [...] ranges from -0.05 rad/s to 0.05 rad/s" (4.2.3),
so theta0 w = 0.05 rad/s, w = 0.0955 rad/s (period 66 s); its "initial target power of 0.2534 W" is
5.068 N*m x 0.05 rad/s, the product of the two peaks (which do not coincide).
Electrical power (estimate): P = i^2 R + Ke w_m i (copper loss plus back-EMF power; R phase-to-phase,
Ke line-to-line as in the profile); supply current = P / V_supply: a meter on the 24 V supply reads
this, a phase-current probe (or the driver's reported current) the q-axis current; both are shown. The
figures skip the first SETTLE_S = 0.5 s (the foot is released onto spring and load at t = 0).
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace

import numpy as np

from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.pid import CascadeController
from hal.virtual.plant import Plant, PlantParams, load_plant_params, spring_bench
from host_tools.benchtests.output import BenchResult, Figure
from host_tools.benchtests.spring_calibration import two_mass_stiffness

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
READINGS = {"driver": "current-lag", "imu": "n/a"}
logger = logging.getLogger(__name__)

SAMPLE_S = 1e-3
#: The start (foot released onto the spring and load at t = 0) is excluded from the figures.
SETTLE_S = 0.5
REPORT_TARGET_TORQUE_NM = 5.068
REPORT_TARGET_POWER_W = 1.5
REPORT_SPEED_RAD_S = 0.05
REPORT_INITIAL_POWER_W = 0.2534
REPORT_CURRENT_A = (-0.2, 0.7)
REPORT_PEAK_TORQUE_NM = 10.0
REPORT_ELECTRICAL_PEAK_W = 0.39


def omega_for_power(p: PlantParams, power_w: float = REPORT_TARGET_POWER_W) -> float:
    """The w [rad/s] at which the spring's peak mechanical power k_l theta0^2 w max((1+s)c) is power_w."""
    shape = 1.5 * math.sqrt(3.0) / 2.0  # max of (1 + sin x) cos x, at sin x = 1/2
    return power_w / (p.spring_stiffness_nm_per_rad * p.spring_offset_rad**2 * shape)


def omega_for_speed(p: PlantParams, speed_rad_s: float = REPORT_SPEED_RAD_S) -> float:
    """The w [rad/s] at which theta0 sin(wt) peaks at speed_rad_s (the report's -0.05..0.05 rad/s)."""
    return speed_rad_s / p.spring_offset_rad


def run_load(p: PlantParams, load_kg: float, omega_rad_s: float, periods: float,
             fw: FirmwareConfig | None = None) -> dict[str, np.ndarray]:
    """Track theta0 sin(wt) on the spring bench with one load and the firmware's cascade; signals at 1 kHz."""
    fw = fw or load_firmware_config()
    plant = Plant(p, spring_bench(load_kg), initial_angle_rad=0.0)
    ctl = CascadeController(fw.position_gains, fw.velocity_gains, SAMPLE_S, fw.current_limit_a, fw.velocity_limit_rad_s)
    theta0 = p.spring_offset_rad
    n = int(round(periods * 2 * math.pi / omega_rad_s / SAMPLE_S))
    out = {k: np.empty(n) for k in ("t_s", "ref_rad", "angle_rad", "velocity_rad_s", "current_a",
                                    "torque_nm", "spring_torque_nm")}
    for k in range(n):
        t = k * SAMPLE_S
        s = plant.state_at(t)
        ref = theta0 * math.sin(omega_rad_s * t)
        ref_vel = theta0 * omega_rad_s * math.cos(omega_rad_s * t)
        plant.set_current_command(ctl.update(ref, ref_vel, s.output_angle_rad, s.output_velocity_rad_s), t)
        for key, v in (("t_s", t), ("ref_rad", ref), ("angle_rad", s.output_angle_rad),
                       ("velocity_rad_s", s.output_velocity_rad_s), ("current_a", s.current_q_a),
                       ("torque_nm", s.output_torque_nm),
                       ("spring_torque_nm", p.spring_stiffness_nm_per_rad * (s.output_angle_rad + theta0))):
            out[key][k] = v
    w_m = out["velocity_rad_s"] * p.total_ratio
    i = out["current_a"]
    out["electrical_power_w"] = i * i * p.phase_resistance_ohm + p.ke_v_s_per_rad * w_m * i
    out["supply_current_a"] = out["electrical_power_w"] / p.supply_voltage_v
    out["spring_power_w"] = out["spring_torque_nm"] * out["velocity_rad_s"]
    return out


def per_period_peak_mean(t_s: np.ndarray, x: np.ndarray, period_s: float) -> float:
    """Mean over whole periods of each period's maximum of x."""
    idx = np.floor(t_s / period_s + 1e-9).astype(int)
    peaks = [x[idx == j].max() for j in range(int(idx.max()) + 1) if np.sum(idx == j) > 0.9 * period_s / SAMPLE_S]
    return float(np.mean(peaks)) if peaks else float(np.max(x))


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None,
        periods: float | None = None) -> BenchResult:
    """Run the three loads; compare the 1.48 kg run (after SETTLE_S) with the report's figures."""
    del seed
    p = params if params is not None else load_plant_params()
    omega = omega_for_speed(p)
    n_periods = periods if periods is not None else (0.5 if quick else 1.0)
    period_s = 2 * math.pi / omega
    fw = load_firmware_config()
    runs = {m: run_load(p, m, omega, n_periods, fw) for m in p.load_masses_kg}
    full = runs[max(runs)]
    keep = full["t_s"] >= SETTLE_S
    heavy = {k: v[keep] for k, v in full.items()}
    track_rms_deg = float(np.degrees(np.sqrt(np.mean((heavy["angle_rad"] - heavy["ref_rad"]) ** 2))))
    fitted_theta0 = "fitted: spring_bench.spring_offset_rad (theta0 = pi/6 makes 2 k_l theta0 = 5.068 N*m)"
    fitted_w = f"fitted: w = {omega:.4f} rad/s (theta0 w = 0.05 rad/s, the report's speed range)"
    i_q, i_s = heavy["current_a"], heavy["supply_current_a"]
    k_tables = two_mass_stiffness()
    p_tables = replace(p, spring_rate_n_per_m=k_tables)
    tables = run_load(p_tables, max(runs), omega, n_periods, fw)
    i_tab = tables["current_a"][tables["t_s"] >= SETTLE_S]
    bare = run_load(p_tables, 0.0, omega, n_periods, fw)  # the spring alone, no load hung
    i_bare = bare["current_a"][bare["t_s"] >= SETTLE_S]
    figures = [
        Figure("peak spring torque, 1.48 kg", "N*m", "5.068 (target, 3.8.3)", REPORT_TARGET_TORQUE_NM,
               float(heavy["spring_torque_nm"].max()), f"tracking error rms {track_rms_deg:.2f} deg",
               basis=fitted_theta0),
        Figure("peak ankle speed, 1.48 kg", "rad/s", "-0.05..0.05 (4.2.3)", REPORT_SPEED_RAD_S,
               float(np.abs(heavy["velocity_rad_s"]).max()),
               f"99th percentile {np.percentile(np.abs(heavy['velocity_rad_s']), 99):.3f} rad/s; the peaks are "
               "stick-slip spikes at the reversals (static friction 0.93 N*m); the report: \"an error of -0.15 "
               "rad/s\" (4.2.3)", basis=fitted_w),
        Figure("peak spring mechanical power, 1.48 kg", "W", "0.2534 (\"initial target\", 4.2.3)",
               REPORT_INITIAL_POWER_W, float(np.abs(heavy["spring_power_w"]).max()),
               f"99th percentile {np.percentile(np.abs(heavy['spring_power_w']), 99):.3f} W; 0.2534 = 5.068 x 0.05, "
               "the product of two peaks that do not coincide; the report's 1.5 W (3.8.3) needs ~9x its speed range",
               basis="predicted"),
        Figure("q-axis (phase) current range, 1.48 kg", "A", "-0.2..0.7 (measured, 4.2.3)", REPORT_CURRENT_A[1],
               float(i_q.max()), f"{i_q.min():.2f}..{i_q.max():.2f} A: what the driver reports; compared: the max",
               basis="predicted"),
        Figure("q-axis current range with the tables' spring, 1.48 kg", "A", "-0.2..0.7 (measured, 4.2.3)",
               REPORT_CURRENT_A[1], float(i_tab.max()),
               f"{i_tab.min():.2f}..{i_tab.max():.2f} A with {k_tables:.1f} N/m (Tables B4/B5, two-mass) instead "
               f"of {p.spring_rate_n_per_m:g} N/m; changes sign: {'yes' if i_tab.min() < 0 < i_tab.max() else 'no'}; "
               f"without a load {i_bare.min():.2f}..{i_bare.max():.2f} A",
               basis="assumed: the spring rate Tables B4/B5 give (pafp bench spring-calibration)"),
        Figure("q-axis current minimum with the tables' spring, 1.48 kg", "A", "-0.2..0.7 (measured, 4.2.3)",
               REPORT_CURRENT_A[0], float(i_tab.min()), "below 0: the current changes sign as the report's",
               basis="assumed: the spring rate Tables B4/B5 give (pafp bench spring-calibration)"),
        Figure("supply current range (P/V), 1.48 kg", "A", "-0.2..0.7 (measured, 4.2.3)", REPORT_CURRENT_A[1],
               float(i_s.max()), f"{i_s.min():.3f}..{i_s.max():.3f} A: what a meter on the 24 V supply reads",
               basis="predicted"),
        Figure("peak motor torque at the ankle, 1.48 kg", "N*m", "10 (4.2.3)", REPORT_PEAK_TORQUE_NM,
               float(np.abs(heavy["torque_nm"]).max()), "Kt i N eta", basis="predicted"),
        Figure("mean per-period peak electrical power, 1.48 kg", "W", "0.39 (4.2.3)", REPORT_ELECTRICAL_PEAK_W,
               per_period_peak_mean(heavy["t_s"] - SETTLE_S, heavy["electrical_power_w"], period_s)
               if n_periods >= 1.0 else float(heavy["electrical_power_w"].max()), "i^2 R + Ke w_m i",
               basis="predicted"),
    ]
    for m, r in runs.items():
        logger.info("loading %.2f kg: peak torque %.2f N m, current %.2f..%.2f A", m,
                    np.abs(r["torque_nm"]).max(), r["current_a"].min(), r["current_a"].max())

    def plot(fig: object) -> None:
        axes = fig.subplots(4, 1, sharex=True)  # type: ignore[attr-defined]
        for m, r in runs.items():
            axes[0].plot(r["t_s"], r["current_a"], lw=0.9, label=f"{m:g} kg")
            axes[1].plot(r["t_s"], r["velocity_rad_s"], lw=0.9)
            axes[2].plot(r["t_s"], r["torque_nm"], lw=0.9)
            axes[3].plot(r["t_s"], r["electrical_power_w"], lw=0.9)
        axes[2].axhline(REPORT_PEAK_TORQUE_NM, color="0.5", ls="--", lw=0.8, label="report peak 10 N·m")
        axes[0].axhspan(*REPORT_CURRENT_A, color="0.85", label="report −0.2…0.7 A")
        for ax, lab in zip(axes, ("current [A]", "ω [rad/s]", "torque [N·m]", "P_elec [W]"), strict=True):
            ax.set_ylabel(lab)
            ax.legend(fontsize=7, loc="upper right") if ax.get_legend_handles_labels()[0] else None
        axes[0].set_title(f"Loading bench, θ = π/6·sin({omega:.3f} t), cascade PID at 1 kHz")
        axes[-1].set_xlabel("time [s]")

    columns: dict[str, np.ndarray] = {"t_s": full["t_s"]}
    for m, r in runs.items():
        for key in ("ref_rad", "angle_rad", "velocity_rad_s", "current_a", "torque_nm", "electrical_power_w"):
            columns[f"{key}_{m:g}kg"] = r[key]
    return BenchResult("loading", figures, columns, plot,
                       {"omega_rad_s": omega, "periods": n_periods, "theta0_rad": p.spring_offset_rad,
                        "tracking_rms_deg_1.48kg": track_rms_deg, "settle_s": SETTLE_S,
                        "tables_spring_n_per_m": k_tables,
                        "current_a_tables_spring_1.48kg": [float(i_tab.min()), float(i_tab.max())],
                        "current_a_tables_spring_no_load": [float(i_bare.min()), float(i_bare.max())],
                        "supply_current_a_1.48kg": [float(heavy["supply_current_a"].min()),
                                                    float(heavy["supply_current_a"].max())],
                        "peak_torque_nm": {f"{m:g}": float(np.abs(r["torque_nm"][r["t_s"] >= SETTLE_S]).max())
                                           for m, r in runs.items()}})

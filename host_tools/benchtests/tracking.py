"""Gait tracking on the full firmware run: untuned gains, tuned gains, tuned gains + Butterworth on the IMU.

Protocol (docs/bench.md): the firmware runs on the virtual suspended-foot bench (`pafp run`: RTOS,
encoder, IMU and motor over UART at 921600 baud) and follows the normative ankle angle. Per case the
figures are the RMS and max error of the plant's true angle against the reference over whole strides,
and the lag that best aligns them (host_tools.metrics). Cases:

- untuned: a first hand-set guess (the report's initial gains are not given): P-only position loop
  kp = 1 /rad (1 rad of error asks for the full velocity limit) and P-only velocity loop kp = 0.2 s/rad
  (1 rad/s of error asks for 0.2 x the current limit); everything else as the profile.
- tuned: the gains of the firmware profile (profiles/firmware.toml, read at run time, or a given path).
- tuned + Butterworth: the same with the order-2 low-pass on the IMU pitch at BUTTERWORTH_HZ, and once
  more at BUTTERWORTH_LOW_HZ to show where the filter's lag trips the sensor-disagreement check.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.pid import PidGains
from host_tools.benchtests.output import BenchResult, Figure
from host_tools.report import summarise
from host_tools.runner import RunConfig, RunResult, run_virtual

logger = logging.getLogger(__name__)

__all__ = ["UNTUNED_POSITION", "UNTUNED_VELOCITY", "CaseResult", "run", "run_case", "tracking_cases"]

UNTUNED_POSITION = PidGains(kp=1.0)
UNTUNED_VELOCITY = PidGains(kp=0.2)
BUTTERWORTH_HZ = 20.0
BUTTERWORTH_LOW_HZ = 10.0
BUTTERWORTH_ORDER = 2
REPORT_TEXT = "plot only (Figs 4.8–4.11)"


@dataclass(frozen=True)
class CaseResult:
    """One run's summary plus the sampled signals the plot and the CSV need."""

    name: str
    summary: dict
    t_s: np.ndarray
    reference_deg: np.ndarray
    angle_deg: np.ndarray
    estimate_error_deg: np.ndarray
    gait_start_s: float | None

    @property
    def estimate_rms_deg(self) -> float:
        """RMS of fused-estimate minus true angle after the gait start (what the IMU filter acts on)."""
        if self.gait_start_s is None:
            return math.nan
        sel = self.t_s >= self.gait_start_s
        return float(np.sqrt(np.mean(self.estimate_error_deg[sel] ** 2))) if sel.any() else math.nan


def run_case(name: str, firmware: FirmwareConfig, *, strides: int, seed: int, baud: int = 921600) -> CaseResult:
    """Run the firmware once on the virtual bench (no trace) and keep its summary and signals."""
    result: RunResult = run_virtual(RunConfig(strides=strides, baud=baud, seed=seed, firmware=firmware,
                                              trace_capacity=0))
    s = summarise(result)
    p = result.probe.arrays()
    logger.info("%s: RMS %.3f deg, max %.3f deg, lag %.1f ms, misses %d, faults %s", name, s["rms_error_deg"],
                s["max_error_deg"], s["lag_ms"], s["deadline_misses"], s["faults"])
    return CaseResult(name, s, p["t_s"], np.degrees(p["reference_rad"]), np.degrees(p["true_angle_rad"]),
                      np.degrees(p["fused_angle_rad"] - p["true_angle_rad"]), result.gait_start_s)


def tracking_cases(tuned: FirmwareConfig) -> dict[str, FirmwareConfig]:
    """The four firmware configurations compared, keyed by case name."""
    return {
        "untuned": tuned.with_changes(position_gains=UNTUNED_POSITION, velocity_gains=UNTUNED_VELOCITY),
        "tuned": tuned,
        f"tuned + Butterworth {BUTTERWORTH_HZ:g} Hz": tuned.with_changes(
            imu_lowpass_hz=BUTTERWORTH_HZ, imu_lowpass_order=BUTTERWORTH_ORDER),
        f"tuned + Butterworth {BUTTERWORTH_LOW_HZ:g} Hz": tuned.with_changes(
            imu_lowpass_hz=BUTTERWORTH_LOW_HZ, imu_lowpass_order=BUTTERWORTH_ORDER),
    }


def _note(c: CaseResult) -> str:
    s = c.summary
    faults = ", ".join(s["faults"]) or "no fault"
    return f"{faults}; {s['deadline_misses']} deadline misses; estimate RMS {c.estimate_rms_deg:.3f}°"


def run(seed: int = 0, quick: bool = False, profile: Path | None = None, strides: int | None = None) -> BenchResult:
    """Run the tracking cases and compare RMS error, max error and lag (the report gives plots only)."""
    n = strides if strides is not None else (2 if quick else 5)
    tuned = load_firmware_config(profile)
    cases = [run_case(name, fw, strides=n, seed=seed) for name, fw in tracking_cases(tuned).items()]
    figures: list[Figure] = []
    for c in cases:
        s = c.summary
        figures += [
            Figure(f"{c.name}: RMS error", "deg", REPORT_TEXT, None, s["rms_error_deg"], _note(c)),
            Figure(f"{c.name}: max error", "deg", REPORT_TEXT, None, s["max_error_deg"], ""),
            Figure(f"{c.name}: lag", "ms", REPORT_TEXT, None, s["lag_ms"], ""),
        ]
    base = cases[0]
    columns: dict[str, np.ndarray] = {"t_s": base.t_s, "reference_deg": base.reference_deg}
    for c in cases:
        key = c.name.replace(" + ", "_").replace(" ", "_").lower()
        columns[f"angle_deg_{key}"] = c.angle_deg
        columns[f"estimate_error_deg_{key}"] = c.estimate_error_deg

    def plot(fig: object) -> None:
        ax_a, ax_e = fig.subplots(2, 1, sharex=True)  # type: ignore[attr-defined]
        ax_a.plot(base.t_s, base.reference_deg, color="k", lw=1.5, label="reference")
        for c in cases:
            ax_a.plot(c.t_s, c.angle_deg, lw=0.9, label=f"{c.name} (RMS {c.summary['rms_error_deg']:.2f}°)")
            ax_e.plot(c.t_s, c.angle_deg - np.interp(c.t_s, base.t_s, base.reference_deg), lw=0.8, label=c.name)
        ax_a.set_ylabel("ankle angle [deg]")
        ax_a.set_title(f"Gait tracking, {n} strides at 921600 baud (seed {seed})")
        ax_a.legend(fontsize=7)
        ok = [c.angle_deg - np.interp(c.t_s, base.t_s, base.reference_deg) for c in cases if not c.summary["faults"]]
        if ok:  # scale the error axis to the runs that kept walking (a tripped run falls onto the stop)
            lim = 1.5 * max(float(np.max(np.abs(e))) for e in ok)
            ax_e.set_ylim(-lim, lim)
        ax_e.set_ylabel("error [deg] (axis scaled to fault-free runs)")
        ax_e.set_xlabel("time [s]")
        ax_e.axhline(0.0, color="0.5", lw=0.6)

    params = {"strides": n, "seed": seed, "profile": str(profile) if profile else "profiles/firmware.toml",
              "untuned_position": asdict(UNTUNED_POSITION), "untuned_velocity": asdict(UNTUNED_VELOCITY),
              "tuned_position": asdict(tuned.position_gains), "tuned_velocity": asdict(tuned.velocity_gains),
              "butterworth_order": BUTTERWORTH_ORDER,
              "cases": {c.name: {"rms_error_deg": c.summary["rms_error_deg"],
                                 "max_error_deg": c.summary["max_error_deg"], "lag_ms": c.summary["lag_ms"],
                                 "deadline_misses": c.summary["deadline_misses"], "faults": c.summary["faults"],
                                 "estimate_rms_deg": c.estimate_rms_deg} for c in cases}}
    return BenchResult("tracking", figures, columns, plot, params)

"""Gait tracking on the full firmware run: untuned gains, tuned gains, tuned gains + Butterworth on the IMU.

Protocol (docs/bench.md): the firmware runs on the virtual suspended-foot bench (`pafp run`: RTOS,
encoder, IMU and motor over UART at 921600 baud, the real bench's imperfections) and follows the
normative ankle angle. Per case the figures are measured as the report measured them -- the IMU pitch
the firmware received against the reference (its Figs 4.8-4.10) -- then the plant's true angle
(emulation only), over whole strides in RUN (host_tools.reports.metrics), with the lag that best aligns them.
Cases:

- untuned: the report's first run had no feed-forward (its controller is a PID cascade, 3.6.3-3.6.4) and
  gains it does not give: feed-forward off, P-only position loop kp = 1 /rad (1 rad of error asks for
  the full velocity limit), P-only velocity loop kp = 0.2 s/rad; everything else as the profile.
- tuned: the firmware profile (profiles/firmware.toml, read at run time, or a given path): its gains
  and its gravity + inertia feed-forward.
- tuned, IMU Butterworth (offline): the report's Fig 4.11 -- a Butterworth low-pass "applied" to the
  raw IMU data to "better capture the true response" -- as a zero-phase order-2 filter at
  BUTTERWORTH_HZ on the logged IMU pitch of the tuned run (no new run: a plotting step, not control).
- tuned + Butterworth in the firmware: the order-2 low-pass inside the loop on the IMU pitch at
  BUTTERWORTH_HZ, and at BUTTERWORTH_LOW_HZ to show where its lag trips the sensor-disagreement check.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt

from firmware.config import FirmwareConfig, load_firmware_config
from firmware.control.pid import PidGains
from hal.virtual.devices.bno08x_config import with_imu_reading
from hal.virtual.imperfections import load_imperfections
from hal.virtual.plant import PlantParams
from hal.virtual.plant.readings import IMUS, imu_reading_signal
from host_tools.benchtests.output import BenchResult, Figure
from host_tools.reports.metrics import run_window, signal_figures
from host_tools.reports.report import summarise
from host_tools.runner import RunConfig, RunResult, run_virtual

logger = logging.getLogger(__name__)

__all__ = ["HELD_OUT_SEEDS", "UNTUNED_POSITION", "UNTUNED_VELOCITY", "CaseResult", "imu_model_error", "run",
           "run_case", "tracking_cases"]

#: The readings of the report this test runs under (hal.virtual.plant.readings); the geometry is the bench's.
READINGS = {"driver": "current-lag", "imu": "first-order-lag"}
#: Seeds the profile's gains were not tuned on (they were tuned on seed 0): the tuned rows' spread.
HELD_OUT_SEEDS = tuple(range(1, 11))
NO_FF = "tuned gains, no feed-forward"
HOLD_CASE = "tuned, IMU sample-hold reading"

UNTUNED_POSITION = PidGains(kp=1.0)
UNTUNED_VELOCITY = PidGains(kp=0.2)
BUTTERWORTH_HZ = 20.0
BUTTERWORTH_LOW_HZ = 10.0
BUTTERWORTH_ORDER = 2
REPORT_TEXT = "plot only (Figs 4.8–4.11)"
OFFLINE = f"tuned, IMU Butterworth {BUTTERWORTH_HZ:g} Hz offline"
BASES = {
    "untuned": "assumed: no feed-forward, P-only gains kp = 1 /rad and 0.2 s/rad (the report gives none)",
    "tuned": "fitted: the firmware profile's gains and feed-forward, tuned on this emulator at seed 0 (the "
             "report's tuned gains are not given)",
    NO_FF: "fitted: the profile's gains (tuned at seed 0) with the feed-forward off (the report had none)",
    OFFLINE: f"assumed: order {BUTTERWORTH_ORDER}, {BUTTERWORTH_HZ:g} Hz, zero-phase, on the logged IMU pitch "
             "(the report gives neither order nor cut-off)",
}


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
    imu_deg: np.ndarray
    run_mask: np.ndarray

    @property
    def estimate_rms_deg(self) -> float:
        """RMS of fused-estimate minus true angle after the gait start (what the IMU filter acts on)."""
        if self.gait_start_s is None:
            return math.nan
        sel = self.t_s >= self.gait_start_s
        return float(np.sqrt(np.mean(self.estimate_error_deg[sel] ** 2))) if sel.any() else math.nan


def run_case(name: str, firmware: FirmwareConfig, *, strides: int, seed: int, baud: int = 921600,
             params: PlantParams | None = None, imu: str = IMUS[0], run_options: dict | None = None) -> CaseResult:
    """Run the firmware once on the virtual bench (no trace) and keep its summary and signals.

    imu: the IMU reading the device model runs (hal.virtual.plant.readings), with the bench's imperfections.
    run_options: more RunConfig options (e.g. the plant_file and plant_seed `pafp tune --plant` runs).
    """
    options: dict = {} if params is None else {"plant_params": params}
    if imu != IMUS[0]:
        base = load_imperfections().bench_options(seed)["imu_config"]
        options["imu_config"] = with_imu_reading(base, imu)
    result: RunResult = run_virtual(RunConfig(strides=strides, baud=baud, seed=seed, firmware=firmware,
                                              trace_capacity=0, bench_options=options, **(run_options or {})))
    s = summarise(result)
    p = result.probe.arrays()
    imu = s["tracking"]["imu"]
    logger.info("%s: IMU RMS %s deg, max %s deg, lag %s ms, misses %d, faults %s", name, imu["rms_deg"],
                imu["max_deg"], imu["lag_ms"], s["deadline_misses"], s["faults"])
    w = run_window(p["t_s"], p["supervisor_state"], gait_start_s=result.gait_start_s,
                   stride_s=firmware.stride_s, strides=strides)
    return CaseResult(name, s, p["t_s"], np.degrees(p["reference_rad"]), np.degrees(p["true_angle_rad"]),
                      np.degrees(p["fused_angle_rad"] - p["true_angle_rad"]), result.gait_start_s,
                      np.degrees(p["imu_pitch_rad"]), w.mask)


def offline_butterworth(c: CaseResult, cutoff_hz: float = BUTTERWORTH_HZ, order: int = BUTTERWORTH_ORDER) -> dict:
    """The report's Fig 4.11: the logged IMU pitch low-passed (zero phase) against the reference."""
    ok = np.isfinite(c.imu_deg)
    fs = 1.0 / float(np.median(np.diff(c.t_s)))
    b, a = butter(order, cutoff_hz, fs=fs)
    filtered = np.full_like(c.imu_deg, np.nan)
    filtered[ok] = filtfilt(b, a, c.imu_deg[ok])
    stride_s = float(c.summary["tracking"]["min_run_s"])
    w = run_window(c.t_s, np.where(c.run_mask, 1, 0), gait_start_s=c.gait_start_s, stride_s=stride_s,
                   strides=c.summary["strides"])
    return signal_figures(c.t_s, np.radians(c.reference_deg), np.radians(filtered), w)


def tracking_cases(tuned: FirmwareConfig) -> dict[str, FirmwareConfig]:
    """The four firmware configurations run, keyed by case name (the offline filter needs no run)."""
    return {
        "untuned": tuned.with_changes(position_gains=UNTUNED_POSITION, velocity_gains=UNTUNED_VELOCITY,
                                      feedforward=False),
        NO_FF: tuned.with_changes(feedforward=False),
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


def imu_model_error(reference_deg: np.ndarray, t_s: np.ndarray, reading: str) -> dict[str, float]:
    """RMS and max of the reference minus the reference seen through the named IMU reading alone [deg].

    What the IMU model costs a perfect tracker: no plant, no noise, no bias.
    """
    ok = np.isfinite(reference_deg)
    seen = imu_reading_signal(t_s[ok], reference_deg[ok], reading)
    err = reference_deg[ok] - seen
    return {"rms_deg": float(np.sqrt(np.mean(err**2))), "max_deg": float(np.max(np.abs(err)))}


def _spread(values: list[float]) -> dict[str, float]:
    """Median, min and max of the finite values (nan when none)."""
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if not v.size:
        return {"median": math.nan, "min": math.nan, "max": math.nan, "n": 0}
    return {"median": float(np.median(v)), "min": float(v.min()), "max": float(v.max()), "n": int(v.size)}


def run(seed: int = 0, quick: bool = False, profile: Path | None = None, strides: int | None = None,
        params: PlantParams | None = None, held_out: tuple[int, ...] = HELD_OUT_SEEDS) -> BenchResult:
    """Run the tracking cases and compare RMS error, max error and lag (the report gives plots only).

    The tuned case and its no-feed-forward twin are also run on held_out seeds (the gains were tuned on
    seed 0): median and spread of their IMU and encoder RMS.
    """
    n = strides if strides is not None else (2 if quick else 5)
    tuned = load_firmware_config(profile)
    configs = tracking_cases(tuned)
    cases = [run_case(name, fw, strides=n, seed=seed, params=params) for name, fw in configs.items()]
    figures: list[Figure] = []
    by_name = {c.name: c for c in cases}
    offline = offline_butterworth(by_name["tuned"])

    def rows(name: str, imu: dict, truth: dict | None, note: str, basis: str) -> list[Figure]:
        out = [
            Figure(f"{name}: IMU RMS error", "deg", REPORT_TEXT, None, imu["rms_deg"], note, basis=basis),
            Figure(f"{name}: IMU max error", "deg", REPORT_TEXT, None, imu["max_deg"], "", basis=basis),
            Figure(f"{name}: IMU lag", "ms", REPORT_TEXT, None, imu["lag_ms"], "", basis=basis),
        ]
        if truth is not None:
            out += [
                Figure(f"{name}: RMS error", "deg", REPORT_TEXT, None, truth["rms_deg"],
                       "plant's true angle: emulation only", basis=basis),
                Figure(f"{name}: max error", "deg", REPORT_TEXT, None, truth["max_deg"], "emulation only", basis=basis),
                Figure(f"{name}: lag", "ms", REPORT_TEXT, None, truth["lag_ms"], "emulation only", basis=basis),
            ]
        return out

    for c in cases:
        tr = c.summary["tracking"]
        basis = BASES.get(c.name, f"assumed: {BUTTERWORTH_ORDER}nd-order Butterworth in the loop on the IMU pitch "
                                  "(the report filtered its data, not its loop)")
        figures += rows(c.name, tr["imu"], tr["truth"], _note(c), basis)
        if c.name == "tuned":
            figures += rows(OFFLINE, offline, None, "the logged IMU pitch of the tuned run, filtered", BASES[OFFLINE])
    held: dict[str, dict[str, dict[str, float]]] = {}
    for name in (NO_FF, "tuned"):
        runs = [run_case(name, configs[name], strides=n, seed=k, params=params) for k in held_out]
        held[name] = {sig: _spread([r.summary["tracking"][sig]["rms_deg"] for r in runs])
                      for sig in ("imu", "encoder", "truth")}
        for sig, label in (("imu", "IMU RMS error"), ("encoder", "encoder RMS error"), ("truth", "RMS error")):
            st = held[name][sig]
            figures.append(Figure(
                f"{name}, seeds not tuned on: {label} (median)", "deg", REPORT_TEXT, None, st["median"],
                f"{st['n']} seeds {held_out[0]}..{held_out[-1]}: {st['min']:.3f}…{st['max']:.3f}°"
                + ("; plant's true angle: emulation only" if sig == "truth" else
                   "; the encoder reads from its power-up zero (the seed's offset)" if sig == "encoder" else ""),
                basis="assumed: the profile's gains, tuned at seed 0, on bench imperfections drawn with other seeds"))
    hold = run_case(HOLD_CASE, configs["tuned"], strides=n, seed=seed, params=params, imu="sample-hold")
    figures += rows(HOLD_CASE, hold.summary["tracking"]["imu"], hold.summary["tracking"]["truth"], _note(hold),
                    "assumed: the IMU model holds the pitch every 0.0195 s (3.5.4 read as a sample interval), "
                    "no lag; the profile's gains and feed-forward")
    ref_run = by_name["tuned"]
    model = {r: imu_model_error(ref_run.reference_deg[ref_run.run_mask], ref_run.t_s[ref_run.run_mask], r)
             for r in IMUS}
    for r in IMUS:
        figures.append(Figure(f"IMU model alone, {r} reading: RMS error", "deg", REPORT_TEXT, None,
                              model[r]["rms_deg"], f"the reference through the IMU model (0.0195 s, 3.5.4), no plant; "
                              f"max {model[r]['max_deg']:.2f}°", basis="predicted"))
    base = cases[0]
    columns: dict[str, np.ndarray] = {"t_s": base.t_s, "reference_deg": base.reference_deg}
    for c in cases:
        key = c.name.replace(" + ", "_").replace(" ", "_").lower()
        columns[f"angle_deg_{key}"] = c.angle_deg
        columns[f"imu_deg_{key}"] = c.imu_deg
        columns[f"estimate_error_deg_{key}"] = c.estimate_error_deg

    def plot(fig: object) -> None:
        ax_a, ax_e = fig.subplots(2, 1, sharex=True)  # type: ignore[attr-defined]
        ax_a.plot(base.t_s, base.reference_deg, color="k", lw=1.5, label="reference")
        for c in cases:
            rms = c.summary["tracking"]["imu"]["rms_deg"]
            label = f"{c.name}, IMU (RMS " + ("n/a)" if rms is None else f"{rms:.2f}°)")
            ax_a.plot(c.t_s, c.imu_deg, lw=0.9, label=label)
            ax_e.plot(c.t_s, c.imu_deg - np.interp(c.t_s, base.t_s, base.reference_deg), lw=0.8, label=f"{c.name}, IMU")
        ax_a.set_ylabel("ankle angle [deg]")
        ax_a.set_title(f"Gait tracking, {n} strides at 921600 baud (seed {seed})")
        ax_a.legend(fontsize=7)
        ok = [np.nan_to_num(c.imu_deg - np.interp(c.t_s, base.t_s, base.reference_deg))[c.run_mask] for c in cases
              if not c.summary["faults"]]
        if ok:  # scale the error axis to the runs that kept walking (a tripped run falls onto the stop)
            lim = 1.5 * max(float(np.max(np.abs(e))) for e in ok)
            ax_e.set_ylim(-lim, lim)
        ax_e.set_ylabel("IMU minus reference [deg] (axis: fault-free runs)")
        ax_e.set_xlabel("time [s]")
        ax_e.axhline(0.0, color="0.5", lw=0.6)

    info = {"strides": n, "seed": seed, "profile": str(profile) if profile else "profiles/firmware.toml",
              "untuned_position": asdict(UNTUNED_POSITION), "untuned_velocity": asdict(UNTUNED_VELOCITY),
              "tuned_position": asdict(tuned.position_gains), "tuned_velocity": asdict(tuned.velocity_gains),
              "butterworth_order": BUTTERWORTH_ORDER,
              "offline_butterworth": {"hz": BUTTERWORTH_HZ, **offline},
              "held_out_seeds": list(held_out), "held_out": held, "imu_model_alone": model,
              "imu_sample_hold": {"imu": hold.summary["tracking"]["imu"], "truth": hold.summary["tracking"]["truth"],
                                  "readings": hold.summary["readings"], "faults": hold.summary["faults"]},
              "cases": {c.name: {"imu": c.summary["tracking"]["imu"], "encoder": c.summary["tracking"]["encoder"],
                                 "truth": c.summary["tracking"]["truth"],
                                 "deadline_misses": c.summary["deadline_misses"], "faults": c.summary["faults"],
                                 "estimate_rms_deg": c.estimate_rms_deg} for c in cases}}
    return BenchResult("tracking", figures, columns, plot, info)

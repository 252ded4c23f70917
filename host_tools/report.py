"""Writes the outputs of a virtual run: telemetry, trace, plot, summary.json and report.md."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from firmware.protocol.telemetry import TelemetryDecoder
from host_tools.build_info import describe
from host_tools.metrics import RUN_STATE, RunWindow, cut_strides, run_window, signal_figures
from host_tools.monitor import CsvSink
from host_tools.plots import plot_tracking
from host_tools.runner import RunResult

__all__ = ["TRACKING_SIGNALS", "summarise", "tracking_lines", "tracking_summary", "tracking_text", "write_outputs"]

#: The tracking figures in the order they are shown: what a bench measures first, the truth last.
#: (name, probe field, description)
TRACKING_SIGNALS: tuple[tuple[str, str, str], ...] = (
    ("imu", "imu_pitch_rad", "IMU pitch as the firmware received it (the report's Figs 4.8-4.10)"),
    ("encoder", "encoder_angle_rad", "angle from the encoder count (zero at power-up)"),
    ("fused", "fused_angle_rad", "the firmware's fused estimate (encoder + IMU), what it controls"),
    ("truth", "true_angle_rad", "the plant's true output angle: emulation only, no bench has it"),
)


def _us(cycles: int | None, f_cpu: int) -> float | None:
    return None if cycles is None else round(cycles * 1e6 / f_cpu, 3)


def _run_window(r: RunResult) -> RunWindow:
    p = r.probe.arrays()
    return run_window(p["t_s"], p["supervisor_state"], gait_start_s=r.gait_start_s,
                      stride_s=r.firmware.config.stride_s, strides=r.config.strides)


def _has_plant(r: RunResult) -> bool:
    """Whether the probe's true angle is a plant's (serial mode without one records the fused estimate)."""
    return getattr(r, "angle_source", "plant") == "plant"


def tracking_summary(r: RunResult) -> dict:
    """The four tracking figures over the RUN window, measured ones first, with the time they cover."""
    p = r.probe.arrays()
    w = _run_window(r)
    out: dict = {"time_in_run_s": round(w.time_in_run_s, 3), "min_run_s": round(w.min_run_s, 3),
                 "enough_run": w.enough}
    if not w.enough:
        out["note"] = (f"only {w.time_in_run_s:.3f} s of gait with the supervisor in RUN, less than one stride "
                       f"({w.min_run_s:g} s): no tracking figure")
    for name, key, _ in TRACKING_SIGNALS:
        angle = p[key] if name != "truth" or _has_plant(r) else None
        out[name] = signal_figures(p["t_s"], p["reference_rad"], angle, w)
    out["truth"]["emulation_only"] = True
    return out


def summarise(r: RunResult) -> dict:
    """The summary of a run as plain JSON-able values."""
    fw, sched = r.firmware, r.scheduler
    f_cpu = fw.f_cpu_hz
    tracking = tracking_summary(r)
    p = r.probe.arrays()
    # the legacy top-level figures: the probe's angle (the plant's true one in virtual mode) over the window
    m = signal_figures(p["t_s"], p["reference_rad"], p["true_angle_rad"], _run_window(r))
    bounds = {b.name: b for b in r.bounds}
    deadlines = {t.name: t.relative_deadline for t in fw.tasks}  # firmware tasks only (no bench probe)
    tasks = {}
    for name, st in sched.stats.items():
        if name not in deadlines:
            continue
        b = bounds.get(name)  # none in serial mode: host times are measured, not analysed
        tasks[name] = {
            "jobs": st.jobs, "wcrt_us": _us(st.worst_response, f_cpu),
            "bound_us": _us(b.bound, f_cpu) if b else None, "deadline_us": _us(deadlines[name], f_cpu),
            "misses": st.deadline_misses, "skipped": st.skipped, "start_jitter_us": _us(st.start_jitter, f_cpu),
            "within_bound": None if b is None else
            st.worst_response is None or (b.bound is not None and st.worst_response <= b.bound),
        }
    util = sched.utilisation()
    sup = fw.supervisor
    faults = [] if sup.reason.value == 0 else [sup.reason.name]
    link = fw.motor.stats
    return {
        "strides": r.config.strides,
        "sim_time_s": round(r.sim_time_s, 6),
        "wall_time_s": round(r.wall_time_s, 3),
        "realtime_factor": round(r.sim_time_s / r.wall_time_s, 2) if r.wall_time_s > 0 else None,
        "build": describe(),
        "tracking": tracking,
        **getattr(r, "bench_record", {}),
        "rms_error_deg": m["rms_deg"],
        "max_error_deg": m["max_deg"],
        "lag_ms": m["lag_ms"],
        "deadline_misses": sum(t["misses"] for t in tasks.values()),
        "faults": faults,
        "cpu_utilisation": round(util.total, 5),
        "baud": r.config.baud,
        "seed": r.config.seed,
        "supervisor_state": sup.state.name,
        "watchdog_resets": fw.watchdog_resets,
        "motor_link": {
            "requests": link.requests, "replies": link.replies, "full_replies": link.full_replies,
            "missing_replies": link.missing_replies, "stale_replies": link.stale_replies,
            "crc_errors": fw.motor.crc_errors, "rx_timeouts": link.rx_timeouts,
            "max_feedback_age_ms": round(link.max_age_s * 1e3, 3),
            "feedback_rate_hz": round(link.replies / r.sim_time_s, 1) if r.sim_time_s else 0.0,
        },
        "telemetry": {"records_sent": fw.logger.sent, "records_dropped": fw.logger.dropped,
                      "bytes": len(r.telemetry)},
        "tasks": tasks,
    }


def _write_telemetry_csv(data: bytes, path: Path) -> dict:
    dec = TelemetryDecoder()
    sink = CsvSink(path)
    try:
        sink.write(dec.feed(data))
    finally:
        sink.close()
    return asdict(dec.stats)


def _num(v: float | None, fmt: str) -> str:
    return "n/a" if v is None else format(v, fmt)


def tracking_lines(tr: dict) -> list[str]:
    """The tracking figures as a Markdown table, measured ones first, truth labelled emulation-only."""
    lines = ["| tracking error (reference minus ...) | RMS | max | lag |", "|---|---|---|---|"]
    for name, _, text in TRACKING_SIGNALS:
        f = tr[name]
        lines.append(f"| {name}: {text} | {_num(f['rms_deg'], '.3f')}° | {_num(f['max_deg'], '.3f')}° | "
                     f"{_num(f['lag_ms'], '.1f')} ms |")
    lines += ["", f"Over {tr['time_in_run_s']:.3f} s of gait with the supervisor in RUN (at least "
              f"{tr['min_run_s']:g} s, one stride, is needed for a figure)."
              + (f" {tr['note']}." if "note" in tr else "")]
    return lines


def tracking_text(tr: dict) -> list[str]:
    """The tracking figures as lines for the terminal, measured ones first."""
    out = []
    for name, _, _ in TRACKING_SIGNALS:
        f = tr[name]
        label = "truth (emulation only)" if name == "truth" else name
        out.append(f"  tracking, {label:<22} RMS {_num(f['rms_deg'], '.3f')} deg, max {_num(f['max_deg'], '.3f')} deg, "
                   f"lag {_num(f['lag_ms'], '.1f')} ms")
    note = f" ({tr['note']})" if "note" in tr else ""
    out.append(f"  time in RUN with the gait running: {tr['time_in_run_s']:.3f} s{note}")
    return out


def _bench_lines(s: dict) -> list[str]:
    """What plant and which imperfections the run had (virtual mode only)."""
    if "plant" not in s:
        return []
    seed = s["plant"]["seed"]
    plant = "nominal plant" if seed is None else f"plant drawn from its tolerances with seed {seed}"
    imp = s["imperfections"]
    on = [k for k, v in imp.items() if isinstance(v, dict) and v["enabled"] and v["modelled"]]
    off = [k for k, v in imp.items() if isinstance(v, dict) and not v["enabled"] and v["modelled"]]
    return [f"Bench: {plant}; imperfections on: {', '.join(on) or 'none'}"
            + (f"; switched off: {', '.join(off)}" if off else "") + ".", ""]


def _report_md(s: dict, md_extra: list[str] | None = None) -> str:
    lines = [
        "# pafp run report", "",
        f"{s['strides']} strides, {s['sim_time_s']:.3f} s simulated in {s['wall_time_s']:.2f} s "
        f"(realtime factor {s['realtime_factor']}; {s['build']}), motor link {s['baud']} baud, seed {s['seed']}.",
        "",
        *tracking_lines(s["tracking"]), "", *_bench_lines(s),
        "| metric | value |", "|---|---|",
        f"| deadline misses | {s['deadline_misses']} |",
        f"| faults | {', '.join(s['faults']) or 'none'} |",
        f"| CPU utilisation | {100 * s['cpu_utilisation']:.2f} % |",
        f"| motor feedback rate | {s['motor_link']['feedback_rate_hz']} Hz |",
        f"| worst feedback age | {s['motor_link']['max_feedback_age_ms']} ms |",
        f"| telemetry records sent / dropped | {s['telemetry']['records_sent']} / "
        f"{s['telemetry']['records_dropped']} |", "",
        "## Tasks (response times in µs)", "",
        "| task | jobs | worst observed | analysed bound | deadline | misses | within bound |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, t in s["tasks"].items():
        within = "n/a" if t["within_bound"] is None else "yes" if t["within_bound"] else "NO"
        lines.append(f"| {name} | {t['jobs']} | {t['wcrt_us']} | {t['bound_us']} | {t['deadline_us']} | "
                     f"{t['misses']} | {within} |")
    lines += md_extra or []
    lines += ["", "Files: `telemetry.bin` (raw telemetry UART), `telemetry.csv`, `trace.json` (Perfetto / "
              "chrome://tracing), `tracking.png`, `summary.json`.", ""]
    return "\n".join(lines)


def write_outputs(r: RunResult, out: Path, extra: dict | None = None, md_extra: list[str] | None = None) -> dict:
    """Write every output file into `out`; return the summary (`extra` merged in; `md_extra` ends report.md)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "telemetry.bin").write_bytes(r.telemetry)
    s = summarise(r)
    s.update(extra or {})
    s["telemetry"]["decoder"] = _write_telemetry_csv(r.telemetry, out / "telemetry.csv")
    if r.scheduler.trace is not None:
        r.scheduler.trace.write_chrome(out / "trace.json", r.firmware.f_cpu_hz)
    p = r.probe.arrays()
    fw = r.firmware
    if r.gait_start_s is not None and len(p["t_s"]):
        cut = {"imu": "imu_pitch_rad", "truth (emulation only)": "true_angle_rad"} if _has_plant(r) else \
            {"imu": "imu_pitch_rad"}
        strides = {label: cut_strides(p["t_s"], p["reference_rad"], np.nan_to_num(p[key]), start_s=r.gait_start_s,
                                      stride_s=fw.config.stride_s, strides=r.config.strides)
                   for label, key in cut.items()}
        ref = fw.reference
        pct = np.linspace(0, 100, 101)
        band = np.array([ref.band_deg(x) for x in pct])
        run = p["supervisor_state"] == RUN_STATE
        errors = {("truth (emulation only)" if name == "truth" else name):
                  np.where(run, np.degrees(p["reference_rad"] - p[key]), np.nan)
                  for name, key, _ in TRACKING_SIGNALS if name != "truth" or _has_plant(r)}
        imu = s["tracking"]["imu"]["rms_deg"]
        plot_tracking(out / "tracking.png", strides, (pct, band[:, 0], band[:, 1]), p["t_s"],
                      p["current_cmd_a"], p["current_meas_a"], errors,
                      f"Gait tracking, {s['strides']} strides, IMU-measured RMS "
                      + ("n/a" if imu is None else f"{imu:.2f}°"))
    (out / "summary.json").write_text(json.dumps(s, indent=2) + "\n", encoding="utf-8")
    (out / "report.md").write_text(_report_md(s, md_extra), encoding="utf-8")
    return s

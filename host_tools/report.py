"""Writes the outputs of a virtual run: telemetry, trace, plot, summary.json and report.md."""

from __future__ import annotations

import json
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from firmware.protocol.telemetry import TelemetryDecoder
from host_tools.build_info import describe
from host_tools.metrics import cut_strides, tracking_metrics
from host_tools.monitor import CsvSink
from host_tools.plots import plot_tracking
from host_tools.runner import RunResult

__all__ = ["summarise", "write_outputs"]


def _us(cycles: int | None, f_cpu: int) -> float | None:
    return None if cycles is None else round(cycles * 1e6 / f_cpu, 3)


def summarise(r: RunResult) -> dict:
    """The summary of a run as plain JSON-able values."""
    fw, sched = r.firmware, r.scheduler
    f_cpu = fw.f_cpu_hz
    p = r.probe.arrays()
    start = r.gait_start_s if r.gait_start_s is not None else math.inf
    m = tracking_metrics(p["t_s"], p["reference_rad"], p["true_angle_rad"], start_s=start,
                         stride_s=fw.config.stride_s, strides=r.config.strides)
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
        "rms_error_deg": round(m.rms_error_deg, 4),
        "max_error_deg": round(m.max_error_deg, 4),
        "lag_ms": round(m.lag_ms, 2),
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
        "controller": {"name": fw.config.controller, "class": type(fw.controller).__qualname__,
                       "published": list(fw.published_names), "error": fw.controller_error or None},
    }


def _write_telemetry_csv(data: bytes, path: Path, extra_names: tuple[str, ...] = ()) -> dict:
    dec = TelemetryDecoder(len(extra_names))
    sink = CsvSink(path, extra_names)
    try:
        sink.write(dec.feed(data))
    finally:
        sink.close()
    return asdict(dec.stats)


def _report_md(s: dict, md_extra: list[str] | None = None) -> str:
    lines = [
        "# pafp run report", "",
        f"{s['strides']} strides, {s['sim_time_s']:.3f} s simulated in {s['wall_time_s']:.2f} s "
        f"(realtime factor {s['realtime_factor']}; {s['build']}), motor link {s['baud']} baud, seed {s['seed']}.",
        "",
        "| metric | value |", "|---|---|",
        f"| RMS tracking error | {s['rms_error_deg']:.3f}° |",
        f"| max tracking error | {s['max_error_deg']:.3f}° |",
        f"| lag | {s['lag_ms']:.1f} ms |",
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


def _strict(value: object) -> object:
    """`value` with every NaN or infinity replaced by None (null): summary.json is strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value


def write_outputs(r: RunResult, out: Path, extra: dict | None = None, md_extra: list[str] | None = None) -> dict:
    """Write every output file into `out`; return the summary (`extra` merged in; `md_extra` ends report.md)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "telemetry.bin").write_bytes(r.telemetry)
    s = summarise(r)
    s.update(extra or {})
    s["telemetry"]["decoder"] = _write_telemetry_csv(r.telemetry, out / "telemetry.csv",
                                                     getattr(r.firmware, "published_names", ()))
    if r.scheduler.trace is not None:
        r.scheduler.trace.write_chrome(out / "trace.json", r.firmware.f_cpu_hz)
    p = r.probe.arrays()
    fw = r.firmware
    if r.gait_start_s is not None and len(p["t_s"]):
        strides = cut_strides(p["t_s"], p["reference_rad"], p["true_angle_rad"], start_s=r.gait_start_s,
                              stride_s=fw.config.stride_s, strides=r.config.strides)
        ref = fw.reference
        pct = np.linspace(0, 100, 101)
        band = np.array([ref.band_deg(x) for x in pct])
        err = np.degrees(p["true_angle_rad"] - p["reference_rad"])
        plot_tracking(out / "tracking.png", strides, (pct, band[:, 0], band[:, 1]), p["t_s"],
                      p["current_cmd_a"], p["current_meas_a"], err,
                      f"Gait tracking, {s['strides']} strides, RMS {s['rms_error_deg']:.2f}°")
    if getattr(r.config, "scenario", "suspended") == "walk":
        from host_tools.actuator import walk_outputs

        s["actuator"], walk_md = walk_outputs(r, out)
        md_extra = [*(md_extra or []), *walk_md]
    (out / "summary.json").write_text(json.dumps(_strict(s), indent=2, allow_nan=False) + "\n", encoding="utf-8")
    (out / "report.md").write_text(_report_md(s, md_extra), encoding="utf-8")
    return s

"""Writes the outputs of a run: telemetry, trace, plot, summary.json and report.md.

Each file is written to a temporary name and renamed (host_tools/outdir.py); summary.json is strict JSON
(a NaN or an infinity, e.g. the tracking error of a run stopped before its gait began, is written as
null). A virtual run that streamed its telemetry (``RunResult.files``) has telemetry.bin/.csv in place
already.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from host_tools.build_info import describe
from host_tools.outdir import naming, write_atomic
from host_tools.reports.gait_latency import event_summary, gait_event_lines
from host_tools.reports.metrics import TrackingMetrics
from host_tools.reports.process_clock import process_elapsed_s
from host_tools.reports.run_files import file_digests
from host_tools.reports.telemetry_csv import TelemetryCsv
from host_tools.reports.tracking_stream import PLOT_STRIDES, TRACKING_SIGNALS, TrackingResult, feed_probe, probe_stream
from host_tools.runner import RunConfig, RunResult
from protocol.telemetry import TelemetryDecoder

if TYPE_CHECKING:
    from host_tools.outdir import RunDir

__all__ = ["TRACKING_SIGNALS", "readings_text", "run_into", "strict_json", "summarise", "tracking_lines",
           "TRACE_FILE", "tracking_of", "tracking_summary", "tracking_text", "write_outputs"]

TRACE_FILE = "trace.pftrace"
"""The run's trace in Perfetto's protobuf format (host_tools/reports/timeline.py)."""



def strict_json(value: object) -> object:
    """value with every non-finite float replaced by None (JSON has no NaN or Infinity).

    >>> strict_json({"a": [1.0, float("nan")], "b": float("inf")})
    {'a': [1.0, None], 'b': None}
    """
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    return value


def tracking_of(r: RunResult) -> TrackingResult:
    """The tracking figures of a run: streamed during it, or computed now from its probe's samples."""
    files = getattr(r, "files", None)
    if files is not None:
        return files.close()
    p = r.probe.arrays()
    t = p["t_s"]
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    stream = probe_stream(stride_s=r.firmware.config.stride_s, strides=r.config.strides, dt_s=dt,
                          expected_samples=len(t))
    stream.set_start(r.gait_start_s)
    feed_probe(stream, p)
    return stream.finish()


def _has_plant(r: RunResult) -> bool:
    """Whether the probe's true angle is a plant's (serial mode without one records the fused estimate)."""
    return getattr(r, "angle_source", "plant") == "plant"


def _figures(m: TrackingMetrics, enough: bool) -> dict[str, float | None]:
    """{"rms_deg", "max_deg", "lag_ms"} rounded; None when the run had too little RUN time or no sample."""
    if not enough or not m.samples:
        return {"rms_deg": None, "max_deg": None, "lag_ms": None}
    return {"rms_deg": round(m.rms_error_deg, 4), "max_deg": round(m.max_error_deg, 4), "lag_ms": round(m.lag_ms, 2)}


def tracking_summary(r: RunResult, tracking: TrackingResult) -> dict:
    """The four tracking figures over the RUN window, measured ones first, with the time they cover."""
    t = tracking
    out: dict = {"time_in_run_s": round(t.time_in_run_s, 3), "min_run_s": round(t.min_run_s, 3),
                 "enough_run": t.enough}
    if not t.enough:
        out["note"] = (f"only {t.time_in_run_s:.3f} s of gait with the supervisor in RUN, less than one stride "
                       f"({t.min_run_s:g} s): no tracking figure")
    for name, _, _ in TRACKING_SIGNALS:
        out[name] = _figures(t.metrics[name], t.enough and (name != "truth" or _has_plant(r)))
    out["truth"]["emulation_only"] = True
    return out


#: The top-level tracking keys of summary.json: bench-measurable figures only (docs/outputs.md).
HEADLINE_KEYS = ("imu_rms_error_deg", "imu_max_error_deg", "imu_lag_ms",
                 "encoder_rms_error_deg", "encoder_max_error_deg", "encoder_lag_ms")


def measured_headline(imu: dict, encoder: dict) -> dict[str, float | None]:
    """The top-level figures of summary.json from the IMU's and the encoder's tracking figures."""
    return {f"{name}_{key}": f[src] for name, f in (("imu", imu), ("encoder", encoder))
            for key, src in (("rms_error_deg", "rms_deg"), ("max_error_deg", "max_deg"), ("lag_ms", "lag_ms"))}


ENCODER_ZERO_NOTE = ("left out of the headline: the encoder angle is the motor's position feedback zeroed at its "
                     "first reply, wherever the foot then rested (on a stop, tens of degrees off), so its tracking "
                     "error carries that pose's offset; tracking.encoder keeps the figure, relative to that zero")
"""Why a serial run with ``--encoder motor`` has no top-level encoder figures (summary.json ``encoder_headline``)."""


def _headline(r: RunResult, imu: dict, encoder: dict) -> dict:
    """The top-level tracking figures; a serial run whose encoder is the motor's feedback (zero at its first reply,
    not at a known pose) keeps its encoder figures under tracking only, and says why."""
    headline: dict = measured_headline(imu, encoder)
    if getattr(r.config, "encoder", None) == "motor":
        headline.update({k: None for k in headline if k.startswith("encoder_")})
        headline["encoder_headline"] = ENCODER_ZERO_NOTE
    return headline


def _us(cycles: int | None, f_cpu: int) -> float | None:
    return None if cycles is None else round(cycles * 1e6 / f_cpu, 3)


def _bus_load(r: RunResult) -> dict[str, float]:
    """The CAN bus's load over the run (frames' bit-times, exact stuffing), when the motor is on CAN."""
    bus = getattr(getattr(r, "bench", None), "can_bus", None)  # serial mode has no bench
    if bus is None or not r.sim_time_s:
        return {}
    return {"bus_load": round(bus.busy_ticks / r.bench.f_cpu_hz / r.sim_time_s, 4)}


def _interrupted(r: RunResult) -> dict:
    """How far a run that was stopped early got: what stopped it, whole strides of gait run, time run."""
    stop = getattr(r, "stop", None)  # serial mode: the stop record names the signal
    by = getattr(r, "stopped_by", None) or (getattr(stop, "signal", None) if stop is not None else None)
    start = r.gait_start_s
    stride_s = r.firmware.config.stride_s
    if stop is not None:  # serial mode counts its whole strides in RUN itself (SerialRunConfig.strides)
        done = r.config.strides
    else:
        done = 0 if start is None else max(0, int((r.sim_time_s - start + 1e-9) // stride_s))
    return {"by": by, "strides_run": done, "sim_time_s": round(r.sim_time_s, 6)}


def summarise(r: RunResult, tracking: TrackingResult | None = None) -> dict:
    """The summary of a run as plain JSON-able values (tracking: from tracking_of(r), computed if not given)."""
    fw, sched = r.firmware, r.scheduler
    f_cpu = fw.f_cpu_hz
    tracking = tracking or tracking_of(r)
    # the top-level figures are what a bench measures (IMU, encoder); the truth is only under tracking.truth
    imu = _figures(tracking.metrics["imu"], tracking.enough)
    enc = _figures(tracking.metrics["encoder"], tracking.enough)
    files = getattr(r, "files", None)
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
    complete = bool(getattr(r, "complete", not getattr(r, "interrupted", False)))
    return {
        "strides": r.config.strides,
        "complete": complete,
        **({} if complete else {"interruption": _interrupted(r)}),
        "sim_time_s": round(r.sim_time_s, 6),
        "wall_time_s": round(r.wall_time_s, 3),
        "realtime_factor": round(r.sim_time_s / r.wall_time_s, 2) if r.wall_time_s > 0 else None,
        "build": describe(),
        "tracking": tracking_summary(r, tracking),
        **getattr(r, "bench_record", {}),
        **_headline(r, imu, enc),
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
            **fw.motor.published(),  # link-specific counters (none on the UART)
            **_bus_load(r),
        },
        "telemetry": {"records_sent": fw.logger.sent, "records_dropped": fw.logger.dropped,
                      "bytes": files.telemetry_bytes if files is not None else len(r.telemetry)},
        "tasks": tasks,
        "controller": {"name": fw.config.controller, "class": type(fw.controller).__qualname__,
                       "published": list(fw.published_names), "error": fw.controller_error or None},
    }


def _write_telemetry_csv(data: bytes, path: Path, f_cpu_hz: int, chunk_bytes: int = 1 << 16,
                         extra_names: tuple[str, ...] = ()) -> dict:
    """Decode data into path (a temporary name, renamed when complete), a chunk at a time."""
    dec = TelemetryDecoder(len(extra_names))
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with naming(path), tmp.open("w", encoding="utf-8", newline="") as f:
            csv = TelemetryCsv(f, f_cpu_hz, extra_names)
            for k in range(0, len(data), chunk_bytes):
                csv.write(dec.feed_values(data[k:k + chunk_bytes]))
        tmp.replace(path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return asdict(dec.stats)


def _figure(value: float | None, digits: int, unit: str) -> str:
    """A figure for report.md, rounded; n/a when the run has none (NaN here, null in summary.json)."""
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}{unit}"


def _num(v: float | None, fmt: str, unit: str = "") -> str:
    return "n/a" if v is None or not math.isfinite(v) else format(v, fmt) + unit


def tracking_lines(tr: dict) -> list[str]:
    """The tracking figures as a Markdown table, measured ones first, truth labelled emulation-only."""
    lines = ["| tracking error (reference minus ...) | RMS | max | lag |", "|---|---|---|---|"]
    for name, _, text in TRACKING_SIGNALS:
        f = tr[name]
        lines.append(f"| {name}: {text} | {_num(f['rms_deg'], '.3f', '°')} | {_num(f['max_deg'], '.3f', '°')} | "
                     f"{_num(f['lag_ms'], '.1f', ' ms')} |")
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
        out.append(f"  tracking, {label:<22} RMS {_num(f['rms_deg'], '.3f', ' deg')}, "
                   f"max {_num(f['max_deg'], '.3f', ' deg')}, lag {_num(f['lag_ms'], '.1f', ' ms')}")
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
            + (f"; switched off: {', '.join(off)}" if off else "") + ".", "", readings_text(s) + ".", ""]


def readings_text(s: dict) -> str:
    """Which readings of the report the run's bench used (docs/bench.md, "Readings"), or an empty string."""
    r = s.get("readings")
    if not r:
        return ""
    return "Readings of the report: " + ", ".join(f"{k} {v}" for k, v in r.items())




def _interrupted_lines(s: dict) -> list[str]:
    """The report's warning that the run was stopped early, and how far it got (nothing for a complete run)."""
    if s["complete"]:
        return []
    i = s["interruption"]
    return [f"**Interrupted**: stopped by {i['by'] or 'a stop request'} after {i['sim_time_s']:.3f} s, with "
            f"{i['strides_run']} whole strides of gait run; every figure below covers that part only "
            "(summary.json: \"complete\": false).", ""]


def _report_md(s: dict, md_extra: list[str] | None = None) -> str:
    asked = "strides asked" if not s["complete"] and "stop" not in s else "strides"  # serial: strides run
    lines = [
        "# pafp run report", "", *_interrupted_lines(s),
        f"{s['strides']} {asked}, {s['sim_time_s']:.3f} s simulated in {s['wall_time_s']:.2f} s "
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
    lines += ["", "Files: `telemetry.bin` (raw telemetry UART), `telemetry.csv`, `trace.pftrace` (Perfetto: "
              "ui.perfetto.dev), `tracking.png`, `thermal.png`, `summary.json`.", ""]
    return "\n".join(lines)


def adc_summary(r: RunResult) -> dict | None:
    """summary.json's ``adc`` (None without the ADC sensors fitted): every sensor on the ADC, shipped or a plug-in's
    (hal/virtual/devices/registry.py), with its channels' codes as the MCU's ADC buffer held them at the run's end."""
    sensors = getattr(getattr(r, "bench", None), "ground_sensors", None)
    if sensors is None:
        return None
    from hal.virtual.devices.registry import DEVICES

    adc = sensors.adc
    codes = dict(zip(adc.channels, adc.read(), strict=True))
    shipped = {n.replace("-", "_") for n in DEVICES.shipped()}
    return {"bits": adc.bits, "vref_v": adc.vref_v, "at_s": round(r.sim_time_s, 6),
            "sensors": {part: {"origin": "shipped" if part in shipped else "plug-in",
                               "channels": {ch: codes[ch] for ch in sensor.outputs() if ch in codes}}
                        for part, sensor in sensors.parts.items()}}


def adc_lines(adc: dict) -> list[str]:
    """report.md's section on the ADC sensors."""
    lsb = adc["vref_v"] / 2 ** adc["bits"]
    lines = ["", "## Sensors on the ADC", "",
             f"The codes the MCU's ADC buffer held at {adc['at_s']:.3f} s ({adc['bits']} bits, {adc['vref_v']:g} V).",
             "", "| sensor | origin | channel | code | volts |", "|---|---|---|---|---|"]
    for part, sensor in adc["sensors"].items():
        for ch, code in sensor["channels"].items():
            lines.append(f"| {part} | {sensor['origin']} | {ch} | {code} | {code * lsb:.3f} |")
    return lines


def write_outputs(r: RunResult, out: Path, extra: dict | None = None, md_extra: list[str] | None = None, *,
                  plot: bool = True, trace: bool = True) -> dict:
    """Write every output file into `out`; return the summary (`extra` merged in; `md_extra` ends report.md).

    ``plot=False`` and ``trace=False`` leave out tracking.png and trace.pftrace.
    """
    out.mkdir(parents=True, exist_ok=True)
    tracking = tracking_of(r)
    files = getattr(r, "files", None)
    if files is None:
        write_atomic(out / "telemetry.bin", r.telemetry)
    s = summarise(r, tracking)
    s.update(extra or {})
    s["telemetry"]["decoder"] = (files.decoder_stats() if files is not None
                                 else _write_telemetry_csv(r.telemetry, out / "telemetry.csv", r.firmware.f_cpu_hz,
                                                          extra_names=r.firmware.published_names))
    if trace and r.scheduler.trace is not None:
        from host_tools.reports.timeline import write_trace  # the perfetto package: only when a trace is written

        with naming(out / TRACE_FILE):
            write_trace(r, out / TRACE_FILE, (files.directory if files is not None else out) / "telemetry.bin")
    fw = r.firmware
    if plot:  # drawn on every path, also when no stride ran (a run stopped early still shows its currents)
        from host_tools.reports.plots import plot_tracking  # matplotlib: only when a plot is drawn

        ref = fw.reference
        pct = np.linspace(0, 100, 101)
        band = np.array([ref.band_deg(x) for x in pct])
        p = tracking.plot
        shown = [name for name, _, _ in TRACKING_SIGNALS if name != "truth" or _has_plant(r)]
        label = {"truth": "truth (emulation only)"}
        strides = {label.get(n, n): st for n, st in tracking.strides.items() if n in shown and n in PLOT_STRIDES}
        errors = {label.get(n, n): p.errors_deg[n] for n in shown}
        plot_tracking(out / "tracking.png", strides, (pct, band[:, 0], band[:, 1]), p.t_s, p.current_cmd_a,
                      p.current_meas_a, errors, f"Gait tracking, {s['strides']} strides, RMS measured by the IMU "
                      f"{_figure(s['imu_rms_error_deg'], 2, '°')}, by the encoder "
                      f"{_figure(s['encoder_rms_error_deg'], 2, '°')}")
    if getattr(r.config, "scenario", "suspended") == "walk":
        from host_tools.reports.actuator import walk_outputs

        s["actuator"], walk_md = walk_outputs(r, out, tracking.plot.t_s, tracking.plot.current_cmd_a,
                                              tracking.plot.current_meas_a)
        md_extra = [*(md_extra or []), *walk_md]
    if getattr(r, "heat", None):  # a virtual run: the winding model, the supply and their log (runner.attach_heat)
        from host_tools.reports.thermal import battery_summary, thermal_lines, thermal_summary

        s["thermal"] = thermal_summary(r)
        s["battery"] = battery_summary(r, fw.config.stride_s, getattr(r.config, "speed", None))
        md_extra = [*(md_extra or []), *thermal_lines(s["thermal"], s["battery"])]
        if plot:
            from host_tools.reports.thermal import plot_thermal

            plot_thermal(out / "thermal.png", s["thermal"], s["battery"])
    adc = adc_summary(r)
    if adc is not None:
        s["adc"] = adc
        md_extra = [*(md_extra or []), *adc_lines(adc)]
    gait = event_summary(r)
    if gait is not None:
        s["gait_events"] = gait
        md_extra = [*(md_extra or []), *gait_event_lines(gait)]
    s["files_sha256"] = file_digests(out)  # ties record.bin and telemetry.csv to this run (`pafp fit` checks)
    elapsed = process_elapsed_s()  # all but the two writes below and the exit
    s["process_wall_time_s"] = round(elapsed, 3)
    s["process_realtime_factor"] = round(r.sim_time_s / elapsed, 2) if elapsed > 0 else None
    write_atomic(out / "summary.json", json.dumps(strict_json(s), indent=2, allow_nan=False) + "\n")
    write_atomic(out / "report.md", _report_md(s, md_extra))
    return s


def run_into(cfg: RunConfig, run_dir: RunDir, *, extra: dict | None = None, plot: bool = True, trace: bool = True,
             progress: Callable[[float], None] | None = None, should_stop: Callable[[], bool] | None = None,
             on_run: Callable[[], None] | None = None) -> tuple[RunResult, dict]:
    """Run cfg on the virtual bench streaming into run_dir's staging directory, write every output, publish it.

    Returns the result and its summary. On any exception (a write that fails: OSError naming the file) the
    staging directory is removed, so --out keeps what it held. ``on_run`` is called between the run and the
    writes (the progress bar's end).
    """
    from dataclasses import replace

    from host_tools.runner import run_virtual

    with run_dir.filling() as staged:
        cfg = replace(cfg, stream_to=staged, trace_capacity=cfg.trace_capacity if trace else 0)
        result = run_virtual(cfg, progress=progress, should_stop=should_stop)
        if on_run is not None:
            on_run()
        s = write_outputs(result, staged, extra, plot=plot, trace=trace)
    return result, s

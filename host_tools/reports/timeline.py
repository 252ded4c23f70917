"""The trace of a run as a firmware engineer reads it: tasks, interrupts, counters and instants (trace.pftrace).

Tracks, in the order the Perfetto UI shows them (docs/telemetry.md, "The trace"):

* **firmware**: one slice track per task, highest priority first, a slice per job (its own cycles and the
  interference in its arguments), then one track per interrupt source with a slice per firing that preempted a job:
  the firings the scheduler counted in that job (``rtos.trace.IrqRecord``), each served from its firing time or
  after the previous one's end, for the source's cycles. Firings on an idle CPU are not drawn (they cost no job
  anything; the CPU counter holds them).
* **kernel**: deadline misses, overrun faults, watchdog kicks and resets; **safety**: each fault trip (reason
  and measured value) and the first safe command that reached the motor after it (zero current or the brake);
  **gait (detector)**: heel strike, foot flat, heel off and toe off as each detector saw them; **fault injector**:
  each time an injector acted (a campaign point, ``RunConfig.faults``); with ``--trace-wire`` a track per wire and
  direction with a slice per frame (host_tools/reports/wire_trace.py).
* **counters**: the telemetry records' reference, encoder, IMU and fused angles, current command and measurement and
  supervisor state, at each record's own time (the logger's rate); the winding temperature the motor reports and,
  with a battery, the bus voltage the firmware has, and the CPU utilisation per window, every :data:`SAMPLE_S`;
  the thermal model's winding temperature (emulation only).

A run keeps only the last ``window_s`` seconds of it (the scheduler's trace is pruned as the run goes, and the
rest is cut at the end), so a long walk's memory stays bounded.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from host_tools.reports.perfetto_trace import PerfettoTrace, Stream
from protocol.telemetry import RECORD_FIELDS, TelemetryDecoder

__all__ = ["COUNTERS", "Timeline", "write_trace"]

COUNTERS = (("reference_rad", "reference angle", "deg"), ("encoder_angle_rad", "encoder angle", "deg"),
            ("imu_pitch_rad", "IMU pitch", "deg"), ("fused_angle_rad", "fused angle", "deg"),
            ("current_cmd_a", "current command", "A"), ("current_meas_a", "current measured", "A"))
"""Telemetry fields drawn as counters: (field, track name, unit); angles in degrees."""
SLOW = (("motor-reported winding temperature", "C"), ("bus voltage (firmware)", "V"), ("CPU utilisation", "%"),
        ("winding temperature, model (emulation only)", "C"))
"""The counters the timeline samples itself, in the order of its samples' values."""
GAIT = ("heel strike", "foot flat", "heel off", "toe off")
SAMPLE_S = 0.1
"""The slow counters' period, which is also the CPU utilisation's window: the motor reports its temperature and bus
voltage at about 10 Hz (with the full status reply), and a sample costs the run an interpreted call."""


class Timeline:
    """What the trace needs beyond the scheduler's records: slow counters, the safe commands on the wire, the window.

    :meth:`sample` is the bench probe's listener (``ProbeBody.slow_listeners``): it samples the slow counters and prunes
    the scheduler's trace to the window. ``watch`` (an observer of the motor's received commands, gated by
    :meth:`watching`) is armed at the first trip (:meth:`watch_from_trip`).
    """

    def __init__(self, scheduler: Any, firmware: Any, f_cpu_hz: int, window_s: float | None,
                 winding: Callable[[], float] | None = None) -> None:
        """Sample ``firmware``'s view and ``scheduler``'s utilisation; keep ``window_s`` seconds (None: all)."""
        self.scheduler, self.firmware, self.f_cpu_hz = scheduler, firmware, f_cpu_hz
        self.window_cycles = None if window_s is None else int(window_s * f_cpu_hz)
        self.winding = winding
        self.samples: deque[tuple[int, float, float, float, float]] = deque()
        self.watch: Any = None  # an Observer(sample=False, gate=...) of the motor's commands
        self.wire: Any = None  # a WireTrace (host_tools/reports/wire_trace.py) with --trace-wire
        self._busy = (0, 0)  # (time, busy cycles) at the previous sample
        self.sample_cycles = int(SAMPLE_S * f_cpu_hz) - f_cpu_hz // 1000  # a probe period's slack

    def watch_from_trip(self, rig: Any) -> None:
        """Arm the watch on ``rig``'s taps at the supervisor's first trip (``Supervisor.on_trip``), not before: a tap
        on the motor's wire costs the run a call per frame (and the UART its horizon), which a run that never trips
        need not pay."""
        def on_trip() -> None:
            if self.watch is None:
                from hal.virtual.faults.observer import Observer

                self.watch = Observer(sample=False, gate=self.watching)
                self.watch.arm(rig)
        self.firmware.supervisor.on_trip = on_trip

    def watching(self) -> bool:
        """The watch's gate: True from a trip until the first safe command after it reached the motor (so the watch
        decodes and keeps a handful of commands per trip, however long the run goes on in the safe state)."""
        trips = self.firmware.supervisor.trips
        if not trips:
            return False
        last = self.watch.commands[-1] if self.watch.commands else None
        return last is None or not (last[2] and last[0] >= trips[-1][0])

    def sample(self, t_s: float) -> None:
        """Called by the probe (10 Hz): every SAMPLE_S, one sample of the slow counters; forget what left the window."""
        now = self.scheduler.now
        t0, b0 = self._busy
        if now - t0 < self.sample_cycles:
            return
        busy = self.scheduler.busy_cycles()
        cpu = 100.0 * (busy - b0) / (now - t0)
        self._busy = (now, busy)
        fb = self.firmware.motor.feedback
        model = self.winding() if self.winding is not None else math.nan
        self.samples.append((now, float(fb.temp_motor_c), float(fb.v_in_v), cpu, model))
        if self.window_cycles is not None and now > self.window_cycles:  # the run is longer than the window
            cut = now - self.window_cycles
            while self.samples and self.samples[0][0] < cut:
                self.samples.popleft()
            trace = self.scheduler.trace
            if trace is not None:
                trace.prune_before(cut)
            if self.wire is not None:
                self.wire.prune_before(cut)


def _telemetry_records(telemetry: bytes | Path, extra: int) -> Iterator[tuple[int | float, ...]]:
    """The telemetry records' values (RECORD_FIELDS order), from the bytes or a telemetry.bin, a block at a time."""
    decoder = TelemetryDecoder(extra)
    if isinstance(telemetry, Path):
        with telemetry.open("rb") as f:
            while block := f.read(1 << 20):
                yield from decoder.feed_values(block)
    else:
        yield from decoder.feed_values(telemetry)


class _Builder:
    """The tracks of one trace and the streams of their events."""

    def __init__(self, f_cpu_hz: int, board: str) -> None:
        self.pf = PerfettoTrace()
        self.f = f_cpu_hz
        self.fw_track = self.pf.track(f"firmware ({board})", ordered=True, rank=0)
        self.rank = 0

    def ns(self, cycles: int) -> int:
        return cycles * 1_000_000_000 // self.f

    def child(self, name: str) -> int:
        """A new track in the firmware group, after the others."""
        self.rank += 1
        return self.pf.track(name, self.fw_track, rank=self.rank)


def _job_streams(b: _Builder, trace: Any, cut: int, hidden: set[str]) -> list[Stream]:
    """The job slices and the interrupt slices inside them."""
    pf = b.pf
    tasks = {name: b.child(name) for name in trace.task_names if name not in hidden}
    irqs = [i for i in trace.irqs() if i.job_start >= cut]
    fired = {i.source for i in irqs}  # a source that preempted nothing in the window has no track
    isr = {k: b.child(f"ISR {name}") for k, (name, _cost) in enumerate(trace.interrupts) if k in fired}
    jobs: list[tuple[int, bytes]] = []
    for task, job, _release, _ready, start, finish, cost in trace.jobs():
        if task in hidden or start < cut:
            continue
        track = tasks[task]
        preempted = finish - start - cost
        jobs += pf.slice(track, task, b.ns(start), b.ns(finish),
                         {"job": job, "cycles": cost, "interference_cycles": preempted} if preempted else {"job": job})
    return [jobs, _isr_slices(b, trace.interrupts, irqs, isr)]


def isr_layout(start: int, firings: Iterable[tuple[int, int, int]]) -> list[tuple[int, int, int]]:
    """(source, begin, end) of each firing (time, source, cycles) of a job that started at ``start``, served in
    time order, each from its firing time or the previous one's end (a firing of unknown time: time -1).

    >>> isr_layout(100, [(150, 0, 20), (160, 1, 30), (-1, 0, 20)])
    [(0, 100, 120), (0, 150, 170), (1, 170, 200)]
    """
    out, t = [], start
    for when, source, cycles in sorted(firings):
        begin = max(t, when, start)
        t = begin + cycles
        out.append((source, begin, t))
    return out


def _isr_slices(b: _Builder, sources: list[tuple[str, int]], irqs: list[Any], tracks: dict[int, int]
                ) -> list[tuple[int, bytes]]:
    pf, costs = b.pf, [c for _n, c in sources]
    names = [f"ISR {n}" for n, _c in sources]
    by_job: dict[int, list[tuple[int, int, int]]] = {}
    for job_start, source, count, times in irqs:
        fired = times if len(times) == count else (-1,) * count
        by_job.setdefault(job_start, []).extend((t, source, costs[source]) for t in fired)
    out = []
    for start, firings in by_job.items():
        for source, begin, end in isr_layout(start, firings):
            out += pf.slice(tracks[source], names[source], b.ns(begin), b.ns(end))
    out.sort(key=lambda tp: tp[0])  # by_job keeps the jobs in order; the sort keeps an end before the next begin
    return out


def _wire_streams(b: _Builder, wire: Any, cut: int) -> list[Stream]:
    """A slice per frame on each wire's track (``--trace-wire``)."""
    out = []
    for name, frames in wire.frames.items():
        if not frames:  # a direction that carried nothing (the MCU sends the IMU nothing)
            continue
        track = b.child(name)
        stream = []
        for start, end, what in frames:
            if start >= cut:
                stream += b.pf.slice(track, what, b.ns(start), b.ns(end))
        out.append(stream)
    return out


def _kernel_events(b: _Builder, trace: Any, cut: int, track: int, hidden: set[str]) -> list[tuple[int, bytes]]:
    names = {"deadline_miss": "deadline miss", "fault": "overrun fault", "watchdog_kick": "watchdog kick",
             "watchdog_reset": "watchdog reset"}
    out = [b.pf.instant(track, names.get(kind, kind), b.ns(t), {"task": source, "job": job})
           for kind, t, source, job in trace.events() if t >= cut and source not in hidden]
    out.sort(key=lambda tp: tp[0])
    return out


def _counter_streams(b: _Builder, records: Iterable[tuple[int | float, ...]], cut: int, group: int) -> list[Stream]:
    pf = b.pf
    index = {name: k for k, name in enumerate(RECORD_FIELDS)}
    tracks = [(index[field], pf.track(name, group, unit=unit, rank=k), unit == "deg")
              for k, (field, name, unit) in enumerate(COUNTERS)]
    state_track = pf.track("supervisor state (0 INIT, 1 RUN, 2 SAFE)", group, unit="state", rank=len(COUNTERS))
    at, state_at = index["time_cycles"], index["supervisor_state"]
    streams: list[list[tuple[int, bytes]]] = [[] for _ in tracks]
    states: list[tuple[int, bytes]] = []
    last_state = None
    for rec in records:
        t = int(rec[at])
        if t < cut:
            continue
        t_ns = b.ns(t)
        for stream, (k, track, deg) in zip(streams, tracks, strict=True):
            v = float(rec[k])
            stream.append(pf.counter(track, t_ns, math.degrees(v) if deg else v))
        if rec[state_at] != last_state:
            last_state = rec[state_at]
            states.append(pf.counter(state_track, t_ns, float(last_state)))
    return [*streams, states]


def _slow_streams(b: _Builder, timeline: Timeline | None, cut: int, group: int, battery: bool) -> list[Stream]:
    if timeline is None or not timeline.samples:
        return []
    pf, out = b.pf, []
    for k, (name, unit) in enumerate(SLOW):
        if (k == 1 and not battery) or (k == 3 and timeline.winding is None):
            continue
        track = pf.track(name, group, unit=unit, rank=len(COUNTERS) + 1 + k)
        out.append([pf.counter(track, b.ns(s[0]), s[k + 1]) for s in timeline.samples
                    if s[0] >= cut and math.isfinite(s[k + 1])])
    return out


def _firmware_instants(b: _Builder, r: Any, timeline: Timeline | None, cut_s: float) -> list[Stream]:
    """Fault trips, the safe commands after them, the gait events and the injectors' acts."""
    pf, fw = b.pf, r.firmware
    ns = lambda t_s: int(round(t_s * 1e9))  # noqa: E731 - the firmware's times are seconds
    sup = b.child("safety")
    trips = [(t, reason, detail) for t, reason, detail in fw.supervisor.trips]
    events = [pf.instant(sup, f"fault trip: {reason}", ns(t), {"reason": reason, "measured": detail})
              for t, reason, detail in trips if t >= cut_s]
    watch = getattr(timeline, "watch", None)
    if watch is not None:
        for t_trip, reason, _detail in trips:
            first = next(((t, i) for t, i, safe in watch.commands if safe and t >= t_trip), None)
            if first is not None and first[0] >= cut_s:
                what = "brake" if first[1] != 0.0 else "zero current"
                events.append(pf.instant(sup, "safe command on the wire", ns(first[0]),
                                         {"command": what, "current_a": first[1], "after": reason,
                                          "latency_ms": round((first[0] - t_trip) * 1e3, 3)}))
    stop = getattr(r, "stop", None)  # the serial run's stop path (host_tools/serial_mode/stop_record.py)
    safe = getattr(stop, "safe", None)
    if safe is not None and safe.on_wire:  # out of the port latency_ms after the stop began
        t = stop.at_s + stop.latency_ms / 1e3 if stop.latency_ms is not None else safe.at_s
        if t >= cut_s:
            events.append(pf.instant(sup, "safe command on the wire", ns(t),
                                     {"command": ", ".join(safe.names) or "stop", "after": f"stop ({stop.reason})"}))
    streams: list[Stream] = [sorted(events, key=lambda tp: tp[0])]
    detectors = [("motor load", fw.load_detector, ("heel_strike_s", None, None, "toe_off_s"))]
    if getattr(fw, "ground_events", None) is not None:
        detectors.append(("ground sensors", fw.ground_events, ("heel_strike_s", "foot_flat_s", "heel_off_s",
                                                                "toe_off_s")))
    for label, detector, lists in detectors:
        track = b.child(f"gait ({label})")
        gait = [pf.instant(track, name, ns(t), {"detector": label})
                for name, attr in zip(GAIT, lists, strict=True) if attr is not None
                for t in getattr(detector, attr) if t >= cut_s]
        streams.append(sorted(gait, key=lambda tp: tp[0]))
    injectors = [f for f in getattr(r.config, "faults", ()) if hasattr(f, "record") and hasattr(f, "describe")]
    if injectors:
        track = b.child("fault injector")
        acts = [pf.instant(track, f"injector {f.NAME}", ns(t), {"fault": f.describe(), "what": f.record.what})
                for f in injectors for t in f.record.times_s if t >= cut_s]
        streams.append(sorted(acts, key=lambda tp: tp[0]))
    return streams


def write_trace(r: Any, path: Path, telemetry: bytes | Path, board: str = "") -> int:
    """Write the trace of run ``r`` (a RunResult or SerialRunResult) to ``path``; return its size in bytes.

    ``telemetry`` is the run's telemetry stream (its bytes or its telemetry.bin).
    """
    trace = r.scheduler.trace
    f = int(r.firmware.f_cpu_hz)
    timeline: Timeline | None = getattr(r, "timeline", None)
    window = timeline.window_cycles if timeline is not None else None
    cut = 0 if window is None else max(0, r.scheduler.now - window)
    clock = "wall clock" if r.scheduler.clock.realtime else f"{f / 1e6:g} MHz"
    b = _Builder(f, f"{board or getattr(r.config, 'board', '') or 'MCU'}, {clock}")
    hidden = {"bench_probe", "serial_probe"}  # instruments of the bench, not firmware
    streams = _job_streams(b, trace, cut, hidden)
    streams.append(_kernel_events(b, trace, cut, b.child("kernel"), hidden))
    streams += _firmware_instants(b, r, timeline, cut / f)
    if timeline is not None and timeline.wire is not None:
        streams += _wire_streams(b, timeline.wire, cut)
    counters = b.pf.track("counters", ordered=True, rank=1)
    extra = len(getattr(r.firmware, "published_names", ()))
    streams += _counter_streams(b, _telemetry_records(telemetry, extra), cut, counters)
    battery = bool((getattr(r, "heat", None) or {}).get("battery"))
    streams += _slow_streams(b, timeline, cut, counters, battery)
    return b.pf.write(path, streams)


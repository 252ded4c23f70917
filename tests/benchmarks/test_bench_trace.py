"""What the run's trace (trace.pftrace, host_tools/reports/timeline.py) costs: speed, size and memory.

- ``test_bench_trace_realtime_factor``: the realtime factor of 2 strides with the trace and without it, side by
  side (the two alternate, best of ROUNDS each); goal: with it within 10 % of without; beside it, the median of
  each pair's own ratio. The same factors on the
  process's CPU time go beside them: on a machine shared with other work the wall-clock pair can differ by more
  than the trace costs; CPU time leaves out the time the run waited for a core (not a shared cache's slowing).
  Beside them, the minor page faults of each run (fewest of the rounds) and the wall time of a first write to a
  page on this machine: a virtual machine that hands freed memory back to its host pays tens of µs for each.
- ``test_bench_trace_size``: a 20-stride run whose window holds all of it (``--trace-strides 20``): the file's
  size (goal under 10 MB), the time to write it, and the same events as Chrome trace-event JSON (the format the
  run wrote before: a slice as an "X" event, a counter sample as a "C" event, an instant as an "i" event), the
  measurement behind writing Perfetto's protobuf.
- ``test_bench_trace_memory``: peak RSS (VmHWM) of a 20 kg walk of 25 and of 100 strides, with and without the
  trace (fresh processes): the trace's share, and that it does not grow with the walk (its 20 s window).
"""

from __future__ import annotations

import json
import mmap
import resource
import statistics
import time
from pathlib import Path

from host_tools.build_info import describe
from host_tools.reports.report import TRACE_FILE, write_outputs
from host_tools.runner import RunConfig, run_virtual
from tests.benchmarks.test_bench_process import _process
from tests.trace_reader import read_trace

ROUNDS = 40
"""Pairs of runs of the realtime factor (about 0.2 s each): on a shared virtual machine the speed of both changes
by 5 to 50 % for seconds at a time, and fewer rounds let such a stretch decide which one got the quiet moments."""
SIZE_MB = 10.0


def _first_write_us(pages: int = 4000) -> float:
    """Wall time of a first write to a page of fresh anonymous memory, in µs (a minor page fault each)."""
    with mmap.mmap(-1, pages * mmap.PAGESIZE) as m:
        t0 = time.perf_counter()
        for k in range(0, pages * mmap.PAGESIZE, mmap.PAGESIZE):
            m[k] = 1
        return (time.perf_counter() - t0) / pages * 1e6


def test_bench_trace_realtime_factor(benchmark) -> None:
    factors: dict[str, list[float]] = {"on": [], "off": [], "cpu_on": [], "cpu_off": []}
    faults: dict[str, list[int]] = {"on": [], "off": []}

    def run() -> None:
        for key, capacity in (("off", 0), ("on", RunConfig.trace_capacity)):
            cpu = time.process_time()
            f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
            r = run_virtual(RunConfig(strides=2, trace_capacity=capacity))
            faults[key].append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
            factors[f"cpu_{key}"].append(r.sim_time_s / (time.process_time() - cpu))
            factors[key].append(r.sim_time_s / r.wall_time_s)

    benchmark.pedantic(run, rounds=ROUNDS, iterations=1)
    on, off = max(factors["on"]), max(factors["off"])
    cpu_on, cpu_off = max(factors["cpu_on"]), max(factors["cpu_off"])
    info = benchmark.extra_info
    info.update(build=describe(), realtime_factor_trace_on=round(on, 2), realtime_factor_trace_off=round(off, 2),
                ratio=round(on / off, 3), cpu_time_factor_trace_on=round(cpu_on, 2),
                cpu_time_factor_trace_off=round(cpu_off, 2), cpu_time_ratio=round(cpu_on / cpu_off, 3),
                minor_faults_trace_on=min(faults["on"]), minor_faults_trace_off=min(faults["off"]),
                first_write_to_a_page_us=round(_first_write_us(), 1),
                # each pair's own ratio (its two runs back to back), their median: beside the ratio of the best, a
                # figure a slow stretch of the machine moves less (it slows both runs of a pair alike)
                paired_ratio_median=round(statistics.median(a / b for a, b in zip(
                    factors["on"], factors["off"], strict=True)), 3))
    assert on >= 0.9 * off


def _chrome_json(path: Path) -> bytes:
    """The events of a trace.pftrace as a Chrome trace-event JSON document (one tid per track)."""
    tr = read_trace(path)
    tid = {uuid: k for k, uuid in enumerate(tr.tracks)}
    events: list[dict] = [{"name": "thread_name", "ph": "M", "pid": 1, "tid": tid[u], "args": {"name": t.name}}
                          for u, t in tr.tracks.items()]
    events += [{"name": s.name, "ph": "X", "pid": 1, "tid": tid[s.track], "ts": s.ts / 1e3, "dur": s.dur / 1e3,
                "args": s.args} for s in tr.slices]
    events += [{"name": s.name, "ph": "i", "s": "t", "pid": 1, "tid": tid[s.track], "ts": s.ts / 1e3,
                "args": s.args} for s in tr.instants]
    events += [{"name": tr.tracks[u].name, "ph": "C", "pid": 1, "ts": t / 1e3, "args": {"value": v}}
               for u, samples in tr.counters.items() for t, v in samples]
    return json.dumps({"traceEvents": events}).encode()


def test_bench_trace_size(benchmark, tmp_path: Path) -> None:
    r = run_virtual(RunConfig(strides=20, trace_window_s=None))
    written: list[float] = []

    def write() -> None:
        t0 = time.perf_counter()
        write_outputs(r, tmp_path, plot=False)
        written.append(time.perf_counter() - t0)

    benchmark.pedantic(write, rounds=1, iterations=1)
    size_mb = (tmp_path / TRACE_FILE).stat().st_size / 1e6
    tr = read_trace(tmp_path / TRACE_FILE)
    info = benchmark.extra_info
    info.update(build=describe(), sim_time_s=round(r.sim_time_s, 2), trace_mb=round(size_mb, 2),
                chrome_json_mb=round(len(_chrome_json(tmp_path / TRACE_FILE)) / 1e6, 2),
                slices=len(tr.slices), instants=len(tr.instants),
                counter_samples=sum(len(c) for c in tr.counters.values()), outputs_s=round(written[0], 2))
    assert size_mb < SIZE_MB


def test_bench_trace_memory(benchmark, tmp_path: Path) -> None:
    peaks: dict[str, float] = {}

    def run() -> None:
        for strides in (25, 100):
            for trace in (True, False):
                out = tmp_path / f"walk{strides}{trace}"
                args = ["run", "--scenario", "walk", "--strides", str(strides), "--body-mass", "20", "--no-plot",
                        "--out", str(out), *([] if trace else ["--no-trace"])]
                peaks[f"{strides}_{'trace' if trace else 'no_trace'}"] = _process(args, tmp_path)[1]

    benchmark.pedantic(run, rounds=1, iterations=1)
    info = benchmark.extra_info
    info.update(build=describe(), peak_rss_mb={k: round(v, 1) for k, v in peaks.items()},
                trace_share_mb={n: round(peaks[f"{n}_trace"] - peaks[f"{n}_no_trace"], 1) for n in (25, 100)})
    growth_traced = peaks["100_trace"] - peaks["25_trace"]
    growth_plain = peaks["100_no_trace"] - peaks["25_no_trace"]
    info["growth_25_to_100_mb"] = {"trace": round(growth_traced, 1), "no_trace": round(growth_plain, 1)}
    assert growth_traced < growth_plain + 10.0  # the window is full at 25 strides already: no growth beyond it

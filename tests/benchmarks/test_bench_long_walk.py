"""A 1000-stride walk at 20 kg on the AK60-6 from a battery: wall time, peak memory and the thermal figures.

``pafp run --scenario walk --strides 1000 --body-mass 20 --battery molicel_p42a_6s1p`` runs once in a
subprocess (one round: it takes minutes); ``extra_info`` holds its wall time, the child's peak RSS
(``ru_maxrss``), the size of its trace.pftrace (the last 20 s: the trace's memory is measured in
test_bench_trace.py), and the summary's winding temperature after strides 1, 100, 500 and 1000, the steady state,
the energy per stride and the distance per charge (docs/design.md, "Winding temperature and battery in a run").
The goals:
memory bounded (peak RSS under 600 MB, a 100-stride walk's plus a margin: the run streams its outputs and
keeps one heat row per stride) and fast (under 20 minutes on the 2-core machine).
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from pathlib import Path

from host_tools.build_info import describe

STRIDES = 1000
PEAK_RSS_MB = 600
WALL_S = 20 * 60


def _walk(out: Path, strides: int) -> tuple[float, dict]:
    cmd = [sys.executable, "-m", "host_tools", "run", "--scenario", "walk", "--strides", str(strides),
           "--body-mass", "20", "--battery", "molicel_p42a_6s1p", "--out", str(out)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    return time.perf_counter() - t0, json.loads((out / "summary.json").read_text())


def test_bench_long_walk(benchmark, tmp_path: Path) -> None:
    result: dict = {}

    def run() -> float:
        wall, summary = _walk(tmp_path / "walk", STRIDES)
        result.update(wall=wall, summary=summary)
        return wall

    benchmark.pedantic(run, rounds=1, iterations=1)
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    s = result["summary"]
    t, b = s["thermal"], s["battery"]
    by_stride = t["winding_c_by_stride"]
    info = benchmark.extra_info
    info["build"] = describe()
    info["wall_s"] = round(result["wall"], 1)
    info["peak_rss_mb"] = round(peak_mb, 1)
    info["trace_mb"] = round((tmp_path / "walk" / "trace.pftrace").stat().st_size / 1e6, 2)  # its last 20 s
    info["winding_c_after_strides"] = {n: by_stride[n - 1] for n in (1, 100, 500, STRIDES) if n <= len(by_stride)}
    info["steady_state_c"] = t["steady_state_c"]
    info["time_constants_s"] = t["time_constants_s"]
    info["energy_per_stride_j"] = b["energy_per_stride_j"]
    info["distance_per_charge_km"] = b["distance_per_charge_km"]
    info["faults"] = s["faults"]
    assert len(by_stride) == STRIDES
    assert s["faults"] == []
    assert peak_mb < PEAK_RSS_MB
    assert result["wall"] < WALL_S

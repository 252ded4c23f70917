"""Wall time of `pafp sweep` on LocalClusters of worker processes (--benchmark-only).

`test_bench_sweep_grid`: profiles/sweeps/baud_gains.toml (9 points of 2 strides), and SEEDS_SPEC (16 seeds
of 4 strides: points long enough for the speed-up to show), each on 1 then 2 worker processes: wall time in
total (cluster start-up excluded and reported apart), per point, the speed-up, and the check that both
worker counts give the same table. `test_bench_sweep_robustness`: profiles/sweeps/robustness.toml
(200 Monte Carlo points) on 2 workers, with its figures (median and worst RMS, fault fraction).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from host_tools.studies.sweep_engine import check_points, dask_client, run_sweep
from host_tools.studies.sweep_spec import load_spec
from host_tools.studies.sweep_table import TIMING_COLUMNS

SWEEPS = Path(__file__).resolve().parents[2] / "profiles" / "sweeps"
SEEDS_SPEC = """
[base]
strides = 4
[[grid]]
key = "run.seed"
linspace = [0, 15, 16]
"""


def _timed_sweep(spec_path: Path, out: Path, workers: int) -> dict:
    spec = load_spec(spec_path)
    check_points(spec)
    t0 = time.perf_counter()
    with dask_client(workers=workers) as client:
        started = time.perf_counter() - t0
        outcome = run_sweep(spec, out, client, progress=False)
    rows = pq.read_table(out / "results.parquet").to_pylist()
    return {"cluster_start_s": round(started, 2), "total_s": round(outcome.wall_time_s, 2),
            "per_point_s": round(outcome.wall_time_s / len(rows), 4),
            "point_run_median_s": round(statistics.median(r["wall_time_s"] for r in rows), 4),
            "rows": [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows], "raw": rows}


@pytest.mark.parametrize("name", ["baud_gains", "seeds"])
def test_bench_sweep_grid(benchmark, tmp_path: Path, name: str):
    spec = SWEEPS / "baud_gains.toml"
    if name == "seeds":
        spec = tmp_path / "seeds.toml"
        spec.write_text(SEEDS_SPEC, encoding="utf-8")
    results: dict[int, dict] = {}

    def run() -> None:
        for w in (1, 2):
            results[w] = _timed_sweep(spec, tmp_path / f"w{w}", w)

    benchmark.pedantic(run, rounds=1, iterations=1)
    info = benchmark.extra_info
    for w, r in results.items():
        info[f"workers_{w}"] = {k: v for k, v in r.items() if k not in ("rows", "raw")}
    info["speedup_1_to_2_workers"] = round(results[1]["total_s"] / results[2]["total_s"], 2)
    assert results[1]["rows"] == results[2]["rows"]
    assert len(results[1]["rows"]) == {"baud_gains": 9, "seeds": 16}[name]


def test_bench_sweep_robustness(benchmark, tmp_path: Path):
    result: dict = {}

    def run() -> None:
        result.update(_timed_sweep(SWEEPS / "robustness.toml", tmp_path / "robustness", 2))

    benchmark.pedantic(run, rounds=1, iterations=1)
    rows = result["raw"]
    ran = [r for r in rows if r["status"] in ("ok", "fault")]
    rms = [r["rms_error_deg"] for r in ran]
    info = benchmark.extra_info
    info.update({k: v for k, v in result.items() if k not in ("rows", "raw")})
    info["points"] = len(rows)
    info["median_rms_deg"] = statistics.median(rms) if rms else None
    info["worst_rms_deg"] = max(rms) if rms else None
    info["fault_fraction"] = round(sum(bool(r["faults"]) for r in ran) / max(1, len(ran)), 4)
    info["failed_points"] = sum(r["status"] in ("error", "timeout") for r in rows)
    assert len(rows) == 200

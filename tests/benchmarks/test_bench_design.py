"""Wall time of the shipped design search, profiles/designs/adult.toml, on 2 worker processes (--benchmark-only).

Issue 23's goal: the whole search (192 walking runs of 20 strides) in under 20 minutes on this 2-core machine with
2 workers. Reports the spec's check (every design's profile built), the cluster's start-up, the total, the time per
point and the median point's own time, and checks that every point gave figures (ok or a fault, none an error).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import pyarrow.parquet as pq

from host_tools.commands.design import _write_profiles, columns
from host_tools.studies.design_point import design_error_row, run_design_point
from host_tools.studies.design_spec import load_design_spec
from host_tools.studies.sweep_engine import dask_client, run_tasks

ADULT = Path(__file__).resolve().parents[2] / "profiles" / "designs" / "adult.toml"
GOAL_S = 20 * 60


def test_bench_adult_design_search(benchmark, tmp_path: Path):
    result: dict = {}

    def run() -> None:
        t0 = time.perf_counter()
        spec = load_design_spec(ADULT)
        points = spec.points(tmp_path / "out")
        _write_profiles(points, tmp_path / "out")
        result["spec_check_s"] = time.perf_counter() - t0
        with dask_client(workers=2) as client:
            result["cluster_start_s"] = time.perf_counter() - t0 - result["spec_check_s"]
            outcome = run_tasks(points, run_design_point, tmp_path / "out", client, columns=columns(),
                                digest=spec.digest, error_row=design_error_row, progress=False,
                                ok=lambda row: row["status"] in ("ok", "fault"))
        result["search_s"] = outcome.wall_time_s
        result["total_s"] = time.perf_counter() - t0

    benchmark.pedantic(run, rounds=1, iterations=1)
    rows = pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()
    info = benchmark.extra_info
    info.update({k: round(v, 2) for k, v in result.items()})
    info["points"] = len(rows)
    info["per_point_s"] = round(result["search_s"] / len(rows), 3)
    info["point_median_s"] = round(statistics.median(r["wall_time_s"] for r in rows), 3)
    info["status"] = {s: sum(r["status"] == s for r in rows) for s in sorted({r["status"] for r in rows})}
    assert len(rows) == 192
    assert all(r["status"] in ("ok", "fault") for r in rows), [r["error"] for r in rows if r["error"]][:3]
    assert result["total_s"] < GOAL_S

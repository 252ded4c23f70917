"""Wall time of the shipped fault campaign, profiles/faults/default.toml, on 2 worker processes (--benchmark-only).

Issue 36's goal: the whole campaign (816 points: the suspended foot, walking at 20 kg on the AK60-6 and at 80 kg
on the adult design, UART and CAN servo, 4 onsets, 2 durations, every injector) within 20 minutes on this 2-core
machine with 2 workers. The bench keeps the stricter 15 minutes of the earlier goal (at least 500 points), which
the compiled build meets (docs/safety.md, "Speed"). Reports the cluster start-up apart, the total, the time per
point and the median point's own time (its faulted run and its share of the fault-free runs), and checks that
every point ran and its fault fired.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import pyarrow.parquet as pq

from host_tools.commands.faults import columns
from host_tools.studies.fault_point import fault_error_row, run_fault_point
from host_tools.studies.fault_spec import load_fault_spec
from host_tools.studies.sweep_engine import dask_client, run_tasks

DEFAULT = Path(__file__).resolve().parents[2] / "profiles" / "faults" / "default.toml"
GOAL_S = 15 * 60  # stricter than issue 36's 20 minutes, and met


def test_bench_default_fault_campaign(benchmark, tmp_path: Path):
    spec = load_fault_spec(DEFAULT)
    result: dict = {}

    def run() -> None:
        t0 = time.perf_counter()
        with dask_client(workers=2) as client:
            result["cluster_start_s"] = time.perf_counter() - t0
            outcome = run_tasks(spec.points(), run_fault_point, tmp_path / "out", client, columns=columns(),
                                digest=spec.digest, error_row=fault_error_row, progress=False)
        result["total_s"] = outcome.wall_time_s

    benchmark.pedantic(run, rounds=1, iterations=1)
    rows = pq.read_table(tmp_path / "out" / "results.parquet").to_pylist()
    info = benchmark.extra_info
    info.update({k: round(v, 2) for k, v in result.items()})
    info["points"] = len(rows)
    info["per_point_s"] = round(result["total_s"] / len(rows), 4)
    info["point_median_s"] = round(statistics.median(r["wall_time_s"] for r in rows), 4)
    info["not_ok"] = sum(r["status"] != "ok" for r in rows)
    assert len(rows) == spec.n_points >= 500
    assert all(r["fired"] for r in rows)
    assert result["total_s"] < GOAL_S

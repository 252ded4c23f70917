"""The shipped fault campaign, profiles/faults/default.toml, on 2 worker processes (--benchmark-only): its wall time,
and its tables are the ones docs/safety.md quotes (host_tools/reports/doc_figures.py, block default_campaign).

Issue 36's goal: the whole campaign (1632 points: the suspended foot, walking at 20 kg on the AK60-6 and at 80 kg
on the adult design, UART and CAN servo, 4 onsets, 2 durations, every injector, the shipped safe state and the
brake side by side) within 20 minutes on this 2-core machine with 2 workers. Reports the time per point and the
median point's own time (its faulted run and its share of the fault-free runs), and checks that every point ran
and its fault fired.
"""

from __future__ import annotations

import statistics

from host_tools.reports import doc_figures

GOAL_S = 20 * 60


def test_bench_default_fault_campaign(benchmark):
    result: dict = {}

    def run() -> None:
        result["spec"], result["rows"], result["total_s"] = doc_figures.campaign_run(doc_figures.DEFAULT_SPEC)

    benchmark.pedantic(run, rounds=1, iterations=1)
    spec, rows = result["spec"], result["rows"]
    info = benchmark.extra_info
    info["total_s"] = round(result["total_s"], 2)
    info["points"] = len(rows)
    info["per_point_s"] = round(result["total_s"] / len(rows), 4)
    info["point_median_s"] = round(statistics.median(r["wall_time_s"] for r in rows), 4)
    info["not_ok"] = sum(r["status"] != "ok" for r in rows)
    assert len(rows) == spec.n_points >= 500
    assert all(r["fired"] for r in rows)
    assert result["total_s"] < GOAL_S
    stale = doc_figures.check(blocks={"default_campaign": doc_figures.default_campaign})
    assert stale == [], "run: python -m host_tools.reports.doc_figures --write --bench"

"""Speed of a whole firmware run on the virtual bench: realtime factor of 2 strides (--benchmark-only).

The realtime factor is simulated seconds per wall second of the scheduler's run (what ``pafp run``
prints); it goes into ``benchmark.extra_info["realtime_factor"]`` (median over the rounds).
"""

from __future__ import annotations

import statistics

from host_tools.runner import RunConfig, run_virtual


def test_bench_run_two_strides(benchmark):
    factors: list[float] = []

    def run() -> float:
        result = run_virtual(RunConfig(strides=2))
        factors.append(result.sim_time_s / result.wall_time_s)
        return result.sim_time_s

    sim_s = benchmark.pedantic(run, rounds=3, iterations=1)
    benchmark.extra_info["realtime_factor"] = round(statistics.median(factors), 2)
    assert sim_s > 2.0
    assert all(f > 0.0 for f in factors)

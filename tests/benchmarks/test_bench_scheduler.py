"""Scheduler throughput against an equivalent SimPy 4 model, in jobs per second.

Run with ``.venv/bin/python -m pytest tests/benchmarks/test_bench_scheduler.py --benchmark-only``.
Five periodic tasks (utilisation 0.485) with empty job bodies, statistics on, trace off, over the same
span of virtual time. The SimPy model: one process per task that waits for each release, takes a
``simpy.PriorityResource(capacity=1)`` (non-preemptive, priority = our priority number) for the job's
cost, records the response (count, sum, worst), and skips releases that came while it was busy (our
SKIP policy). ``extra_info["jobs_per_s"]`` is from the median round; the SimPy benchmark also records
``ratio_ours_to_simpy`` (goal >= 5) against the empty-body variant of ours.

One known difference: when several tasks are released at the same instant while the CPU is idle,
SimPy grants the free resource to whichever request its event order processes first, not to the
highest priority; a few more releases are then skipped (33 001 jobs instead of 35 000). Rates are
compared per job, so this does not favour either side.
"""

from __future__ import annotations

from collections.abc import Generator
from typing import Any

import pytest

from rtos import Scheduler, Task

SPAN_CYCLES = 20_000_000  # 35 000 jobs
TASKS = [(1000, 100), (2000, 200), (5000, 500), (10_000, 1000), (20_000, 2000)]  # (period, cost) cycles
ROUNDS = 5
_RATES: dict[str, float] = {}


def _empty_body(job: object) -> None:
    """A job that does nothing."""


def _ours(body: Any) -> int:
    s = Scheduler([Task(f"t{i}", i + 1, period=p, cost=c, body=body) for i, (p, c) in enumerate(TASKS)])
    s.run_until(SPAN_CYCLES)
    return sum(st.jobs for st in s.stats.values())


def _simpy_model() -> int:
    simpy = pytest.importorskip("simpy")
    env = simpy.Environment()
    cpu = simpy.PriorityResource(env, capacity=1)
    stats = [[0, 0, 0] for _ in TASKS]  # jobs, response sum, worst response

    def task(prio: int, period: int, cost: int) -> Generator[Any, Any, None]:
        release = 0
        st = stats[prio - 1]
        while True:
            if env.now < release:
                yield env.timeout(release - env.now)
            with cpu.request(priority=prio) as req:
                yield req
                yield env.timeout(cost)
            resp = env.now - release
            st[0] += 1
            st[1] += resp
            if resp > st[2]:
                st[2] = resp
            release += period
            if release < env.now:  # SKIP: the next release is the first one at or after now
                release += -(-(env.now - release) // period) * period

    for i, (p, c) in enumerate(TASKS):
        env.process(task(i + 1, p, c))
    env.run(until=SPAN_CYCLES)
    return sum(s[0] for s in stats)


def _record(benchmark: Any, key: str, jobs: int) -> float:
    rate = jobs / benchmark.stats.stats.median
    benchmark.extra_info["jobs"] = jobs
    benchmark.extra_info["jobs_per_s"] = round(rate)
    _RATES[key] = rate
    return rate


def test_bench_ours_no_body(benchmark):
    jobs = benchmark.pedantic(_ours, args=(None,), rounds=ROUNDS, iterations=1)
    assert jobs == 35_000
    _record(benchmark, "no_body", jobs)


def test_bench_ours_empty_body(benchmark):
    jobs = benchmark.pedantic(_ours, args=(_empty_body,), rounds=ROUNDS, iterations=1)
    assert jobs == 35_000
    _record(benchmark, "empty_body", jobs)


def test_bench_simpy_equivalent(benchmark):
    jobs = benchmark.pedantic(_simpy_model, rounds=ROUNDS, iterations=1)
    assert 0.9 * 35_000 <= jobs <= 35_000  # see the module docstring on simultaneous releases
    rate = _record(benchmark, "simpy", jobs)
    if "empty_body" in _RATES:
        ratio = _RATES["empty_body"] / rate
        benchmark.extra_info["ratio_ours_to_simpy"] = round(ratio, 2)
        if "no_body" in _RATES:
            benchmark.extra_info["ratio_no_body_to_simpy"] = round(_RATES["no_body"] / rate, 2)
        assert ratio >= 5, f"ours {_RATES['empty_body']:.0f} jobs/s vs SimPy {rate:.0f} jobs/s"

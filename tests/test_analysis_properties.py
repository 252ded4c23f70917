"""Random task sets: the emulator never beats the analysis, reaches it at the critical instant, and
schedules by the rules (highest priority first, never idle while ready, deterministic)."""

from __future__ import annotations

import dataclasses

from hypothesis import assume, given
from hypothesis import strategies as st

from rtos import OverrunPolicy, PeriodicInterrupt, Scheduler, Task, Trace
from rtos.analysis import response_time_bounds
from rtos.critical import critical_instant, emulation_horizon, observe_worst, release_patterns

# divisor-friendly periods: every hyperperiod is at most 2000 ticks, so examples stay small
PERIODS = (100, 200, 250, 400, 500, 1000, 2000)
IRQ_PERIODS = (50, 100, 250, 500)
POLICIES = (OverrunPolicy.SKIP, OverrunPolicy.LATE, OverrunPolicy.QUEUE)


@st.composite
def task_sets(draw: st.DrawFn, jitter: bool = False, irqs: bool = False, policies: bool = False):
    """2-8 tasks (utilisation with interrupts <= 0.95), optional jitter and periodic interrupts."""
    n = draw(st.integers(2, 8))
    periods = [draw(st.sampled_from(PERIODS)) for _ in range(n)]
    sources = []
    if irqs:
        for j in range(draw(st.integers(0, 2))):
            sources.append(PeriodicInterrupt(f"irq{j}", draw(st.sampled_from(IRQ_PERIODS)),
                                             draw(st.integers(1, 20))))
    irq_u = sum(s.cost_cycles / s.period for s in sources)
    total = draw(st.floats(0.05, 0.95)) - irq_u
    assume(total > 0.02)
    shares = [draw(st.integers(1, 100)) for _ in range(n)]
    prios = draw(st.permutations(range(1, n + 1)))
    tasks = []
    for k in range(n):
        t = periods[k]
        cost = max(1, int(total * shares[k] / sum(shares) * t))
        tasks.append(Task(
            f"t{k}", prios[k], t, cost=cost,
            deadline=draw(st.integers(cost, 2 * t)),
            offset=draw(st.integers(0, t)),
            jitter=draw(st.integers(0, t // 4)) if jitter else 0,
            overrun=draw(st.sampled_from(POLICIES)) if policies else OverrunPolicy.SKIP,
        ))
    assume(sum(t.cost / t.period for t in tasks) + irq_u <= 0.95)
    return tasks, sources


def _run(tasks, irqs, horizon, seed=0, trace=None):
    """Emulate and return the scheduler."""
    s = Scheduler(tasks, interrupts=[PeriodicInterrupt(i.name, i.period, i.cost_cycles, i.offset) for i in irqs],
                  seed=seed, trace=trace)
    s.run_until(horizon)
    return s


@given(task_sets(jitter=True, irqs=True, policies=True), st.integers(0, 3))
def test_observed_never_exceeds_the_bound(case, seed):
    tasks, irqs = case
    davis = {b.name: b.bound for b in response_time_bounds(tasks, irqs)}
    discrete = {b.name: b.bound for b in response_time_bounds(tasks, irqs, blocking="discrete")}
    for name, d in discrete.items():
        assert d is not None and d <= davis[name]
    horizon, _, _ = emulation_horizon(tasks, irqs)
    runs = [_run(tasks, irqs, horizon, seed)]  # the drawn offsets
    for pattern in release_patterns(tasks, irqs):
        runs.append(_run(*pattern.apply(tasks, irqs), horizon, seed))
    for s in runs:
        for name, stats in s.stats.items():
            if stats.jobs:
                assert stats.worst_response <= discrete[name], name


@given(task_sets(irqs=True))
def test_critical_instant_reaches_the_discrete_bound_exactly(case):
    """Without jitter the critical-instant pattern reaches the 'discrete' bound to the tick.

    Every task queues its releases (OverrunPolicy.QUEUE) as the analysis assumes: with SKIP or LATE a
    task whose response exceeds its period drops releases that the analysis counts.
    """
    tasks, irqs = case
    tasks = [dataclasses.replace(t, overrun=OverrunPolicy.QUEUE) for t in tasks]
    davis = {b.name: b.bound for b in response_time_bounds(tasks, irqs)}
    bounds = response_time_bounds(tasks, irqs, blocking="discrete")
    horizon, _, _ = emulation_horizon(tasks, irqs)
    for b in bounds:
        pattern = critical_instant(tasks, b.name, irqs)
        s = _run(*pattern.apply(tasks, irqs), horizon)
        assert s.stats[b.name].worst_response == b.bound, (b.name, pattern)
        assert b.bound <= davis[b.name]


@given(task_sets())
def test_observe_worst_is_between_discrete_and_davis_bounds(case):
    tasks, irqs = case
    seen = observe_worst(tasks, irqs).worst
    bounds = response_time_bounds(tasks, irqs, blocking="discrete")
    davis = response_time_bounds(tasks, irqs)
    for b, d in zip(bounds, davis, strict=True):
        assert seen[b.name] == b.bound <= d.bound


def _check_rules(jobs, prio: dict[str, int]) -> None:
    """Highest-priority ready job starts; the CPU never idles while a job is ready."""
    prev_finish = 0
    for n, j in enumerate(jobs):
        assert j.start >= prev_finish
        for other in jobs[n + 1:]:
            if other.ready <= j.start and other.task != j.task:
                assert prio[other.task] > prio[j.task], (j, other)
            if j.start > prev_finish:  # the CPU idled before j: nothing started later was ready then
                assert other.ready >= j.start, (j, other)
        if j.start > prev_finish:
            assert j.ready == j.start, j
        prev_finish = j.finish


@given(task_sets(jitter=True, irqs=True, policies=True), st.integers(0, 5))
def test_scheduling_rules_and_determinism(case, seed):
    tasks, irqs = case
    horizon = 3 * max(t.period for t in tasks)
    traces = []
    for _ in range(2):
        tr = Trace(maxlen=100_000)
        s = _run([dataclasses.replace(t) for t in tasks], irqs, horizon, seed, tr)
        traces.append((tr.jobs(), [st.as_dict() for st in s.stats.values()]))
    assert traces[0] == traces[1]
    tr_jobs = traces[0][0]
    assert tr_jobs
    _check_rules(tr_jobs, {t.name: t.priority for t in tasks})

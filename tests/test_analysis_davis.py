"""The textbook example of Davis, Burns, Bril & Lukkien (2007), by analysis and by emulation."""

from __future__ import annotations

from pathlib import Path

import pytest

from rtos import PeriodicInterrupt, Scheduler, Task
from rtos.analysis import response_time_bounds
from rtos.critical import critical_instant, observe_worst, synchronous
from rtos.taskset import load_taskset

DAVIS = Path(__file__).resolve().parents[1] / "profiles" / "tasksets" / "davis2007.toml"


@pytest.fixture
def davis_tasks() -> list[Task]:
    return load_taskset(DAVIS).tasks


def _bounds(tasks, **kw):
    return {b.name: b for b in response_time_bounds(tasks, **kw)}


def test_davis_profile_is_the_published_task_set(davis_tasks):
    got = [(t.name, t.priority, t.period, t.deadline, t.cost) for t in davis_tasks]
    assert got == [("A", 1, 2500, 2500, 1000), ("B", 2, 3500, 3250, 1000), ("C", 3, 3500, 3250, 1000)]


def test_revised_analysis_gives_the_published_bounds(davis_tasks):
    b = _bounds(davis_tasks)
    assert (b["A"].bound, b["B"].bound, b["C"].bound) == (2000, 3000, 3500)
    assert b["B"].schedulable and not b["C"].schedulable
    assert b["C"].worst_instance == 1  # the second instance in the busy period is the worst
    assert b["C"].busy_period == 7000 and b["C"].instances == 2


def test_flawed_first_instance_analysis_says_three_ms(davis_tasks):
    flawed = _bounds(davis_tasks, first_instance_only=True)
    assert flawed["C"].bound == 3000 and flawed["C"].schedulable  # wrongly schedulable


def test_discrete_blocking_is_one_tick_less_for_blocked_tasks(davis_tasks):
    b = _bounds(davis_tasks, blocking="discrete")
    assert (b["A"].bound, b["B"].bound, b["C"].bound) == (1999, 2999, 3500)


def test_emulation_reaches_c_bound_and_b_only_at_its_critical_instant(davis_tasks):
    def worst(pattern):
        s = Scheduler(pattern.apply(davis_tasks)[0])
        s.run_until(20 * 3500)
        return {n: st.worst_response for n, st in s.stats.items()}

    sync = worst(synchronous(davis_tasks))
    assert sync["B"] == 2000 and sync["C"] == 3500
    crit_b = worst(critical_instant(davis_tasks, "B"))
    assert crit_b["B"] == 2999  # one tick short of the published 3000: the blocker starts a tick early
    assert critical_instant(davis_tasks, "B").blocker == "C"
    assert observe_worst(davis_tasks).worst == {"A": 1999, "B": 2999, "C": 3500}


def test_c_misses_its_deadline_in_emulation(davis_tasks):
    s = Scheduler(davis_tasks)
    s.run_until(3 * 3500)
    c = s.stats["C"]
    assert c.deadline_misses == 1 and c.worst_job_index == 1 and c.worst_response == 3500


def test_blocker_of_b_worst_case_is_named(davis_tasks):
    s = Scheduler(critical_instant(davis_tasks, "B").apply(davis_tasks)[0])
    s.run_until(3500)
    blk = s.stats["B"].worst_blocker
    assert (blk.task, blk.job, blk.cycles) == ("C", 0, 999)


def test_interrupt_at_the_start_instant_of_a_lowest_priority_task():
    """No lower-priority task: interrupts are counted over [0, w), so one firing exactly at w is not
    charged before the job starts (it is charged to the job itself) and cannot pull in a hp release."""
    tasks = [Task("H", 1, period=11, cost=9), Task("L", 2, period=1000, cost=10)]
    irq = [PeriodicInterrupt("tick", period=10, cost=1)]
    b = _bounds(tasks, interrupts=irq, blocking="discrete")
    s = Scheduler(tasks, interrupts=irq)
    s.run_until(1000)
    assert s.stats["L"].worst_response == b["L"].bound == 22


def test_interrupt_with_a_blocker_starts_with_it():
    tasks = [Task("H", 1, period=100, cost=5), Task("L", 2, period=100, cost=20)]
    irq = [PeriodicInterrupt("tick", period=10, cost=2)]
    bound = _bounds(tasks, interrupts=irq, blocking="discrete")["H"].bound
    ts, irqs = critical_instant(tasks, "H", irq).apply(tasks, irq)
    s = Scheduler(ts, interrupts=irqs)
    s.run_until(1000)
    # L runs from -1 (relative to H) with firings at -1, 9, 19: ends at 25; H then runs [25, 32) with the
    # firing at 29 -> response 32
    assert s.stats["H"].worst_response == bound == 32


def test_unbounded_when_utilisation_exceeds_one():
    tasks = [Task("a", 1, 10, cost=6), Task("b", 2, 10, cost=6)]
    b = _bounds(tasks)
    assert b["a"].bound == 12 and b["b"].bound is None and not b["b"].schedulable


def test_analysis_rejects_callable_costs_and_bad_blocking():
    with pytest.raises(ValueError, match="constant"):
        response_time_bounds([Task("x", 1, 10, cost=lambda n: 3)])
    with pytest.raises(ValueError, match="blocking"):
        response_time_bounds([Task("x", 1, 10, cost=3)], blocking="nope")  # type: ignore[arg-type]

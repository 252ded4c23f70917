"""Interrupt sources and interference: exact fixed point against a cycle-stepping reference."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from rtos import PeriodicInterrupt, Scheduler, Task, TimestampedInterrupt, Trace, solve_finish


def _fires_at(times_by_source, t):
    return [sum(1 for x in times if x == t) for times in times_by_source]


def brute_force_finish(start, cost, sources):
    """Step one cycle at a time: an interrupt firing at cycle t while work is left adds its cost."""
    times = [s[0] for s in sources]
    costs = [s[1] for s in sources]
    left, t = cost, start
    while left > 0:
        for n, c in zip(_fires_at(times, t), costs, strict=True):
            left += n * c
        left -= 1
        t += 1
    return t


def _periodic_times(period, offset, until):
    return list(range(offset, until, period))


@given(st.integers(1, 50), st.integers(0, 60), st.integers(0, 200), st.integers(0, 200))
def test_periodic_count_matches_enumeration(period, offset, t0, length):
    irq = PeriodicInterrupt("p", period, 1, offset)
    want = sum(1 for x in _periodic_times(period, offset, 500) if t0 <= x < t0 + length)
    assert irq.count_in(t0, t0 + length) == want


@given(
    st.lists(st.tuples(st.integers(3, 40), st.integers(0, 3), st.integers(0, 40)), min_size=1, max_size=3),
    st.integers(0, 100), st.integers(0, 120),
)
def test_solved_finish_equals_cycle_stepping(specs, start, cost):
    # keep the interrupt load below 1 so the job finishes
    specs = [(p, min(c, p // 2 // len(specs)), o) for p, c, o in specs]
    sources = [PeriodicInterrupt(f"i{k}", p, c, o) for k, (p, c, o) in enumerate(specs)]
    counts = [0] * len(sources)
    got = solve_finish(start, cost, sources, counts)
    ref = brute_force_finish(start, cost, [(_periodic_times(p, o, 10_000), c) for p, c, o in specs])
    assert got == ref
    assert sum(n * s.cost_cycles for n, s in zip(counts, sources, strict=True)) == got - start - cost


@given(st.lists(st.integers(0, 300), max_size=40), st.integers(0, 80), st.integers(1, 60))
def test_timestamped_source_in_a_schedule_matches_cycle_stepping(raw_times, cost_a, period):
    """Whole schedule with a bursty source: every job's finish equals the stepped reference."""
    times = sorted(raw_times)
    tasks = [Task("a", 1, period + 40, cost=cost_a % 30 + 1), Task("b", 2, 70, cost=13)]
    tr = Trace()
    s = Scheduler(tasks, interrupts=[TimestampedInterrupt("rx", 3, iter(times))], trace=tr)
    s.run_until(400)
    for j in tr.jobs():
        c = tasks[0].cost if j.task == "a" else tasks[1].cost
        assert j.finish == brute_force_finish(j.start, c, [(times, 3)])
    st_rx = s.interrupt_stats()[0]
    assert st_rx.count == sum(1 for x in times if x < max(400, s.now))
    in_jobs = sum(1 for x in times for j in tr.jobs() if j.start <= x < j.finish)
    assert st_rx.in_jobs == in_jobs


def test_timestamped_rejects_decreasing_times():
    irq = TimestampedInterrupt("bad", 1, [5, 3])
    with pytest.raises(ValueError, match="non-decreasing"):
        irq.count_in(0, 10)


def test_lazy_source_sees_non_decreasing_t0():
    class Recorder:
        name = "rec"
        cost_cycles = 2

        def __init__(self):
            self.calls = []

        def count_in(self, t0, t1):
            self.calls.append((t0, t1))
            return sum(1 for x in range(0, 10_000, 7) if t0 <= x < t1)

    rec = Recorder()
    s = Scheduler([Task("a", 1, 50, cost=10), Task("b", 2, 30, cost=4)], interrupts=[rec])
    s.run_until(3000)
    t0s = [c[0] for c in rec.calls]
    assert t0s == sorted(t0s) and len(rec.calls) > 100


def test_idle_interrupts_count_toward_utilisation_not_jobs():
    tick = PeriodicInterrupt("systick", period=100, cost=10)
    s = Scheduler([Task("x", 1, 1000, cost=50)], interrupts=[tick])
    s.run_until(1000)
    st_tick = s.interrupt_stats()[0]
    assert (st_tick.in_jobs, st_tick.while_idle) == (1, 9)
    assert s.stats["x"].worst_response == 60
    u = s.utilisation()
    assert u.interrupt_cycles == {"systick": 100} and u.task_cycles == {"x": 50}
    assert u.total == pytest.approx(0.15) and u.of("systick") == pytest.approx(0.1)


def test_saturating_interrupts_raise(monkeypatch):
    monkeypatch.setattr("rtos.interrupts.MAX_FIXED_POINT_STEPS", 1000)
    s = Scheduler([Task("x", 1, 100, cost=5)], interrupts=[PeriodicInterrupt("storm", 2, 2)])
    with pytest.raises(RuntimeError, match="saturate"):
        s.run_until(10)


def test_interrupt_source_validation():
    with pytest.raises(ValueError, match="period"):
        PeriodicInterrupt("p", 0, 1)
    with pytest.raises(ValueError, match="cost"):
        TimestampedInterrupt("t", -1, [])
    with pytest.raises(ValueError, match="InterruptSource"):
        Scheduler([Task("x", 1, 10, cost=1)], interrupts=[object()])  # type: ignore[list-item]


def test_counting_source_subclass_and_duck_typed_source_give_the_same_finish():
    from rtos.interrupts import CountingSource, bind_sources

    class Every30(CountingSource):  # an interpreted subclass: counted through the direct call
        def __init__(self) -> None:
            self.name, self.cost_cycles = "every30", 10

        def count_in(self, t0: int, t1: int) -> int:
            return max(0, -(-t1 // 30) - -(-t0 // 30))

    class Duck:  # only the InterruptSource shape: counted through its bound count_in
        name, cost_cycles = "duck", 10

        def count_in(self, t0: int, t1: int) -> int:
            return Every30().count_in(t0, t1)

    duck = Duck()
    assert isinstance(bind_sources([Every30()])[0].src, Every30) and bind_sources([duck])[0].src is not duck
    counts_native, counts_duck = [0], [0]
    assert solve_finish(0, 100, [Every30()], counts_native) == solve_finish(0, 100, [Duck()], counts_duck) == 150
    assert counts_native == counts_duck == [5]
    with pytest.raises(NotImplementedError, match="count_in"):
        CountingSource().count_in(0, 1)

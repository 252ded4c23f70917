"""Critical-instant release patterns, and emulation of a task set under them to observe worst cases."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

from rtos.analysis import constant_cost, response_time_bounds
from rtos.interrupts import PeriodicInterrupt
from rtos.scheduler import Scheduler
from rtos.task import Fault, OverrunPolicy, Task, by_priority


@dataclass(frozen=True)
class CriticalInstant:
    """Offsets (cycles) that release ``target`` with its worst case; ``blocker`` is released a tick earlier.

    Every task of higher priority than ``target`` (and every other task) is released with it, one tick
    after its longest lower-priority blocker; periodic interrupts fire first together with the blocker.
    """

    target: str | None
    blocker: str | None
    task_offsets: dict[str, int]
    interrupt_offsets: dict[str, int]

    def apply(
        self, tasks: Sequence[Task], interrupts: Sequence[PeriodicInterrupt] = ()
    ) -> tuple[list[Task], list[PeriodicInterrupt]]:
        """Return copies of ``tasks`` and ``interrupts`` with this pattern's offsets."""
        new_tasks = [dataclasses.replace(t, offset=self.task_offsets.get(t.name, t.offset)) for t in tasks]
        new_irqs = [
            PeriodicInterrupt(s.name, s.period, s.cost_cycles, self.interrupt_offsets.get(s.name, s.offset))
            for s in interrupts
        ]
        return new_tasks, new_irqs


def synchronous(tasks: Sequence[Task], interrupts: Sequence[PeriodicInterrupt] = ()) -> CriticalInstant:
    """The pattern that releases everything at cycle 0."""
    return CriticalInstant(None, None, {t.name: 0 for t in tasks}, {s.name: 0 for s in interrupts})


def critical_instant(
    tasks: Sequence[Task], target: str, interrupts: Sequence[PeriodicInterrupt] = ()
) -> CriticalInstant:
    """The release pattern that produces ``target``'s analysed worst case (exactly, without jitter).

    >>> ts = [Task("A", 1, 2500, cost=1000), Task("B", 2, 3500, cost=1000), Task("C", 3, 3500, cost=1000)]
    >>> critical_instant(ts, "B").task_offsets
    {'A': 1, 'B': 1, 'C': 0}
    """
    ordered = by_priority(tasks)
    names = [t.name for t in ordered]
    if target not in names:
        raise ValueError(f"no task named {target!r}; tasks are {names}")
    lower = ordered[names.index(target) + 1:]
    blocker = max(lower, key=constant_cost, default=None)
    if blocker is None or constant_cost(blocker) == 0:
        pattern = synchronous(ordered, interrupts)
        return dataclasses.replace(pattern, target=target)
    offsets = {t.name: 1 for t in ordered}
    offsets[blocker.name] = 0
    return CriticalInstant(target, blocker.name, offsets, {s.name: 0 for s in interrupts})


def release_patterns(
    tasks: Sequence[Task], interrupts: Sequence[PeriodicInterrupt] = ()
) -> list[CriticalInstant]:
    """The synchronous pattern followed by each task's critical instant (duplicates removed)."""
    out = [synchronous(tasks, interrupts)]
    seen = {tuple(sorted(out[0].task_offsets.items()))}
    for t in by_priority(tasks):
        p = critical_instant(tasks, t.name, interrupts)
        key = tuple(sorted(p.task_offsets.items()))
        if key not in seen:
            seen.add(key)
            out.append(p)
    return out


@dataclass(frozen=True)
class Observation:
    """Worst response per task (cycles) seen over the emulated patterns, and the horizon used."""

    worst: dict[str, int | None]
    horizon_cycles: int
    hyperperiod_cycles: int
    capped: bool
    patterns: int


def emulation_horizon(
    tasks: Sequence[Task], interrupts: Sequence[PeriodicInterrupt] = (), max_jobs: int = 200_000
) -> tuple[int, int, bool]:
    """Return (horizon, hyperperiod, capped): one hyperperiod plus the longest deadline, busy period and cost.

    The horizon is cut so that about ``max_jobs`` jobs are run per pattern; ``capped`` says if it was.
    """
    hyper = math.lcm(*(t.period for t in tasks), *(s.period for s in interrupts))
    busy = max((b.busy_period or 0 for b in response_time_bounds(tasks, interrupts, blocking="discrete")),
               default=0)
    horizon = 2 + hyper + max(max(t.relative_deadline + t.jitter for t in tasks), busy) + sum(
        constant_cost(t) for t in tasks)
    rate = sum(1 / t.period for t in tasks)
    if horizon <= max_jobs / rate:  # not horizon * rate: the hyperperiod of coprime periods overflows a float
        return horizon, hyper, False
    return max(1, int(max_jobs / rate)), hyper, True


def observe_worst(
    tasks: Sequence[Task],
    interrupts: Sequence[PeriodicInterrupt] = (),
    *,
    max_jobs: int = 200_000,
    seed: int = 0,
    overrun: OverrunPolicy | None = OverrunPolicy.QUEUE,
) -> Observation:
    """Emulate the task set (bodies removed) under every release pattern; keep each task's worst response.

    By default every task queues its releases (``OverrunPolicy.QUEUE``), as the analysis assumes;
    pass ``overrun=None`` to keep each task's own policy.
    """
    bare = [dataclasses.replace(t, body=None, cost=constant_cost(t), overrun=overrun or t.overrun)
            for t in tasks]
    horizon, hyper, capped = emulation_horizon(bare, interrupts, max_jobs)
    patterns = release_patterns(bare, interrupts)
    worst: dict[str, int | None] = {t.name: None for t in bare}

    def ignore(fault: Fault) -> None:
        """FAULT-policy overruns are counted by the scheduler; the emulation carries on."""

    for pattern in patterns:
        ts, irqs = pattern.apply(bare, interrupts)
        sched = Scheduler(ts, interrupts=irqs, on_fault=ignore, seed=seed)
        sched.run_until(horizon)
        for name, st in sched.stats.items():
            w = st.worst_response
            if w is not None and (worst[name] is None or w > worst[name]):  # type: ignore[operator]
                worst[name] = w
    return Observation(worst, horizon, hyper, capped, len(patterns))

"""Worst-case response-time analysis for cooperative (non-preemptive) fixed-priority scheduling.

Follows R. I. Davis, A. Burns, R. J. Bril and J. J. Lukkien (2007), "Controller Area Network (CAN)
schedulability analysis: Refuted, revisited and revised", Real-Time Systems 35(3):239-272, with time
in integer ticks (one tick = one cycle, tau = 1):

    B_i    = max_{k in lp(i)} C_k                       ("davis", as published)
           = max_{k in lp(i)} C_k - 1                   ("discrete": a blocker must start a tick early)
    t_i    = B_i + sum_{k in hep(i)} ceil((t_i + J_k) / T_k) C_k          level-i busy period
    Q_i    = ceil((t_i + J_i) / T_i)                                      instances to check
    w_i(q) = B_i + q C_i + sum_{k in hp(i)} ceil((w_i(q) + J_k + 1) / T_k) C_k
    R_i(q) = J_i + w_i(q) - q T_i + C_i,     R_i = max_q R_i(q)

Interrupt sources are the highest priority and preempt jobs: each one, with minimum inter-arrival T_j
and cost c_j, adds ceil((x + beta) / T_j) c_j to the busy period, to w and to the job's own execution
(beta = 1 when a lower-priority blocker exists: its interrupts start with it, one tick before the
release; else 0). The "discrete" variant is exact for this package's scheduler: the critical-instant
release pattern of rtos.critical reaches it. The published "davis" blocking term is one tick more
pessimistic in B_i (the continuous-time supremum), which the default keeps so that published figures
come out as published. ``first_instance_only=True`` gives the flawed pre-2007 analysis (q = 0 only).

>>> from rtos.task import Task
>>> ts = [Task("A", 1, 2500, cost=1000), Task("B", 2, 3500, 3250, cost=1000),
...       Task("C", 3, 3500, 3250, cost=1000)]
>>> [b.bound for b in response_time_bounds(ts)]
[2000, 3000, 3500]
>>> [b.bound for b in response_time_bounds(ts, first_instance_only=True)]
[2000, 3000, 3000]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import Literal, Protocol

from rtos.task import Task, by_priority

BlockingModel = Literal["davis", "discrete"]


class SporadicInterrupt(Protocol):
    """An interrupt source as the analysis sees it: minimum inter-arrival ``period`` and a cost."""

    name: str
    period: int
    cost_cycles: int


@dataclass(frozen=True)
class TaskBound:
    """Analysed worst case of one task, in cycles; ``bound`` is None when the busy period never ends."""

    name: str
    priority: int
    period: int
    deadline: int
    cost: int
    jitter: int
    blocking: int
    busy_period: int | None
    instances: int
    bound: int | None
    worst_instance: int | None

    @property
    def schedulable(self) -> bool:
        """True when the bound exists and does not exceed the deadline."""
        return self.bound is not None and self.bound <= self.deadline


# (period, cost, added to x inside the ceiling)
_Term = tuple[int, int, int]


def _least_fixed_point(base: int, terms: Sequence[_Term], x: int, limit: int) -> int | None:
    """Least x >= start with x = base + sum ceil((x + add) / T) C, or None once x exceeds ``limit``."""
    while True:
        nxt = base
        for period, cost, add in terms:
            nxt += -(-(x + add) // period) * cost
        if nxt == x:
            return x
        if nxt > limit:
            return None
        x = nxt


def constant_cost(task: Task) -> int:
    """The task's worst-case cost in cycles; the analysis needs a constant."""
    if callable(task.cost):
        raise ValueError(f"task {task.name!r}: analysis needs a constant worst-case cost, not a callable")
    return int(task.cost)


def _search_limit(utilisation: Fraction, base: int, terms: Sequence[_Term]) -> int:
    """An upper bound on any busy period (valid when utilisation < 1), or a generous cap when it is 1."""
    slack = base + sum(c * (1 + Fraction(add, p)) for p, c, add in terms)
    if utilisation < 1:
        return math.ceil(slack / (1 - utilisation)) + 1
    hyper = math.lcm(*(p for p, _, _ in terms)) if terms else 1
    return 4 * (hyper + math.ceil(slack)) + 1


def response_time_bounds(
    tasks: Sequence[Task],
    interrupts: Sequence[SporadicInterrupt] = (),
    *,
    blocking: BlockingModel = "davis",
    first_instance_only: bool = False,
) -> list[TaskBound]:
    """Analyse every task (highest priority first) under cooperative fixed-priority scheduling."""
    if blocking not in ("davis", "discrete"):
        raise ValueError(f"blocking must be 'davis' or 'discrete', got {blocking!r}")
    ordered = by_priority(tasks)
    costs = [constant_cost(t) for t in ordered]
    irq_terms: list[tuple[int, int]] = []
    for src in interrupts:
        period = getattr(src, "period", None)
        if not isinstance(period, int) or period <= 0:
            raise ValueError(f"interrupt {src.name!r}: analysis needs a minimum inter-arrival period >= 1, "
                             f"got {period!r}")
        irq_terms.append((period, src.cost_cycles))
    irq_util = sum((Fraction(c, p) for p, c in irq_terms), Fraction(0))
    out = []
    for i, task in enumerate(ordered):
        c_i, t_i, j_i = costs[i], task.period, task.jitter
        lower = costs[i + 1:]
        longest = max(lower, default=0)
        b = max(longest - 1, 0) if blocking == "discrete" else longest
        beta = 1 if longest > 0 else 0
        irq = [(p, c, beta) for p, c in irq_terms]
        hep: list[_Term] = [(t.period, costs[k], t.jitter) for k, t in enumerate(ordered[: i + 1])]
        hp: list[_Term] = [(t.period, costs[k], t.jitter + 1) for k, t in enumerate(ordered[:i])]
        util = irq_util + sum((Fraction(c, p) for p, c, _ in hep), Fraction(0))
        limit = _search_limit(util, b, hep + irq)
        busy = None if util > 1 else _least_fixed_point(b, hep + irq, b + sum(c for _, c, _ in hep), limit)
        if busy is None:
            out.append(TaskBound(task.name, task.priority, t_i, task.relative_deadline, c_i, j_i, b, None,
                                 0, None, None))
            continue
        instances = 1 if first_instance_only else max(1, -(-(busy + j_i) // t_i))
        bound: int | None = None
        worst_q: int | None = None
        w = b
        for q in range(instances):
            w_q = _least_fixed_point(b + q * c_i, hp + irq, w + (c_i if q else 0), limit)
            if w_q is None:
                bound = worst_q = None
                break
            w = w_q
            irq_before = sum(-(-(w + beta) // p) * c for p, c in irq_terms)
            finish = _least_fixed_point(w + c_i - irq_before, irq, w + c_i, limit)
            if finish is None:
                bound = worst_q = None
                break
            r = j_i + finish - q * t_i
            if bound is None or r > bound:
                bound, worst_q = r, q
        out.append(TaskBound(task.name, task.priority, t_i, task.relative_deadline, c_i, j_i, b, busy,
                             instances, bound, worst_q))
    return out

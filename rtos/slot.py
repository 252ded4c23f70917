"""A task as the scheduler's dispatch loop sees it (rtos/scheduler.py): its constants and release state in native
fields, compiled with the scheduler."""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from rtos.stats import TaskStats
from rtos.task import Body, Job, OverrunPolicy, Task

_QUEUE: Final = OverrunPolicy.QUEUE


class Slot:
    """One task as the dispatch loop sees it: its constants and release state in native fields.

    A task is either waiting for its next ready time (``waiting``) or pending in the scheduler's
    ready bitmask (or running).
    """

    def __init__(self, rank: int, task: Task, stats: TaskStats, ready: int) -> None:
        """Take the task's (frozen) parameters; the first release is at its offset, ready at ``ready``."""
        self.rank = rank
        self.task = task
        self.name = task.name
        self.period = task.period
        self.offset = task.offset
        self.deadline = task.relative_deadline
        self.jitter = task.jitter
        cost = task.cost
        self.cost_model: Callable[[object], object] | None = cost if callable(cost) else None
        self.cost = 0 if callable(cost) else cost
        self.body: Body | None = task.body
        self.plain = task.overrun is not _QUEUE  # a policy that drops releases
        self.job = Job(task)
        self.stats = stats
        self.nrel = task.offset  # nominal release of the pending (or next) job
        self.nnext = task.offset + task.period  # the release after it
        self.ready = ready  # nrel after jitter
        self.waiting = True
        # what delayed the pending job: the blocking slot's rank (-1: nothing), its job's release, the delay;
        # a Blocker is built from them only when the job sets a new worst response
        self.blocked_by = -1
        self.blocked_release = 0
        self.blocked_cycles = 0
        # the trace's id of the task (-1: its jobs are not recorded), its codes' base (id * CODES) and the
        # interference and cost - nominal cost of its last job recorded (Trace.carried), read at each run's start
        self.trace_id = -1
        self.trace_code = 0
        self.carried_preempted = 0
        self.carried_dcost = 0

    def index_of(self, release: int) -> int:
        """Release index k of the nominal release ``release`` (= offset + k * period)."""
        return (release - self.offset) // self.period

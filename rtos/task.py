"""Tasks, the jobs they release, and what happens when a job overruns its next release."""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from rtos.job import Job as Job  # re-exported: the job record is compiled with the scheduler

CostModel = int | Callable[[Any], int]
Body = Callable[["Job"], object]


class OverrunPolicy(enum.Enum):
    """What a task does with a release that comes while its previous job is still pending or running."""

    SKIP = "skip"  # drop the release and count it
    LATE = "late"  # keep at most one pending release and run it late; drop (and count) the others
    FAULT = "fault"  # drop the release and report a Fault to the scheduler's on_fault handler
    QUEUE = "queue"  # keep every release (a backlog counter): late jobs run back to back, as the analysis assumes


@dataclass(frozen=True, eq=False)
class Task:
    """A periodic task; every time is in CPU cycles and a SMALLER priority number means HIGHER priority.

    ``cost`` is a constant number of cycles or a callable that receives the value returned by ``body``
    (the work the job actually did, e.g. bytes handled) and returns the job's cycles.
    ``jitter`` is the largest release jitter: each job becomes ready up to ``jitter`` cycles after its
    nominal release ``offset + k * period`` (drawn from the scheduler's seeded generator).

    >>> Task("ctrl", priority=1, period=1000, cost=200).deadline
    1000
    """

    name: str
    priority: int
    period: int
    deadline: int | None = None
    offset: int = 0
    cost: CostModel = 0
    body: Body | None = None
    overrun: OverrunPolicy = OverrunPolicy.SKIP
    jitter: int = 0

    def __post_init__(self) -> None:
        """Validate every field and fill the default deadline (= period)."""
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"task name must be a non-empty string, got {self.name!r}")
        if isinstance(self.priority, bool) or not isinstance(self.priority, int):
            raise ValueError(f"task {self.name!r}: priority must be an int, got {self.priority!r}")
        _check_int(self.name, "period", self.period, minimum=1)
        if self.deadline is None:
            object.__setattr__(self, "deadline", self.period)
        _check_int(self.name, "deadline", self.deadline, minimum=1)
        _check_int(self.name, "offset", self.offset, minimum=0)
        if not callable(self.cost):
            _check_int(self.name, "cost", self.cost, minimum=0)
        _check_int(self.name, "jitter", self.jitter, minimum=0)
        if self.jitter > self.period:
            raise ValueError(
                f"task {self.name!r}: jitter {self.jitter} must be in [0, period={self.period}] cycles"
            )
        if not isinstance(self.overrun, OverrunPolicy):
            raise ValueError(f"task {self.name!r}: overrun must be an OverrunPolicy, got {self.overrun!r}")
        if self.body is not None and not callable(self.body):
            raise ValueError(f"task {self.name!r}: body must be callable or None, got {self.body!r}")

    @property
    def relative_deadline(self) -> int:
        """The deadline in cycles after each nominal release (never None after construction)."""
        return int(self.deadline)  # type: ignore[arg-type]


def _check_int(task: str, field: str, value: object, minimum: int) -> None:
    """Raise ValueError unless ``value`` is an int >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"task {task!r}: {field} must be an int >= {minimum} cycles, got {value!r}")


def by_priority(tasks: Iterable[Task]) -> list[Task]:
    """Return the tasks sorted from highest to lowest priority, checking names and priorities are unique."""
    ordered = sorted(tasks, key=lambda t: t.priority)
    seen_names: set[str] = set()
    for a, b in zip(ordered, ordered[1:], strict=False):
        if a.priority == b.priority:
            raise ValueError(
                f"priority {a.priority} is used by both {a.name!r} and {b.name!r}; priorities must be unique"
            )
    for t in ordered:
        if t.name in seen_names:
            raise ValueError(f"task name {t.name!r} is used twice; names must be unique")
        seen_names.add(t.name)
    return ordered


@dataclass(frozen=True)
class Fault:
    """A FAULT-policy overrun: job ``job`` of ``task`` was still pending or running at release ``time``.

    ``missed`` releases were dropped; the scheduler reports it when the overrunning job finishes.
    """

    time: int
    task: str
    job: int
    missed: int


class OverrunError(RuntimeError):
    """Raised for a FAULT-policy overrun when the scheduler has no ``on_fault`` handler."""

    def __init__(self, fault: Fault) -> None:
        """Wrap the fault record."""
        super().__init__(
            f"task {fault.task!r} job {fault.job} overran: {fault.missed} release(s) from cycle "
            f"{fault.time} missed and no on_fault handler is set"
        )
        self.fault = fault

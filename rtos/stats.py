"""Always-on statistics with bounded memory: per task, per interrupt source, and CPU utilisation."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

_NONE_YET: Final = 1 << 80  # larger than any response time


@dataclass(frozen=True)
class Blocker:
    """The lower-priority job that was running when a job was released, and how long it delayed it."""

    task: str
    job: int
    cycles: int


class TaskStats:
    """Running statistics of one task (response = finish - nominal release; all times in cycles).

    ``start_jitter`` is max - min of (start - release) and ``finish_jitter`` max - min of
    (finish - release) = worst - best response. A deadline miss is a job whose response exceeds the
    relative deadline; skipped releases (overrun policy) are counted apart and are not jobs.
    ``worst_blocker`` tells which lower-priority job blocked the worst-case job, and for how long.
    The scheduler updates the plain fields inline; read the properties.
    """

    __slots__ = (
        "name", "jobs", "response_sum", "best", "worst", "worst_job", "worst_blocker",
        "delay_min", "delay_max", "deadline_misses", "miss_streak", "longest_miss_streak",
        "skipped", "faults", "busy_cycles",
    )

    def __init__(self, name: str) -> None:
        """Start empty statistics for task ``name``."""
        self.name = name
        self.jobs = 0
        self.response_sum = 0
        self.best = _NONE_YET
        self.worst = -1
        self.worst_job = -1
        self.worst_blocker: Blocker | None = None
        self.delay_min = _NONE_YET
        self.delay_max = -1
        self.deadline_misses = 0
        self.miss_streak = 0
        self.longest_miss_streak = 0
        self.skipped = 0
        self.faults = 0
        self.busy_cycles = 0

    @property
    def best_response(self) -> int | None:
        """Shortest response time in cycles, None before the first job."""
        return self.best if self.jobs else None

    @property
    def worst_response(self) -> int | None:
        """Longest response time in cycles, None before the first job."""
        return self.worst if self.jobs else None

    @property
    def worst_job_index(self) -> int | None:
        """Release index k (release = offset + k * period) of the worst-case job, None before any job."""
        return self.worst_job if self.jobs else None

    @property
    def mean_response(self) -> float | None:
        """Mean response time in cycles, None before the first job."""
        return self.response_sum / self.jobs if self.jobs else None

    @property
    def start_jitter(self) -> int:
        """Max - min of (start - release) over all jobs, in cycles."""
        return self.delay_max - self.delay_min if self.jobs else 0

    @property
    def finish_jitter(self) -> int:
        """Max - min of (finish - release) over all jobs, in cycles."""
        return self.worst - self.best if self.jobs else 0

    def as_dict(self) -> dict[str, object]:
        """Return the statistics as plain values (for JSON or reports)."""
        b = self.worst_blocker
        return {
            "name": self.name, "jobs": self.jobs, "best_response": self.best_response,
            "mean_response": self.mean_response, "worst_response": self.worst_response,
            "worst_job": self.worst_job_index,
            "worst_blocker": None if b is None else {"task": b.task, "job": b.job, "cycles": b.cycles},
            "start_jitter": self.start_jitter, "finish_jitter": self.finish_jitter,
            "deadline_misses": self.deadline_misses, "longest_miss_streak": self.longest_miss_streak,
            "skipped": self.skipped, "faults": self.faults, "busy_cycles": self.busy_cycles,
        }

    def __repr__(self) -> str:
        """Summarise the statistics."""
        return (f"TaskStats({self.name!r}, jobs={self.jobs}, worst={self.worst_response}, "
                f"misses={self.deadline_misses}, skipped={self.skipped})")


class DeadlineHealth:
    """What a firmware asks its kernel: (total deadline misses, longest current miss streak) of some tasks.

    >>> a, b = TaskStats("a"), TaskStats("b")
    >>> a.deadline_misses, b.deadline_misses, b.miss_streak = 1, 3, 2
    >>> DeadlineHealth([a, b])()
    (4, 2)
    """

    def __init__(self, stats: list[TaskStats]) -> None:
        """Watch these tasks' statistics (live objects: each call reads them anew)."""
        self._stats = list(stats)

    def __call__(self) -> tuple[int, int]:
        """(sum of deadline misses, longest current streak of consecutive misses)."""
        misses = streak = 0
        for s in self._stats:
            misses += s.deadline_misses
            if s.miss_streak > streak:
                streak = s.miss_streak
        return misses, streak


class InterruptStats:
    """Firings of one interrupt source, split by whether a job or the idle CPU absorbed them."""

    __slots__ = ("name", "cost_cycles", "in_jobs", "while_idle")

    def __init__(self, name: str, cost_cycles: int) -> None:
        """Start counting for source ``name``."""
        self.name = name
        self.cost_cycles = cost_cycles
        self.in_jobs = 0
        self.while_idle = 0

    @property
    def count(self) -> int:
        """Total firings."""
        return self.in_jobs + self.while_idle

    @property
    def busy_cycles(self) -> int:
        """Total cycles spent in this source's service routine."""
        return self.count * self.cost_cycles


@dataclass(frozen=True)
class Utilisation:
    """CPU utilisation over ``elapsed_cycles``: busy cycles per task and per interrupt source."""

    elapsed_cycles: int
    task_cycles: dict[str, int]
    interrupt_cycles: dict[str, int]

    @property
    def busy_cycles(self) -> int:
        """Cycles spent in jobs and interrupt service routines."""
        return sum(self.task_cycles.values()) + sum(self.interrupt_cycles.values())

    @property
    def total(self) -> float:
        """Fraction of the elapsed cycles the CPU was busy (0 when nothing has elapsed)."""
        return self.busy_cycles / self.elapsed_cycles if self.elapsed_cycles else 0.0

    def of(self, name: str) -> float:
        """Fraction of the elapsed cycles spent in task or interrupt ``name``."""
        cycles = self.task_cycles.get(name, self.interrupt_cycles.get(name))
        if cycles is None:
            raise ValueError(f"no task or interrupt named {name!r}")
        return cycles / self.elapsed_cycles if self.elapsed_cycles else 0.0

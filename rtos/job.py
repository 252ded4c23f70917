"""The job record a task body receives: a compiled class, so the scheduler fills it with native writes.

``rtos.task`` re-exports ``Job``; the task classes stay interpreted (docs/compiled.md, "Values checked as given").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rtos.task import Task


class Job:
    """One job of a task as its body sees it; the scheduler reuses one Job per task, so copy what you keep.

    ``release`` is the nominal release (cycles), ``ready`` the release after jitter, ``start`` the cycle
    the body runs at (also ``scheduler.now`` during the body), ``deadline`` the absolute deadline.
    """

    __slots__ = ("task", "index", "release", "ready", "start")

    def __init__(self, task: Task) -> None:
        """Create the job record of ``task`` (filled in by the scheduler before each call)."""
        self.task = task
        self.index = 0
        self.release = 0
        self.ready = 0
        self.start = 0

    @property
    def deadline(self) -> int:
        """Absolute deadline of this job in cycles."""
        return self.release + self.task.relative_deadline

    def __repr__(self) -> str:
        """Show which job this is."""
        return f"Job({self.task.name!r}, index={self.index}, release={self.release}, start={self.start})"

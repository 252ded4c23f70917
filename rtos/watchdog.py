"""An independent hardware watchdog (IWDG model): kick it in time or it resets at its deadline."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Protocol


class _TimeSource(Protocol):
    """Anything with a ``now`` in cycles (the scheduler)."""

    @property
    def now(self) -> int:
        """Current cycle."""
        ...


class Watchdog:
    """Counts down ``timeout_cycles`` from the last kick; at zero it fires ``on_reset(cycle)`` and re-arms.

    A kick at cycle t moves the deadline to ``t + timeout_cycles``; a kick exactly at the deadline is too
    late (the reset happens at that instant first). Attach it with ``Scheduler.add_watchdog``; job bodies
    then call ``kick()`` and the scheduler's ``now`` is used.

    >>> wd = Watchdog(1000, on_reset=lambda t: None)
    >>> wd.arm(0); wd.kick(400); wd.due
    1400
    """

    def __init__(self, timeout_cycles: object, on_reset: Callable[[int], None] | None = None) -> None:
        """Create a disarmed watchdog; ``on_reset`` receives the cycle of each reset.

        ``timeout_cycles`` is taken as ``object`` (docs/compiled.md, "Values checked as given").
        """
        if isinstance(timeout_cycles, bool) or not isinstance(timeout_cycles, int) or timeout_cycles <= 0:
            raise ValueError(f"watchdog timeout must be an int >= 1 cycles, got {timeout_cycles!r}")
        self.timeout_cycles: int = timeout_cycles
        self.on_reset = on_reset
        self.due: int | None = None
        self.resets = 0
        self.kicks = 0
        self._time: _TimeSource | None = None
        self.kick_log: deque[int] | None = None  # set by Scheduler.add_watchdog: a trace's (Trace.kick_log)

    def bind(self, time_source: _TimeSource) -> None:
        """Use ``time_source.now`` for kicks without an explicit time, and arm at its present."""
        self._time = time_source
        self.arm(time_source.now)

    def arm(self, now: int) -> None:
        """Start counting down from cycle ``now``."""
        self.due = now + self.timeout_cycles

    def kick(self, now: int | None = None) -> None:
        """Reload the counter at cycle ``now`` (default: the bound scheduler's ``now``)."""
        if now is None:
            if self._time is None:
                raise RuntimeError("watchdog is not attached to a scheduler: pass now= or add_watchdog() it")
            now = self._time.now
        if self.due is None:
            raise RuntimeError("watchdog is not armed: call arm(now) or attach it to a scheduler")
        if now >= self.due:
            return  # too late: the reset at self.due is still pending and will fire first
        self.kicks += 1
        self.due = now + self.timeout_cycles
        if self.kick_log is not None:
            self.kick_log.append(now)

    def expire(self) -> int:
        """Fire the pending reset at ``due``: count it, call ``on_reset``, re-arm; return the reset cycle."""
        if self.due is None:
            raise RuntimeError("watchdog is not armed")
        t = self.due
        self.resets += 1
        self.due = t + self.timeout_cycles
        if self.on_reset is not None:
            self.on_reset(t)
        return t

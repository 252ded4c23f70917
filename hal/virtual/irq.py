"""Interrupt sources of the virtual MCU, in the shape the RTOS scheduler counts as interference.

The RTOS (which imports nothing of ours) asks each source ``count_in(t0, t1)``: how many times it
fires in the half-open cycle window [t0, t1), with non-decreasing t0 (the shape
``rtos.interrupts.InterruptSource``). This module holds a small base class that validates the windows,
on the RTOS's ``CountingSource`` so that the compiled solver calls ``count_in`` directly (the one
import of hal.virtual from rtos), and the source of the virtual UARTs.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Final

from hal.virtual.checks import check_int
from hal.virtual.events import Horizon
from rtos.interrupts import CountingSource

__all__ = ["EventTimesInterrupt", "InterruptSourceBase"]

_COMPACT_AT: Final = 4096


class InterruptSourceBase(CountingSource):
    """Shared checks for interrupt sources: a name, a cost and monotone, well-formed windows."""

    def __init__(self, name: str, cost_cycles: object) -> None:
        """Validate and keep the name and the per-firing cost in cycles (an int >= 0)."""
        if not name:
            raise ValueError("an interrupt source needs a non-empty name")
        self.name = name
        self.cost_cycles = check_int("cost_cycles", cost_cycles, 0)
        self._last_t0 = 0

    def _check_window(self, t0: int, t1: int) -> None:
        if t0 < 0 or t1 < t0:
            raise ValueError(f"window [{t0}, {t1}) invalid: need 0 <= t0 <= t1")
        if t0 < self._last_t0:
            raise ValueError(f"window start {t0} goes back before {self._last_t0}: t0 must not decrease")
        self._last_t0 = t0

    def __repr__(self) -> str:
        """Name and cost."""
        return f"{type(self).__name__}(name={self.name!r}, cost_cycles={self.cost_cycles})"


class EventTimesInterrupt(InterruptSourceBase):
    """Fires once at each recorded event time (e.g. each received byte's stop-bit end).

    Event times are pushed in non-decreasing order by the peripheral; ``before_count`` (if given)
    is called with t1 first so that the peripheral can bring its world up to t1 (only when t1 is
    later than every t1 before: the world has already been brought up to those). ``horizon``, if
    set, is a :class:`~hal.virtual.events.Horizon` whose ``next_event`` (int) promises that no event
    time not yet recorded is earlier than it: windows ending at or before it need no ``before_count``.
    """

    def __init__(
        self, name: str, cost_cycles: object, before_count: Callable[[int], None] | None = None
    ) -> None:
        """Start with no recorded events."""
        super().__init__(name, cost_cycles)
        self._times: list[int] = []
        self._lo = 0
        self._before_count = before_count
        self._advanced_to = -1  # the largest t1 handed to before_count so far
        self.horizon: Horizon | None = None  # see the class docstring

    def add_times(self, times: Iterable[int]) -> None:
        """Record event times (non-decreasing, and not earlier than those already recorded)."""
        self._times.extend(times)

    def count_in(self, t0: int, t1: int) -> int:
        """Number of recorded events with t0 <= time < t1."""
        if t0 < self._last_t0 or t1 < t0 or t0 < 0:
            self._check_window(t0, t1)  # raises
        self._last_t0 = t0
        if t1 > self._advanced_to:  # the peripheral has already caught up to any earlier t1
            horizon = self.horizon
            if horizon is None or t1 > horizon.next_event:  # else every event before t1 is recorded
                self._advanced_to = t1
                if self._before_count is not None:
                    self._before_count(t1)
        times = self._times
        n = len(times)
        lo = self._lo  # t0 never decreases: the events before self._lo are past for good
        while lo < n and times[lo] < t0:
            lo += 1
        if lo == n:  # every recorded event is past: forget them all
            if n:
                times.clear()
            self._lo = 0
            return 0
        if lo >= _COMPACT_AT:
            del times[:lo]
            n -= lo
            lo = 0
        self._lo = lo
        hi = lo
        while hi < n and times[hi] < t1:  # a window holds few events: a scan beats a bisect call
            hi += 1
        return hi - lo

    def fired_at(self, t0: int, t1: int) -> tuple[int, ...]:
        """The recorded event times in [t0, t1), right after ``count_in(t0, t1)`` (for the trace)."""
        times, k, out = self._times, self._lo, []
        n = len(times)
        while k < n and times[k] < t1:
            if times[k] >= t0:
                out.append(times[k])
            k += 1
        return tuple(out)

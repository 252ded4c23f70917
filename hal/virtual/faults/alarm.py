"""A world device that calls a function at given ticks: how injectors act at their onset and end on the bench."""

from __future__ import annotations

import heapq
from collections.abc import Callable
from typing import Any

from hal.virtual.events import NEVER, EventDevice

__all__ = ["Alarm", "at"]


class Alarm(EventDevice):
    """Runs each (tick, fn) once, in time order, when the world reaches the tick."""

    def __init__(self, world: Any) -> None:
        """An alarm on world with nothing scheduled."""
        super().__init__()
        self.world = world
        self._due: list[tuple[int, int, Callable[[int], None]]] = []
        world.add(self)

    def add(self, t: int, fn: Callable[[int], None]) -> None:
        """Call fn(t) when the world reaches tick t (a tick already passed: at the next advance)."""
        heapq.heappush(self._due, (max(t, self.world.now + 1), len(self._due), fn))
        self.next_event = self._due[0][0]

    def run_event(self) -> None:
        """Call what is due at next_event."""
        t = self.next_event
        while self._due and self._due[0][0] <= t:
            heapq.heappop(self._due)[2](t)
        self.next_event = self._due[0][0] if self._due else NEVER


def at(rig: Any, t_s: float, fn: Callable[[int], None]) -> None:
    """Call fn(tick) on the rig's world at t_s (no call for an infinite time)."""
    if t_s == float("inf"):
        return
    alarm = rig.taps.get("alarm")
    if alarm is None:
        alarm = rig.taps["alarm"] = Alarm(rig.bench.world)
    alarm.add(rig.bench.world.ticks(t_s), fn)

"""Virtual pins and the virtual watchdog peripheral: e-stop input, status LED, IWDG forwarding."""

from __future__ import annotations

from bisect import insort
from collections.abc import Callable

from hal.interfaces import DigitalIn, DigitalOut, Watchdog

__all__ = ["VirtualDigitalIn", "VirtualDigitalOut", "VirtualWatchdog"]


class VirtualDigitalIn(DigitalIn):
    """An input pin whose level follows a schedule of (cycle, level) changes, applied lazily at reads.

    >>> t = [0]
    >>> pin = VirtualDigitalIn(lambda: t[0])
    >>> pin.set_at(100, True)
    >>> pin.read()
    False
    >>> t[0] = 100
    >>> pin.read()
    True
    """

    def __init__(self, now: Callable[[], int], initial: bool = False) -> None:
        """Start at the initial level with an empty schedule."""
        self._now = now
        self._level = bool(initial)
        self._schedule: list[tuple[int, int, bool]] = []
        self._seq = 0
        self._applied_until = -1

    def set_at(self, t_cycles: int, level: bool) -> None:
        """Schedule the pin to take level at t_cycles (not before a time already read)."""
        if t_cycles < 0 or t_cycles < self._applied_until:
            raise ValueError(
                f"t_cycles {t_cycles} out of range: must be >= 0 and not before cycle "
                f"{self._applied_until}, already read"
            )
        insort(self._schedule, (t_cycles, self._seq, bool(level)))
        self._seq += 1

    def set(self, level: bool) -> None:
        """Change the level from now on (applied at the next read)."""
        self.set_at(self._now(), level)

    def read(self) -> bool:
        """The level now."""
        t = self._now()
        schedule = self._schedule
        i = 0
        while i < len(schedule) and schedule[i][0] <= t:
            self._level = schedule[i][2]
            i += 1
        if i:
            del schedule[:i]
        self._applied_until = max(self._applied_until, t)
        return self._level


class VirtualDigitalOut(DigitalOut):
    """An output pin that records each level change with its cycle time."""

    def __init__(self, now: Callable[[], int], initial: bool = False) -> None:
        """Start at the initial level with an empty history."""
        super().__init__(initial)
        self._now = now
        self.history: list[tuple[int, bool]] = []

    def _drive(self, level: bool) -> None:
        if level != self._level:
            self.history.append((self._now(), level))


class VirtualWatchdog(Watchdog):
    """The watchdog peripheral of the virtual MCU: forwards each kick to a callable (the RTOS watchdog)."""

    def __init__(self, on_kick: Callable[[], None]) -> None:
        """Forward kicks to on_kick."""
        self._on_kick = on_kick
        self.kicks = 0

    def kick(self) -> None:
        """Reload the watchdog: count the kick and forward it."""
        self.kicks += 1
        self._on_kick()

"""Clocks: virtual time in CPU cycles that jumps, and a wall clock that paces releases without drift."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

NS_PER_S = 1_000_000_000


class Clock(Protocol):
    """What the scheduler needs from a clock; times are integer CPU cycles of ``f_cpu_hz``."""

    f_cpu_hz: int
    realtime: bool

    def to_seconds(self, cycles: int) -> float:
        """Convert cycles to seconds."""
        ...

    def to_cycles(self, seconds: float) -> int:
        """Convert seconds to the nearest whole number of cycles."""
        ...

    def start(self, now: int) -> None:
        """Anchor the clock so that cycle ``now`` is the present instant."""
        ...

    def wait_until(self, t: int) -> int:
        """Return once cycle ``t`` has come, giving the current cycle (``t`` or later)."""
        ...

    def now_cycles(self) -> int:
        """Return the current cycle (only meaningful for a real-time clock)."""
        ...


class _CycleClock:
    """Shared conversions between cycles and seconds."""

    realtime = False

    def __init__(self, f_cpu_hz: int) -> None:
        """Check and store the CPU frequency."""
        if isinstance(f_cpu_hz, bool) or not isinstance(f_cpu_hz, int) or f_cpu_hz <= 0:
            raise ValueError(f"f_cpu_hz must be a positive int (Hz), got {f_cpu_hz!r}")
        self.f_cpu_hz = f_cpu_hz

    def to_seconds(self, cycles: int) -> float:
        """Convert cycles to seconds.

        >>> VirtualClock(168_000_000).to_seconds(168_000)
        0.001
        """
        return cycles / self.f_cpu_hz

    def to_cycles(self, seconds: float) -> int:
        """Convert seconds to the nearest whole number of cycles.

        >>> VirtualClock(72_000_000).to_cycles(0.001)
        72000
        """
        return round(seconds * self.f_cpu_hz)

    def to_ns(self, cycles: int) -> int:
        """Convert cycles to whole nanoseconds (rounded down), exact integer arithmetic."""
        return cycles * NS_PER_S // self.f_cpu_hz


class VirtualClock(_CycleClock):
    """Virtual time: waiting for cycle t returns t at once, and a job's finish is solved from its cost."""

    realtime = False

    def start(self, now: int) -> None:
        """Nothing to anchor in virtual time."""

    def wait_until(self, t: int) -> int:
        """Jump to ``t`` instantly."""
        return t

    def now_cycles(self) -> int:
        """Virtual time is kept by the scheduler; a virtual clock has no present of its own."""
        raise RuntimeError("a VirtualClock has no present instant: read Scheduler.now instead")


class WallClock(_CycleClock):
    """Real time in cycles of the nominal ``f_cpu_hz``: absolute-time releases, measured job durations.

    Cycle t is the wall instant ``anchor + t / f_cpu_hz`` computed from the anchor each time, so releases
    never drift. Waiting sleeps until ``spin_s`` before the target, then spins on ``time_ns``.
    """

    realtime = True

    def __init__(
        self,
        f_cpu_hz: int,
        *,
        spin_s: float = 0.001,
        time_ns: Callable[[], int] = time.perf_counter_ns,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        """Create a wall clock; ``time_ns`` and ``sleep`` can be replaced for tests."""
        super().__init__(f_cpu_hz)
        if not 0 <= spin_s <= 1:
            raise ValueError(f"spin_s must be in [0, 1] s, got {spin_s!r}")
        self._spin_ns = int(spin_s * NS_PER_S)
        self._time_ns = time_ns
        self._sleep = sleep
        self._anchor_ns: int | None = None

    def start(self, now: int) -> None:
        """Make cycle ``now`` correspond to the present wall instant."""
        self._anchor_ns = self._time_ns() - self.to_ns(now)

    def _anchor(self) -> int:
        """Return the anchor, anchoring at cycle 0 if nobody did."""
        if self._anchor_ns is None:
            self.start(0)
        return self._anchor_ns  # type: ignore[return-value]

    def now_cycles(self) -> int:
        """Return the present instant in cycles since the anchor."""
        return (self._time_ns() - self._anchor()) * self.f_cpu_hz // NS_PER_S

    def wait_until(self, t: int) -> int:
        """Sleep, then spin, until cycle ``t``; return the measured cycle (``t`` or a little later)."""
        target_ns = self._anchor() + self.to_ns(t)
        remaining = target_ns - self._time_ns()
        if remaining > self._spin_ns:
            self._sleep((remaining - self._spin_ns) / NS_PER_S)
        while self._time_ns() < target_ns:
            pass
        return max(t, self.now_cycles())

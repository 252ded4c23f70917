"""Virtual timers: a general-purpose timer in encoder mode 3 (x4) and the SysTick, both lazy."""

from __future__ import annotations

import math
from collections.abc import Callable

from hal.interfaces import EncoderTimer
from hal.virtual.checks import check_int
from hal.virtual.irq import InterruptSourceBase
from rtos.interrupts import firings_from

__all__ = ["SysTick", "VirtualEncoderTimer"]

SYSTICK_LOAD_MAX = 0xFFFFFF  # 24-bit reload register (CMSIS SysTick_LOAD_RELOAD_Msk)


class VirtualEncoderTimer(EncoderTimer):
    """TIMx in encoder mode 3 (x4), CNT computed from the shaft angle at the instant it is read.

    counts = floor(polarity * angle_rad(t) * counts_per_rev / 2*pi) + offset, CNT = counts mod (ARR+1).
    floor makes every count boundary belong to the count above it, in both directions (angle 0
    reads 0, a hair below 0 reads ARR). The DIR bit follows the most recent change of counts seen
    between two reads, starting from the reset value 0 (hardware updates it at every edge; lazily,
    only the reads are observed).

    >>> enc = VirtualEncoderTimer(lambda: 0, lambda t: -math.tau / 4000)
    >>> enc.cnt(), enc.arr
    (65535, 65535)
    """

    def __init__(
        self,
        now: Callable[[], int],
        angle_rad: Callable[[int], float],
        counts_per_rev: object = 4000,
        bits: int = 16,
        arr: object = None,
        polarity: int = 1,
    ) -> None:
        """Attach to an angle source (radians at a given cycle) with the encoder's resolution."""
        super().__init__(bits, arr)
        counts = check_int("counts_per_rev", counts_per_rev, 1)
        if polarity not in (1, -1):
            raise ValueError(f"polarity {polarity!r} invalid: +1 or -1 (CC1P inverted)")
        self._now = now
        self._angle_rad = angle_rad
        self.counts_per_rev = counts
        self.polarity = polarity
        self._offset = 0
        self._last = 0  # CNT reset value: the counter starts at 0 with DIR = 0
        self._down = False
        self._update_events = 0

    @property
    def update_events(self) -> int:
        """Counter wraps (update events, UIF) seen between successive reads."""
        return self._update_events

    def counts_at(self, t_cycles: int) -> int:
        """Unwrapped count at t_cycles (before the modulo ARR+1), including any set_cnt offset."""
        angle = self._angle_rad(t_cycles)
        if math.isnan(angle) or math.isinf(angle):  # not finite (isnan/isinf are native C calls compiled)
            raise ValueError(f"angle_rad {angle!r} at cycle {t_cycles} is not finite")
        return math.floor(self.polarity * angle * self.counts_per_rev / math.tau) + self._offset

    def _sample(self) -> int:
        counts = self.counts_at(self._now())
        last = self._last
        if counts != last:
            modulus = self._arr + 1
            self._down = counts < last
            self._update_events += abs(counts // modulus - last // modulus)
        self._last = counts
        return counts

    def cnt(self) -> int:
        """The CNT register now, in 0..arr."""
        return self._sample() % (self._arr + 1)

    def counting_down(self) -> bool:
        """The DIR bit now: True if counts last moved downwards."""
        self._sample()
        return self._down

    def _write_cnt(self, value: int) -> None:
        raw = self.counts_at(self._now()) - self._offset
        self._offset = value - raw
        self._last = value

    def update_interrupt(self, cost_cycles: object, name: str = "tim_update") -> InterruptSourceBase:
        """An interrupt source counting wraps in a window, assuming monotone motion within it.

        It evaluates angle_rad at both window ends, which may drive the plant up to t1.
        """
        return _EncoderWrapInterrupt(self, name, cost_cycles)


class _EncoderWrapInterrupt(InterruptSourceBase):
    """Counter wraps between the window ends of an encoder timer (UIF)."""

    def __init__(self, timer: VirtualEncoderTimer, name: str, cost_cycles: object) -> None:
        super().__init__(name, cost_cycles)
        self._timer = timer
        self._cache: dict[int, int] = {}

    def _counts(self, t: int) -> int:
        if t not in self._cache:
            self._cache[t] = self._timer.counts_at(t)
        return self._cache[t]

    def count_in(self, t0: int, t1: int) -> int:
        """Wraps of CNT between t0 and t1 (monotone motion assumed in between)."""
        self._check_window(t0, t1)
        c0, c1 = self._counts(t0), self._counts(t1)
        self._cache = {t0: c0, t1: c1}
        modulus = self._timer.arr + 1
        return abs(c1 // modulus - c0 // modulus)


class SysTick:
    """The Cortex-M SysTick as HAL_InitTick sets it: LOAD = f_cpu / tick_hz - 1, one tick per period.

    >>> st = SysTick(168_000_000)
    >>> st.load, st.ticks(168_000 * 5 + 3)
    (167999, 5)
    """

    def __init__(self, f_cpu_hz: object, tick_hz: object = 1000) -> None:
        """Compute and validate the 24-bit reload value (clock and tick rate: ints >= 1)."""
        f_cpu = check_int("f_cpu_hz", f_cpu_hz, 1)
        tick = check_int("tick_hz", tick_hz, 1)
        load = f_cpu // tick - 1
        if not 1 <= load <= SYSTICK_LOAD_MAX:
            raise ValueError(
                f"SysTick LOAD {load} for f_cpu_hz {f_cpu} and tick_hz {tick} out of range: "
                f"1..{SYSTICK_LOAD_MAX} (24 bits)"
            )
        self.f_cpu_hz = f_cpu
        self.tick_hz = tick
        self.load = load

    @property
    def period_cycles(self) -> int:
        """Cycles between two SysTick interrupts (LOAD + 1)."""
        return self.load + 1

    def ticks(self, now_cycles: int) -> int:
        """HAL_GetTick(): ticks (ms at 1 kHz) elapsed by now_cycles."""
        return now_cycles // self.period_cycles

    def val(self, now_cycles: int) -> int:
        """The SysTick VAL down-counter at now_cycles (LOAD just after each tick, down to 0)."""
        return self.load - now_cycles % self.period_cycles

    def interrupt(self, cost_cycles: object, name: str = "systick") -> InterruptSourceBase:
        """An interrupt source firing at every tick k * period_cycles, k >= 1."""
        return _PeriodicInterrupt(name, cost_cycles, self.period_cycles)


class _PeriodicInterrupt(InterruptSourceBase):
    """Fires at k * period for k >= 1."""

    def __init__(self, name: str, cost_cycles: object, period_cycles: int) -> None:
        super().__init__(name, cost_cycles)
        self._period = period_cycles

    def count_in(self, t0: int, t1: int) -> int:
        """Firings k * period with t0 <= k * period < t1 and k >= 1."""
        if t0 < self._last_t0 or t1 < t0 or t0 < 0:
            self._check_window(t0, t1)  # raises
        self._last_t0 = t0
        return self._firings(t0, t1)

    def _firings(self, t0: int, t1: int) -> int:
        """Firings k * period with t0 <= k * period < t1 and k >= 1 (no check, no state)."""
        period = self._period
        first = -(-t0 // period) or 1
        n = -(-t1 // period) - first
        return n if n > 0 else 0

    def fired_at(self, t0: int, t1: int) -> tuple[int, ...]:
        """The firing cycles k * period in [t0, t1), k >= 1 (for the trace)."""
        return firings_from((self._period, self._period), t0, self._firings(t0, t1))

    def periodic(self) -> tuple[int, int] | None:
        """(period, period): it fires at k * period, k >= 1."""
        return self._period, self._period

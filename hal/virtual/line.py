"""Back-to-back byte timing on one direction of a UART wire, in exact integer cycle arithmetic."""

from __future__ import annotations

from itertools import accumulate
from math import gcd
from typing import Final

__all__ = ["BITS_PER_BYTE_8N1", "ByteLine", "ceil_div"]

BITS_PER_BYTE_8N1 = 10  # start + 8 data + stop
_MAX_PATTERN: Final = 4096  # longest period of the per-byte increments kept as a table


def ceil_div(a: int, b: int) -> int:
    """Ceiling of a / b for integers with b > 0.

    >>> ceil_div(7, 2), ceil_div(8, 2), ceil_div(0, 3)
    (4, 4, 0)
    """
    return -(-a // b)


class ByteLine:
    """When each byte sent on one wire ends, bytes going back to back at a fixed baud.

    A byte lasts ``bits_per_byte * f_cpu_hz / baud`` cycles, an exact rational. Bytes queued
    while the line is busy (before its exact rational end) continue the current burst, and the
    end of the k-th byte of a burst that started at cycle s is ``s + ceil(k * bits * f_cpu / baud)``:
    no rounding drift however long the burst. A byte queued while the line is idle starts a new
    burst at its own (integer) cycle.

    >>> line = ByteLine(168_000_000, 921_600)
    >>> ends = line.schedule(78, start_cycles=1000)
    >>> ends[-1] - 1000          # 78 * 10 / 921600 s = 846.35 us at 168 MHz, rounded up
    142188
    """

    def __init__(self, f_cpu_hz: int, baud: int, bits_per_byte: int = BITS_PER_BYTE_8N1) -> None:
        """Set the byte time from the clock, the baud rate and the bits per character."""
        for label, value in (("f_cpu_hz", f_cpu_hz), ("baud", baud), ("bits_per_byte", bits_per_byte)):
            if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
                raise ValueError(f"{label} {value!r} out of range: a positive int")
        self._num = bits_per_byte * f_cpu_hz  # cycles per byte = num / den
        self._den = baud
        self._origin = 0
        self._count = 0
        # byte k of a burst lasts ceil(k*num/den) - ceil((k-1)*num/den) cycles: periodic in k with
        # period den / gcd(num, den), so a table of one period gives every end by a running sum
        period = baud // gcd(self._num, baud)
        self._period = period
        self._pattern = ([ceil_div(k * self._num, baud) - ceil_div((k - 1) * self._num, baud)
                          for k in range(1, period + 1)] if period <= _MAX_PATTERN else [])
        self._cycle = list(self._pattern)

    @property
    def byte_cycles(self) -> float:
        """Duration of one byte in cycles (for reports; the timing itself is exact)."""
        return self._num / self._den

    @property
    def busy_until(self) -> int:
        """Cycle at which the last queued byte's stop bit ends (the line is idle from then)."""
        return self._origin + ceil_div(self._count * self._num, self._den)

    def schedule(self, n_bytes: int, start_cycles: int) -> list[int]:
        """Queue n_bytes from start_cycles (or when the line frees up); return their end cycles."""
        if n_bytes < 0:
            raise ValueError(f"n_bytes {n_bytes!r} out of range: >= 0")
        if start_cycles < 0:
            raise ValueError(f"start_cycles {start_cycles!r} out of range: >= 0")
        if start_cycles * self._den > self._origin * self._den + self._count * self._num:
            self._origin = start_cycles  # the line is idle (exactly) before start_cycles: new burst
            self._count = 0
        count = self._count
        self._count = count + n_bytes
        if not self._pattern:
            num, den, origin = self._num, self._den, self._origin
            return [origin - (-(k * num) // den) for k in range(count + 1, count + n_bytes + 1)]
        phase = count % self._period
        cycle = self._cycle
        if len(cycle) < phase + n_bytes:
            cycle = self._cycle = self._pattern * ((phase + n_bytes) // self._period + 1)
        incs = cycle[phase : phase + n_bytes]
        if incs:
            incs[0] += self._origin - (-(count * self._num) // self._den)
        return list(accumulate(incs))

    def pending(self, t_cycles: int) -> int:
        """Bytes queued whose stop bit has not ended by t_cycles."""
        if t_cycles >= self.busy_until:
            return 0
        if t_cycles < self._origin:
            return self._count
        done = (t_cycles - self._origin) * self._den // self._num
        return self._count - done

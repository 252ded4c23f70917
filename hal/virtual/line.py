"""Back-to-back byte timing on one direction of a UART wire, in exact integer cycle arithmetic."""

from __future__ import annotations

from mypy_extensions import i64

from hal.virtual.checks import check_int

__all__ = ["BITS_PER_BYTE_8N1", "ByteLine", "ceil_div"]

BITS_PER_BYTE_8N1 = 10  # start + 8 data + stop


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

    def __init__(self, f_cpu_hz: object, baud: object, bits_per_byte: object = BITS_PER_BYTE_8N1) -> None:
        """Set the byte time from the clock, the baud rate and the bits per character (ints >= 1)."""
        f_cpu = check_int("f_cpu_hz", f_cpu_hz, 1)
        den = check_int("baud", baud, 1)
        bits = check_int("bits_per_byte", bits_per_byte, 1)
        # the burst state is in native 64-bit ints (plain C arithmetic when compiled): cycle counts
        # stay far below 2**63
        self._num = bits * f_cpu  # cycles per byte = num / den
        self._den: i64 = den
        step, extra = divmod(self._num, den)
        self._step: i64 = step  # one byte adds step + extra / den cycles
        self._extra: i64 = extra
        self._origin: i64 = 0  # the current burst's start cycle
        self._count = 0  # bytes queued in it
        self._whole: i64 = 0  # count * num = whole * den + rem, 0 <= rem < den: the burst lasts whole + rem/den
        self._rem: i64 = 0

    @property
    def byte_cycles(self) -> float:
        """Duration of one byte in cycles (for reports; the timing itself is exact)."""
        return self._num / self._den

    @property
    def busy_until(self) -> int:
        """Cycle at which the last queued byte's stop bit ends (the line is idle from then)."""
        return self._origin + self._whole + (1 if self._rem else 0)

    def schedule(self, n_bytes: int, start_cycles: int) -> list[int]:
        """Queue n_bytes from start_cycles (or when the line frees up); return their end cycles.

        The ends are exact running sums (whole cycles and a remainder in 1/den), no division per byte.
        """
        if n_bytes < 0:
            raise ValueError(f"n_bytes {n_bytes!r} out of range: >= 0")
        if start_cycles < 0:
            raise ValueError(f"start_cycles {start_cycles!r} out of range: >= 0")
        if start_cycles - self._origin > self._whole:  # idle (exactly) before start_cycles: a new burst
            self._origin = start_cycles
            self._count = self._whole = self._rem = 0
        origin, whole, rem = self._origin, self._whole, self._rem
        step, extra, den = self._step, self._extra, self._den
        ends = [0] * n_bytes
        k: i64
        for k in range(n_bytes):
            whole += step
            rem += extra
            if rem >= den:
                rem -= den
                whole += 1
            ends[k] = origin + whole + (1 if rem else 0)
        self._count += n_bytes
        self._whole, self._rem = whole, rem
        return ends

    def pending(self, t_cycles: int) -> int:
        """Bytes queued whose stop bit has not ended by t_cycles."""
        if t_cycles >= self.busy_until:
            return 0
        if t_cycles < self._origin:
            return self._count
        done = (t_cycles - self._origin) * self._den // self._num
        return self._count - done

"""The per-sample path of the gait reference: a periodic piecewise cubic, evaluated exactly (compiled).

:class:`~firmware.control.reference.GaitReference` fits and validates the curve at design time
(interpreted, with scipy) and hands its coefficients to a :class:`PeriodicCubic`; the control task
samples that object directly every period.
"""

from __future__ import annotations

import math

__all__ = ["PeriodicCubic"]


class PeriodicCubic:
    """Periodic cubic pieces p_i(dt) = ((c3 dt + c2) dt + c1) dt + c0 from breaks[i], clamped to [lo, hi].

    >>> curve = PeriodicCubic([0.0, 1.0], [(0.0, 0.0, 1.0, 0.0), (0.0, 0.0, -1.0, 1.0)], 2.0, -5.0, 5.0)
    >>> curve.sample(2.5)
    (0.5, 1.0, 0.0)
    """

    def __init__(self, breaks: list[float], coef: list[tuple[float, float, float, float]], period_s: float,
                 lo: float, hi: float) -> None:
        """Pieces start at breaks (increasing, the first 0) with coef[i] = (c3, c2, c1, c0); checked by the caller."""
        self.breaks = breaks
        self.coef = coef
        self.period_s = period_s
        self.lo = lo
        self.hi = hi
        self.clamp_count = 0  # samples clamped to lo or hi

    def sample(self, t_s: float) -> tuple[float, float, float]:
        """Return (value, first derivative, second derivative) at t_s >= 0, clamped to [lo, hi].

        A clamped sample has zero derivatives and is counted in clamp_count.
        """
        if not 0.0 <= t_s < math.inf:
            raise ValueError(f"t_s = {t_s!r} is not allowed: must be a finite time >= 0 s")
        tau = t_s % self.period_s
        i = _bisect_right(self.breaks, tau) - 1
        dt = tau - self.breaks[i]
        c3, c2, c1, c0 = self.coef[i]
        value = ((c3 * dt + c2) * dt + c1) * dt + c0
        if value > self.hi:
            self.clamp_count += 1
            return self.hi, 0.0, 0.0
        if value < self.lo:
            self.clamp_count += 1
            return self.lo, 0.0, 0.0
        return value, (3.0 * c3 * dt + 2.0 * c2) * dt + c1, 6.0 * c3 * dt + 2.0 * c2


def _bisect_right(a: list[float], x: float) -> int:
    """bisect.bisect_right for a sorted list of floats (compiled: no boxing of x, no generic call)."""
    lo, hi = 0, len(a)
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo

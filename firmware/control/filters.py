"""Causal low-pass filters: Butterworth biquad cascade and first-order, stepped per sample in pure Python.

scipy designs the Butterworth at construction (butter -> second-order sections); each step runs the
sections in direct form II transposed, the same recurrence as scipy.signal.sosfilt, on Python floats.
"""

from __future__ import annotations

import logging
import math

from firmware.control.validation import check_int_range, check_range, is_number

logger = logging.getLogger(__name__)

#: Allowed Butterworth orders.
ORDER_RANGE: tuple[int, int] = (1, 8)


def _check_rate_and_cutoff(cutoff_hz: float, sample_rate_hz: float) -> None:
    """Raise ValueError unless sample_rate_hz > 0 and 0 < cutoff_hz < sample_rate_hz / 2 (Nyquist)."""
    check_range("sample_rate_hz", sample_rate_hz, 0.0, 1e9, lo_open=True, unit="Hz")
    nyquist = sample_rate_hz / 2.0
    if not (is_number(cutoff_hz) and 0.0 < cutoff_hz < nyquist):
        raise ValueError(
            f"cutoff_hz = {cutoff_hz!r} is not allowed at sample_rate_hz = {sample_rate_hz!r}: "
            f"must lie in (0, {nyquist:g}) Hz (below Nyquist)"
        )


class ButterworthLowPass:
    """Order-n Butterworth low-pass as second-order sections, direct form II transposed, one sample per step.

    >>> f = ButterworthLowPass(order=2, cutoff_hz=10.0, sample_rate_hz=100.0, initial_value=1.5)
    >>> round(f.step(1.5), 12)
    1.5
    """

    __slots__ = ("order", "cutoff_hz", "sample_rate_hz", "_sections", "_zi_unit", "_z")

    def __init__(self, order: int, cutoff_hz: float, sample_rate_hz: float,
                 initial_value: float = 0.0) -> None:
        """Design with scipy.signal.butter (output='sos'); the state starts at steady initial_value."""
        check_int_range("order", order, *ORDER_RANGE)
        _check_rate_and_cutoff(cutoff_hz, sample_rate_hz)
        from scipy import signal  # design time only

        sos = signal.butter(order, cutoff_hz, btype="low", fs=sample_rate_hz, output="sos")
        zi = signal.sosfilt_zi(sos)
        self.order = order
        self.cutoff_hz = float(cutoff_hz)
        self.sample_rate_hz = float(sample_rate_hz)
        # (b0, b1, b2, a1, a2) per section; a0 == 1 by construction of butter's sos.
        self._sections: tuple[tuple[float, float, float, float, float], ...] = tuple(
            (float(s[0]), float(s[1]), float(s[2]), float(s[4]), float(s[5])) for s in sos
        )
        self._zi_unit: tuple[float, ...] = tuple(float(v) for row in zi for v in row)
        self._z: list[float] = [0.0] * len(self._zi_unit)
        self.reset(initial_value)

    @property
    def sos(self) -> list[list[float]]:
        """Second-order sections as [b0, b1, b2, 1, a1, a2] rows (scipy's layout)."""
        return [[b0, b1, b2, 1.0, a1, a2] for b0, b1, b2, a1, a2 in self._sections]

    def reset(self, value: float = 0.0) -> None:
        """Set the state to the steady state of a constant input equal to value (0 clears it)."""
        self._z = [value * z for z in self._zi_unit]

    def step(self, x: float) -> float:
        """Filter one sample and return the output."""
        z = self._z
        i = 0
        for b0, b1, b2, a1, a2 in self._sections:
            y = b0 * x + z[i]
            z[i] = b1 * x - a1 * y + z[i + 1]
            z[i + 1] = b2 * x - a2 * y
            x = y
            i += 2
        return x


class FirstOrderLowPass:
    """First-order low-pass y[k] = alpha x[k] + (1 - alpha) y[k-1], alpha = 1 - exp(-Ts/tau).

    tau = 1/(2 pi fc); alpha is the exact (step-invariant) discretisation of 1/(tau s + 1).

    >>> f = FirstOrderLowPass(cutoff_hz=50.0, sample_rate_hz=1000.0)
    >>> round(f.alpha, 6)
    0.269597
    """

    __slots__ = ("cutoff_hz", "sample_rate_hz", "alpha", "_beta", "_y")

    def __init__(self, cutoff_hz: float, sample_rate_hz: float, initial_value: float = 0.0) -> None:
        """Build the filter for cutoff_hz at sample_rate_hz, state at initial_value."""
        _check_rate_and_cutoff(cutoff_hz, sample_rate_hz)
        self.cutoff_hz = float(cutoff_hz)
        self.sample_rate_hz = float(sample_rate_hz)
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * self.cutoff_hz / self.sample_rate_hz)
        self._beta = 1.0 - self.alpha
        self._y = float(initial_value)

    @property
    def time_constant_s(self) -> float:
        """Continuous time constant tau = 1 / (2 pi fc) in seconds."""
        return 1.0 / (2.0 * math.pi * self.cutoff_hz)

    @property
    def value(self) -> float:
        """Current output (the filter state)."""
        return self._y

    def reset(self, value: float = 0.0) -> None:
        """Set the output state to value."""
        self._y = float(value)

    def step(self, x: float) -> float:
        """Filter one sample and return the output."""
        y = self.alpha * x + self._beta * self._y
        self._y = y
        return y

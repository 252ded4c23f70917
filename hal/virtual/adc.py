"""The virtual STM32 ADC: regular channels scanned on a timer trigger, copied to memory by circular DMA.

Timing (RM0090, 13.5 "Channel-wise programmable sampling time" and 13.6 "Conversion on external trigger"):
a timer triggers one scan of the regular sequence ``sample_rate_hz`` times a second; each channel is
sampled for ``sampling_cycles`` ADC clock cycles and converted in ``conversion_cycles`` more (12 on the
STM32F4, 12.5 on the F1), so ``T_conv = (sampling + conversion) / f_ADC`` per channel, one after the
other. The held voltage is the input's at the end of its sampling window; the code reaches the DMA
buffer at the end of its conversion. The whole scan must fit in one trigger period.

Values: ``code = floor(V / LSB + 0.5 + noise)`` clamped to 0..2**bits - 1 (an input beyond 0..Vref
saturates), LSB = Vref / 2**bits, ``noise`` Gaussian with ``noise_lsb_rms`` LSB. The noise of
conversion n of channel k is a pure function of (seed, k, n) (drawn in blocks of NOISE_BLOCK from a
generator seeded with (seed, k, n // NOISE_BLOCK)), so what a run reads does not depend on when or how
often the firmware looks: laziness keeps determinism. Each
channel is a source ``volts(t_cycles)`` (a device model's output pin). Compiled (setup.py): the firmware
reads it every control period.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from hal.interfaces import Adc

__all__ = ["AdcTiming", "NOISE_BLOCK", "VirtualAdc", "noise_block"]

NOISE_BLOCK = 4096
"""Conversions per block of noise drawn at once for one channel."""


def noise_block(seed: int, channel: int, block: int) -> list[float]:
    """Standard normal numbers for conversions block*NOISE_BLOCK.. of a channel: a pure function of its arguments.

    >>> noise_block(0, 1, 5) == noise_block(0, 1, 5) != noise_block(1, 1, 5)
    True
    """
    return np.random.default_rng([seed, channel, block]).standard_normal(NOISE_BLOCK).tolist()


def _number(name: str, value: object, lo: float, hi: float) -> float:
    """value as a float if it is a number (not a bool) in lo..hi, else ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise ValueError(f"ADC {name} {value!r} out of range: {lo:g}..{hi:g}")
    return float(value)


class AdcTiming:
    """The scan timing in CPU cycles: trigger period, per-channel conversion, sampling window."""

    def __init__(self, f_cpu_hz: int, n_channels: int, sample_rate_hz: object, adc_clock_hz: object,
                 sampling_cycles: object, conversion_cycles: object = 12.0) -> None:
        """ValueError naming a value out of range, or a scan that does not fit in the trigger period.

        The rates and cycle counts are typed ``object`` so that the compiled build still sees a bool as one.
        """
        sample_rate_hz = _number("sample_rate_hz", sample_rate_hz, 1.0, 1e6)
        adc_clock_hz = _number("adc_clock_hz", adc_clock_hz, 1e5, 36e6)
        sampling_cycles = _number("sampling_cycles", sampling_cycles, 1.5, 480.0)
        conversion_cycles = _number("conversion_cycles", conversion_cycles, 6.0, 16.0)
        self.period_cycles = f_cpu_hz / sample_rate_hz
        self.conversion_s = (sampling_cycles + conversion_cycles) / adc_clock_hz
        self.conv_cycles = self.conversion_s * f_cpu_hz
        self.sample_cycles = sampling_cycles / adc_clock_hz * f_cpu_hz
        scan = n_channels * self.conv_cycles
        if scan >= self.period_cycles:
            raise ValueError(f"ADC scan of {n_channels} channels takes {scan / f_cpu_hz * 1e6:.1f} us, longer than "
                             f"the {1e6 / sample_rate_hz:.1f} us trigger period: lower sample_rate_hz or "
                             "sampling_cycles")

    def ready_cycles(self, k: int, n: int) -> float:
        """When conversion n of channel k lands in the DMA buffer."""
        return n * self.period_cycles + (k + 1) * self.conv_cycles

    def held_cycles(self, k: int, n: int) -> float:
        """When conversion n of channel k holds its input (end of the sampling window)."""
        return n * self.period_cycles + k * self.conv_cycles + self.sample_cycles

    def last_ready(self, k: int, t_cycles: int) -> int:
        """The index of channel k's last conversion completed by t_cycles (-1: none yet)."""
        return math.floor((t_cycles - (k + 1) * self.conv_cycles) / self.period_cycles)


class VirtualAdc(Adc):
    """The STM32 ADC + DMA on the bench clock ``now`` (module docstring); ``sources[k]`` drives channel k."""

    def __init__(self, now: Callable[[], int], f_cpu_hz: int, channels: Sequence[str],
                 sources: Sequence[Callable[[int], float]], *, sample_rate_hz: object = 1000.0,
                 adc_clock_hz: object = 21e6, sampling_cycles: object = 84.0, conversion_cycles: object = 12.0,
                 bits: int = 12, vref_v: float = 3.3, noise_lsb_rms: object = 0.0, seed: int = 0) -> None:
        """Bind the channels to their sources; the trigger timer starts at cycle 0."""
        super().__init__(channels, bits, vref_v)
        if len(sources) != len(self.channels):
            raise ValueError(f"{len(sources)} sources for {len(self.channels)} ADC channels")
        noise = _number("noise_lsb_rms", noise_lsb_rms, 0.0, 100.0)
        self.now = now
        self.f_cpu_hz = f_cpu_hz
        self.timing = AdcTiming(f_cpu_hz, len(self.channels), sample_rate_hz, adc_clock_hz, sampling_cycles,
                                conversion_cycles)
        self.sources = list(sources)
        self.noise_lsb_rms = noise
        self.seed = seed
        self._lsb_per_v = (1 << bits) / vref_v
        self._last_n = [-1] * len(self.channels)
        self._codes = [0] * len(self.channels)
        timing = self.timing
        self._period = timing.period_cycles
        self._ready = [(k + 1) * timing.conv_cycles for k in range(len(self.channels))]
        self._held = [k * timing.conv_cycles + timing.sample_cycles for k in range(len(self.channels))]
        self._noise: list[tuple[int, list[float]]] = [(-1, [])] * len(self.channels)
        self.conversions = 0  # conversions computed (the ones somebody looked at)

    def noise(self, k: int, n: int) -> float:
        """The standard normal number of conversion n of channel k."""
        block, i = divmod(n, NOISE_BLOCK)
        held, values = self._noise[k]
        if held != block:
            values = noise_block(self.seed, k, block)
            self._noise[k] = (block, values)
        return values[i]

    def convert(self, k: int, n: int) -> int:
        """The code of conversion n of channel k (its source at the hold instant, quantised, with noise)."""
        v = self.sources[k](int(n * self._period + self._held[k]))  # AdcTiming.held_cycles, inlined
        x = v * self._lsb_per_v + 0.5
        if self.noise_lsb_rms > 0.0:
            x += self.noise_lsb_rms * self.noise(k, n)
        if not math.isfinite(x):
            return 0
        return min(self.full_scale, max(0, math.floor(x)))

    def _dma_buffer(self) -> list[int]:
        t = self.now()
        last, codes, period = self._last_n, self._codes, self._period
        for k, ready in enumerate(self._ready):
            n = math.floor((t - ready) / period)  # AdcTiming.last_ready, inlined
            if n != last[k]:
                last[k] = n
                codes[k] = self.convert(k, n) if n >= 0 else 0
                self.conversions += 1
        return list(codes)

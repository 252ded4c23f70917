"""The ADC in serial mode: the ground sensors' voltages from a Firmata acquisition board on a UART.

Why Firmata: it is the common protocol of small acquisition boards (StandardFirmata ships with the
Arduino IDE; client libraries exist for most languages), it needs nothing beyond the UART pyserial
already gives us, and ``sim://ground-sensors`` serves the same protocol, so serial mode reads the
emulated sensors and a real board the same way. The board: a 3.3 V board with a 12-bit ADC (e.g.
Arduino Due or Zero) running StandardFirmata with ``analogReadResolution(12)`` in ``setup()`` and
``Firmata.begin(115200)``, the four front-end outputs on A0..A3 in the order of ``channels``
(docs/hardware.md, "Ground sensors").

On construction the backend enables reporting of those pins and sets the sampling interval
(``interval_ms``, 2 ms: 4 pins x 3 bytes every 2 ms is 6 kB/s, half of 115200 baud); ``read()`` drains
the UART, decodes and returns the latest value of each pin (0 until its first report), like a DMA
buffer. Bytes that are not Firmata are counted by the decoder and skipped.
"""

from __future__ import annotations

from collections.abc import Sequence

from hal.interfaces import Adc, Uart
from protocol.firmata import FirmataDecoder, report_analog, sampling_interval

__all__ = ["FirmataAdc"]


class FirmataAdc(Adc):
    """An `Adc` whose channels are analog pins 0..n-1 of a Firmata board on ``uart``."""

    def __init__(self, uart: Uart, channels: Sequence[str], *, bits: int = 12, vref_v: float = 3.3,
                 interval_ms: int = 2) -> None:
        """Enable reporting of the pins and set the sampling interval (written to the UART now)."""
        super().__init__(channels, bits, vref_v)
        if len(self.channels) > 16:
            raise ValueError(f"{len(self.channels)} channels: Firmata reports analog pins 0..15 only")
        if isinstance(interval_ms, bool) or not isinstance(interval_ms, int) or not 1 <= interval_ms <= 1000:
            raise ValueError(f"interval_ms {interval_ms!r} out of range: an int in 1..1000")
        self.uart = uart
        self.decoder = FirmataDecoder()
        request = sampling_interval(interval_ms) + b"".join(report_analog(p) for p in range(len(self.channels)))
        uart.write(request)

    def _dma_buffer(self) -> list[int]:
        data = self.uart.read()
        if data:
            self.decoder.feed(data)
        analog, top = self.decoder.analog, self.full_scale
        return [min(top, analog.get(p, 0)) for p in range(len(self.channels))]

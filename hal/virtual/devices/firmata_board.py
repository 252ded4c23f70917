"""A Firmata acquisition board: the ground sensors' voltages sampled and streamed over a UART.

The serial-mode ADC backend (hal/serial/firmata_adc.py) talks to a real board running StandardFirmata;
this model is that board for ``sim://ground-sensors``. Like StandardFirmata it reports its protocol
version at start-up, then every ``sampling interval`` (19 ms until the host sets one) sends an analog
message for each analog pin the host enabled, in pin order, with the code its ADC holds at that instant.
Pins are the ground sensors' ADC channels in order (A0 = load_force, ..., hal/virtual/ground_sensors.py).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from hal.virtual.devices.world import Link, World
from hal.virtual.events import NEVER, EventDevice
from protocol.firmata import FirmataDecoder, analog_message, version_message

__all__ = ["DEFAULT_INTERVAL_MS", "FirmataBoard"]

DEFAULT_INTERVAL_MS = 19
"""StandardFirmata's sampling interval until the host sets one."""


class FirmataBoard(EventDevice):
    """The board on ``world``: ``codes(t)`` gives its ADC's codes at tick t (one per analog pin)."""

    def __init__(self, world: World, codes: Callable[[int], Sequence[int]], pins: int, *, link: Link | None = None,
                 boot_s: float = 0.002) -> None:
        """Power up now; the version report follows after boot_s."""
        super().__init__()
        self.world = world
        self.codes = codes
        self.pins = pins
        self.link = link
        self.decoder = FirmataDecoder()
        t0 = max(world.now, 0)
        self._version_at = t0 + world.ticks(boot_s)
        self._sample_at = NEVER
        self.messages_sent = 0
        self.next_event = self._version_at
        world.add(self)

    @property
    def interval_ticks(self) -> int:
        """The sampling interval in ticks."""
        ms = self.decoder.interval_ms or DEFAULT_INTERVAL_MS
        return self.world.ticks(ms / 1000.0)

    def enabled(self) -> list[int]:
        """The analog pins the host asked for, in order."""
        return [p for p in range(self.pins) if self.decoder.reporting.get(p)]

    # ------------------------------------------------------------------ UART peer
    def connect(self, link: Link | None) -> None:
        """Send the output through link."""
        self.link = link

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        """Take the host's commands (report analog, sampling interval); start sampling once a pin is on."""
        self.decoder.feed(data)
        if self._sample_at == NEVER and self.enabled() and end_times_cycles:
            self._sample_at = end_times_cycles[-1] + self.interval_ticks
            self.next_event = min(self._version_at, self._sample_at)

    def advance_to(self, t_cycles: int) -> None:
        """Bring the whole world (this board included) up to t_cycles."""
        self.world.advance_to(t_cycles)

    # -------------------------------------------------------------- world device
    def run_event(self) -> None:
        """Send the version report, or one sample of the enabled pins."""
        t = self.next_event
        if t >= self._version_at:
            self._version_at = NEVER
            self._transmit(version_message(), t)
        if t >= self._sample_at:
            pins = self.enabled()
            if pins:
                codes = self.codes(t)
                self._transmit(b"".join(analog_message(p, codes[p]) for p in pins), t)
                self.messages_sent += len(pins)
            self._sample_at = t + self.interval_ticks
        self.next_event = min(self._version_at, self._sample_at)

    def _transmit(self, data: bytes, start: int) -> None:
        if self.link is not None:
            self.link.transmit_to_mcu(data, start)

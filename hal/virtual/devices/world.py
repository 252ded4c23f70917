"""The device world: one shared plant and the device models around it, advanced in global time order.

Every device model (AK60-6, BNO08x, encoder) reads or drives the same lazily integrated
:class:`~hal.virtual.plant.Plant`, and the plant only accepts times that never go back. The world
keeps that promise: each device (an ``EventDevice``, :mod:`hal.virtual.events`) announces the time
of its next internal event (``next_event``, in integer ticks of ``f_hz``; :data:`NEVER` when idle)
and ``World.advance_to(t)`` runs every event up to ``t`` across all devices in time order (ties: in
the order the devices were added). A device's own ``advance_to`` (the UART-peer hook) just asks the
world. Time is an integer count of ticks: CPU cycles on the virtual bench, nanoseconds
(``f_hz = 10**9``) when a device runs on the wall clock.
"""

from __future__ import annotations

import logging
import math
from typing import Protocol

from hal.virtual.checks import check_int
from hal.virtual.events import NEVER, EventDevice
from hal.virtual.plant import Plant

__all__ = ["NEVER", "Link", "World", "WorldDevice"]

log = logging.getLogger(__name__)

class Link(Protocol):
    """Where a device's bytes go: the MCU side of a UART (``VirtualUart`` has this method)."""

    def transmit_to_mcu(self, data: bytes, start_cycles: int) -> list[int]:
        """Send data starting at start_cycles (or when the line frees up); return the end times."""
        ...


WorldDevice = EventDevice
"""A device model living in a :class:`World` (:class:`hal.virtual.events.EventDevice`, re-exported)."""


class World:
    """One plant, one time base, and the devices whose events are merged in time order.

    >>> w = World(Plant(initial_angle_rad=0.1), 1_000_000)
    >>> w.advance_to(500); w.now, round(w.seconds(1500), 6)
    (500, 0.0015)
    """

    def __init__(self, plant: Plant, f_hz: object) -> None:
        """Wrap ``plant`` with a time base of ``f_hz`` ticks per second (an int >= 1)."""
        self.plant = plant
        self.f_hz = check_int("f_hz", f_hz, 1)
        self._devices: list[WorldDevice] = []
        self._now = -1
        self._busy = False

    @property
    def now(self) -> int:
        """The tick up to which every device event has been run (-1 before the first advance)."""
        return self._now

    def add(self, device: object) -> None:
        """Register a device (an ``EventDevice``, else TypeError); its events run from the next ``advance_to``."""
        if not hasattr(device, "next_event") or not callable(getattr(device, "run_event", None)):
            raise TypeError(f"device {device!r} lacks next_event and run_event()")
        if not isinstance(device, EventDevice):
            raise TypeError(f"device {device!r} is not an EventDevice (hal.virtual.events)")
        self._devices.append(device)

    def seconds(self, ticks: int) -> float:
        """Convert ticks to seconds."""
        return ticks / self.f_hz

    def ticks(self, t_s: float) -> int:
        """Convert seconds to the nearest tick; ValueError for a non-finite time."""
        if not math.isfinite(t_s):
            raise ValueError(f"time t_s = {t_s!r} must be finite")
        return math.floor(t_s * self.f_hz + 0.5)

    def advance_to(self, t: int) -> None:
        """Run every device event scheduled at or before tick ``t``, earliest first.

        Devices never schedule an event at or before ``now`` (inputs arrive later than the time the
        world has reached; ``Ak60.on_bytes`` and the fault injections check it), so a call with
        ``t <= now`` has nothing to do.
        """
        if t <= self._now or self._busy:  # nothing new, or a device event asking for its own time
            return
        self._busy = True
        try:
            devices = self._devices
            while True:
                best = None
                best_t = t + 1
                for dev in devices:
                    nxt = dev.next_event
                    if nxt < best_t:
                        best, best_t = dev, nxt
                if best is None:
                    break
                if best_t > self._now:
                    self._now = best_t
                best.run_event()
            if t > self._now:
                self._now = t
        finally:
            self._busy = False

    def commit_plant(self) -> None:
        """Integrate the plant up to the world's present (no device queries it earlier any more).

        The plant is integrated lazily, when a device queries or drives it. A wall-clock server (`pafp
        emulate`) calls this while it waits, so that the first command after a quiet spell in which nothing
        queried the plant (an MIT-mode motor before its first frame) does not pay for the whole spell at
        once: the reply to it would come that much late.
        """
        if self._now > 0:
            self.plant.advance_to(self._now / self.f_hz)

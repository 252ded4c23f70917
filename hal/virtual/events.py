"""Event-driven device models as a native base: the world and the UART interrupts read them directly.

A device model announces the tick of its next internal event in ``next_event`` (an int; :data:`NEVER`
when nothing is scheduled) and runs it in ``run_event()``. The compiled :class:`~hal.virtual.devices.world.World`
and the RX interrupt horizon (:mod:`hal.virtual.irq`) read ``next_event`` as a native int field and call
``run_event`` through the vtable instead of a generic attribute look-up and method call. This module
imports no device model, so the peripherals (``irq``, ``uart``) can use it. Python classes (test
doubles) may subclass both classes.
"""

from __future__ import annotations

from typing import Final

from mypy_extensions import mypyc_attr

__all__ = ["NEVER", "EventDevice", "Horizon"]

NEVER: Final = 2305843009213693952
"""2**61: ``next_event`` of a device with nothing scheduled (later than any reachable tick: 435 years at 168 MHz;
below 2**62 so that compiled code keeps it an unboxed int)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class Horizon:
    """A promise about events not yet recorded: none is earlier than ``next_event`` (an int tick)."""

    def __init__(self) -> None:
        """Start with nothing scheduled."""
        self.next_event: int = NEVER


@mypyc_attr(allow_interpreted_subclasses=True)
class EventDevice(Horizon):
    """A device model living in a :class:`~hal.virtual.devices.world.World`: it runs its own events."""

    def run_event(self) -> None:
        """Run the device's event scheduled at ``next_event`` and update ``next_event``."""
        raise NotImplementedError(f"{type(self).__name__} must implement run_event()")

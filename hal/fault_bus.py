"""A python-can bus wrapper with one of pafp's fault injectors on the frames: the CAN counterpart of ``fault://``.

``FaultBus(bus, fault)`` wraps any open ``can.BusABC`` (socketcan, a USB adapter, python-can's ``virtual``) and
passes the frames it receives and sends through the same injector classes as the virtual bench
(hal/virtual/faults): a :class:`~hal.virtual.faults.can_fault.CanFault` decides each frame's fate (destroyed,
or late by its retransmissions), a :class:`~hal.virtual.faults.base.ByteFault` destroys a frame whose data it
would change (the CRC catches it). Times count from the wrapper's creation. Wrap the bus before handing it to
:class:`~hal.pycan.PythonCanPort`. Dangerous faults are refused unless ``allow_dangerous`` (docs/hardware.md).
"""

from __future__ import annotations

import heapq
import itertools
import time
from typing import Any

import can

from hal.can import CanFrame

__all__ = ["FaultBus"]


class FaultBus(can.BusABC):
    """``bus`` with ``fault`` acting on the frames both ways (see the module docstring)."""

    def __init__(self, bus: can.BusABC, fault: Any, allow_dangerous: bool = False, **kwargs: Any) -> None:
        """Wrap an open bus; ValueError for a fault that does not act on frames or is dangerous without leave."""
        from hal.virtual.faults.base import ByteFault
        from hal.virtual.faults.can_fault import CanFault

        if not isinstance(fault, (ByteFault, CanFault)):
            raise ValueError(f"fault {fault.NAME} acts on the {fault.WHERE}, not on CAN frames: it exists on the "
                             "virtual bench only")
        if fault.DANGEROUS and not allow_dangerous:
            raise ValueError(f"fault {fault.NAME} is refused on a real bus: {fault.HAZARD} (docs/hardware.md)")
        if isinstance(fault, CanFault):
            fault.bitrate = int(kwargs.pop("bitrate", 1_000_000))
        self.inner, self.fault = bus, fault
        self.channel_info = f"fault {fault.NAME} on {getattr(bus, 'channel_info', bus)}"
        self._t0 = time.monotonic()
        self._late: list[tuple[float, int, can.Message]] = []  # frames held back: (due, seq, message)
        self._seq = itertools.count()
        super().__init__(channel=getattr(bus, "channel", None), **kwargs)

    def _fate(self, msg: can.Message) -> float | None:
        """None: destroyed; else the delay in seconds."""
        from hal.virtual.faults.can_fault import CanFault

        t = time.monotonic() - self._t0
        frame = CanFrame(msg.arbitration_id, bytes(msg.data), msg.is_extended_id)
        if isinstance(self.fault, CanFault):
            return self.fault.on_frame(frame, t)
        return 0.0 if self.fault.filter(frame.data, t) == frame.data else None

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            now = time.monotonic()
            if self._late and self._late[0][0] <= now:
                return heapq.heappop(self._late)[2], False
            wait = 0.0 if end is None and self._late else None if end is None else max(0.0, end - now)
            if self._late:
                wait = min(wait if wait is not None else 1.0, max(0.0, self._late[0][0] - now))
            msg = self.inner.recv(wait)
            if msg is not None:
                fate = self._fate(msg)
                if fate == 0.0:
                    return msg, False
                if fate is not None:
                    heapq.heappush(self._late, (time.monotonic() + fate, next(self._seq), msg))
            if end is not None and time.monotonic() >= end and not (self._late and self._late[0][0] <= end):
                return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send through the fault: a destroyed frame never reaches the bus (a late one is sent late: blocking)."""
        fate = self._fate(msg)
        if fate is None:
            return
        if fate > 0.0:
            time.sleep(fate)
        self.inner.send(msg, timeout)

    def shutdown(self) -> None:
        """Shut the wrapped bus down."""
        self.inner.shutdown()
        super().shutdown()

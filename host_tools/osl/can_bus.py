"""Run a CAN SDK that hard-codes ``can.interface.Bus(channel="can0", bustype="socketcan")`` on another bus.

opensourceleg's ``TMotorServoActuator`` and TMotorCANControl's managers open ``socketcan``/``can0`` and nothing
else. On Linux, a virtual interface named ``can0`` (``ip link add dev can0 type vcan``) is the plain route
(docs/hardware.md). Where there is no vcan, :func:`redirected_can` swaps python-can's ``Bus`` constructor for
the duration of a ``with`` block, so that the SDK's ``socketcan``/``can0`` opens the bus a can:// URL names::

    with redirected_can("can://udp_multicast/239.74.163.2"):
        motor = TMotorServoActuator(motor_type="AK80-9", motor_id=1)   # the SDK, unchanged

A ``udp_multicast`` bus hands a process its own frames back (multicast loopback), which a socketcan bus
never does; the SDKs' listeners would take their own commands for the motor's replies (opensourceleg's
raises on a 4-byte frame and its receive thread dies). :class:`NoEchoBus` drops those echoes, as
:class:`hal.pycan.PythonCanPort` does for pafp's own ports.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from typing import Any

import can

from hal.pycan import ECHOING_INTERFACES, OwnFrames, own_group_only, parse_can_url

__all__ = ["NoEchoBus", "redirected_can"]


class NoEchoBus(can.BusABC):
    """A python-can bus that does not hand its own frames back (what socketcan does by default)."""

    def __init__(self, bus: can.BusABC, **kwargs: Any) -> None:
        """Wrap an open bus; this one owns it (shutdown shuts it down)."""
        self._bus = bus
        self._own = OwnFrames()
        super().__init__(channel=getattr(bus, "channel_info", "wrapped"), **kwargs)
        self.channel_info = f"{bus.channel_info} (own frames dropped)"

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send msg and remember it, so that its echo is dropped."""
        self._own.sent((msg.arbitration_id, bytes(msg.data), msg.is_extended_id))
        self._bus.send(msg, timeout)

    @property
    def echoes(self) -> int:
        """Own frames the bus handed back, dropped."""
        return self._own.echoes

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if end is None else max(0.0, end - time.monotonic())
            msg = self._bus.recv(left)
            if msg is None:
                return None, False
            if not self._own.is_echo((msg.arbitration_id, bytes(msg.data), msg.is_extended_id)):
                return msg, False
            if end is not None and time.monotonic() >= end:
                return None, False

    def shutdown(self) -> None:
        """Shut the wrapped bus down."""
        super().shutdown()
        self._bus.shutdown()


@contextlib.contextmanager
def redirected_can(url: str, channel: str = "can0") -> Iterator[list[can.BusABC]]:
    """Within the block, ``can.interface.Bus(channel=channel, ...)`` (and ``can.Bus``) open the bus of ``url``.

    ``url`` is a can:// URL (``can://INTERFACE/CHANNEL``; ``id`` and ``mode`` are not needed here). Other
    channels open as asked. Yields the list of buses opened in the block.
    """
    interface, target = _interface_channel(url)
    original = can.interface.Bus
    opened: list[can.BusABC] = []

    def bus(*args: Any, **kwargs: Any) -> can.BusABC:
        asked = kwargs.get("channel", args[0] if args else None)
        if asked != channel:
            return original(*args, **kwargs)
        inner = original(interface=interface, channel=target)
        if interface == "udp_multicast":
            own_group_only(inner)  # as pafp's own ports: not the frames of the host's other groups
        made = NoEchoBus(inner) if interface in ECHOING_INTERFACES else inner
        opened.append(made)
        return made

    can.interface.Bus = bus  # type: ignore[misc,assignment]
    can.Bus = bus  # type: ignore[misc,assignment]
    try:
        yield opened
    finally:
        can.interface.Bus = original  # type: ignore[misc]
        can.Bus = original  # type: ignore[misc]


def _interface_channel(url: str) -> tuple[str, str]:
    """(interface, channel) of a can:// URL; its id and mode may be left out."""
    probe = url if "mode=" in url else url + ("&" if "?" in url else "?") + "id=1&mode=servo"
    parsed = parse_can_url(probe, "redirected_can url")
    return parsed.interface, parsed.channel

"""Errors raised by HAL backends that the firmware is expected to handle (never raw pyserial/OS errors)."""

from __future__ import annotations

__all__ = ["HalError", "PortLostError"]


class HalError(Exception):
    """A peripheral failed in a way the firmware must handle (closed, lost, misconfigured at run time)."""


class PortLostError(HalError):
    """A serial port could not be opened or vanished while in use (unplugged, pty closed, I/O error)."""

    def __init__(self, port: str, reason: str) -> None:
        """Name the port and say what went wrong."""
        super().__init__(f"serial port {port!r} lost: {reason}")
        self.port = port
        self.reason = reason

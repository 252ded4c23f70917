"""`pafp run --telemetry pty`: a new pty whose far end `pafp monitor PATH` can attach to and leave at will.

The firmware's telemetry goes into the pty's master; the slave's path is what a user opens. The slave
stays open here as well, so writes never fail with EIO while no monitor is attached; bytes that do not
fit in the pty's queue (nobody reading) are dropped here and counted, never held: the log must not slow
the firmware, and telemetry.bin keeps every record whatever the pty does.
"""

from __future__ import annotations

import os
import tty

from hal.interfaces import Uart

__all__ = ["TelemetryPty"]

_SPACE = 1 << 16


class TelemetryPty(Uart):
    """A transmit-only `Uart` on a new raw pty; `path` is the end to give `pafp monitor`."""

    def __init__(self, baud: int = 921600) -> None:
        """Open the pty pair (raw, non-blocking master)."""
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        super().__init__(baud, name=f"pty:{self.path}")
        self.dropped = 0

    @property
    def url(self) -> str:
        """How the run names this port in its summary."""
        return self.name

    def _send(self, data: bytes) -> int:
        try:
            n = os.write(self._master, data)
        except BlockingIOError:
            n = 0
        self.dropped += len(data) - n
        return len(data)  # taken: what the pty could not hold is dropped here, not pushed back on the logger

    def _tx_space(self) -> int:
        return _SPACE

    def _receive(self, max_bytes: int) -> bytes:
        return b""

    def _rx_count(self) -> int:
        return 0

    def _close(self) -> None:
        os.close(self._master)
        os.close(self._slave)

"""The telemetry UART of serial mode: every accepted byte goes to a file (flushed) and, optionally, a port.

The file is written as the firmware logs, so a run stopped at any moment (a lost link, Ctrl-C, a crash)
leaves `telemetry.bin` complete up to the last record sent. A failing telemetry port does not stop the
firmware: the capture goes on alone and the error is kept for the report. Nor does a failing file (a full
disk): the bytes are still kept in memory and sent to the port, the error is kept in ``file_error`` and the
command reports it after the stop path (exit 74, docs/hardware.md).
"""

from __future__ import annotations

import logging
from pathlib import Path

from hal.errors import HalError
from hal.interfaces import Uart

__all__ = ["CaptureUart"]

log = logging.getLogger(__name__)

_NO_PORT_SPACE = 1 << 16


class CaptureUart(Uart):
    """A transmit-only `Uart` that appends to `path` and forwards to `inner` while it works."""

    def __init__(self, path: Path, baud: int, inner: Uart | None = None) -> None:
        """Create (truncate) `path`; `inner` is the real telemetry port, if any."""
        super().__init__(baud, name=f"capture:{path.name}")
        self.path = path
        self.inner = inner
        self.inner_error = ""
        self.file_error: OSError | None = None
        self._file = path.open("wb")
        self._data = bytearray()

    def captured(self) -> bytes:
        """Every byte accepted so far."""
        return bytes(self._data)

    def _inner_call(self, fn, *args):  # type: ignore[no-untyped-def]
        """Call the port; on a HalError remember it and carry on without the port."""
        try:
            return fn(*args)
        except HalError as exc:
            self.inner_error = str(exc)
            log.warning("telemetry port lost, capturing to %s only: %s", self.path, exc)
            self.inner = None
            return None

    def _tx_space(self) -> int:
        if self.inner is None:
            return _NO_PORT_SPACE
        free = self._inner_call(self.inner.tx_free)
        return _NO_PORT_SPACE if free is None else int(free)

    def _send(self, data: bytes) -> int:
        accepted = len(data)
        if self.inner is not None:
            n = self._inner_call(self.inner.write, data)
            if n is not None:
                accepted = int(n)
        chunk = data[:accepted]
        self._data += chunk
        if self.file_error is None:
            try:
                self._file.write(chunk)
                self._file.flush()
            except OSError as exc:
                self.file_error = OSError(exc.errno, exc.strerror or str(exc), str(self.path))
                log.error("cannot write %s (%s): telemetry kept in memory, the run goes on", self.path, exc)
        return accepted

    def _receive(self, max_bytes: int) -> bytes:
        return b""

    def _rx_count(self) -> int:
        return 0

    def _close(self) -> None:
        try:
            self._file.close()
        except OSError as exc:  # the last flush: the same failure as a write's
            self.file_error = self.file_error or OSError(exc.errno, exc.strerror or str(exc), str(self.path))

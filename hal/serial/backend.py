"""The pyserial backend: a `Uart` on any port or URL pyserial opens (device paths, loop://, socket://, spy://).

Reads and writes never block (timeout=0, write_timeout=0). A write takes what fits in the transmit
queue (``tx_queue_size`` minus the bytes the OS still holds, where the port reports them) and what
the OS accepts without blocking; the rest is refused and counted as ``tx_dropped``. Any pyserial
or OS error surfaces as `PortLostError` naming the port, never as a raw exception.
"""

from __future__ import annotations

import io
import logging
import time
from collections.abc import Callable
from typing import Any

import serial

from hal.errors import HalError, PortLostError
from hal.interfaces import Uart
from hal.serial.icount import IcountSnapshot, read_icount

__all__ = ["SerialUart"]

log = logging.getLogger(__name__)

# pyserial handlers whose write() cannot do a non-blocking partial write: with write_timeout=0
# loop:// refuses every write (it compares the time to send with the timeout); they are opened
# with a blocking write and never handed more than the space left in their queue.
_BLOCKING_WRITE_SCHEMES = frozenset({"loop"})
_PORT_ERRORS = (serial.SerialException, OSError)
_READ_CHUNK = 4096


def url_scheme(url: str) -> str:
    """The lower-case scheme of a pyserial URL, or '' for a plain device path.

    >>> url_scheme("socket://localhost:7777"), url_scheme("/dev/ttyUSB0")
    ('socket', '')
    """
    return url.split("://", 1)[0].lower() if "://" in url else ""


class SerialUart(Uart):
    """A real (or pyserial-emulated) serial port as a non-blocking `Uart`."""

    def __init__(
        self,
        url: str,
        baud: int,
        *,
        tx_queue_size: int = 4096,
        name: str | None = None,
        port_factory: Callable[..., Any] | None = None,
        **serial_options: Any,
    ) -> None:
        """Open url at baud (8N1 unless serial_options say otherwise); PortLostError if it cannot open."""
        super().__init__(baud, name or url)
        if isinstance(tx_queue_size, bool) or not isinstance(tx_queue_size, int) or tx_queue_size < 1:
            raise ValueError(f"tx_queue_size {tx_queue_size!r} out of range: an int >= 1")
        self.url = url
        blocking = url_scheme(url) in _BLOCKING_WRITE_SCHEMES
        factory = port_factory or serial.serial_for_url
        refused: tuple[type[Exception], ...] = ()
        if url_scheme(url) == "fault":  # our fault-injecting wrapper (hal/serial/protocol_fault.py)
            from hal.serial.protocol_fault import FaultUrlError, register_fault_handler

            register_fault_handler()
            refused = (FaultUrlError,)
        try:
            self._port = factory(
                url, baudrate=baud, timeout=0, write_timeout=None if blocking else 0, **serial_options
            )
        except refused as exc:  # the URL itself refused: a bad input, not a lost port (named once by the caller)
            raise ValueError(f"fault URL refused: {exc}") from None
        except _PORT_ERRORS as exc:
            raise PortLostError(url, f"cannot open: {exc}") from exc
        limit = getattr(self._port, "buffer_size", None) if blocking else None
        self.tx_queue_size = min(tx_queue_size, limit) if isinstance(limit, int) else tx_queue_size
        self._lost_reason: str | None = None
        self._icount_fd = self._fileno()
        self._icount_base = read_icount(self._icount_fd) if self._icount_fd is not None else None

    @property
    def serial(self) -> Any:
        """The underlying pyserial object (for host tools; the firmware never needs it)."""
        return self._port

    @property
    def lost(self) -> bool:
        """True once the port has failed; every later call raises PortLostError."""
        return self._lost_reason is not None

    def _fileno(self) -> int | None:
        try:
            fd = self._port.fileno()
        except (AttributeError, io.UnsupportedOperation, *_PORT_ERRORS):
            return None
        return fd if isinstance(fd, int) else None

    def _call(self, what: str, fn: Callable[..., Any], *args: Any) -> Any:
        if self._lost_reason is not None:
            raise PortLostError(self.url, self._lost_reason)
        try:
            return fn(*args)
        except serial.SerialTimeoutException:
            raise
        except _PORT_ERRORS as exc:
            self._lost_reason = f"{exc} (in {what})"
            log.warning("serial port %s lost: %s", self.url, self._lost_reason)
            raise PortLostError(self.url, self._lost_reason) from exc

    def _out_waiting(self) -> int:
        try:
            return int(self._call("out_waiting", lambda: self._port.out_waiting))
        except (AttributeError, NotImplementedError, io.UnsupportedOperation):
            return 0

    # Uart hooks -----------------------------------------------------------------------------
    def _tx_space(self) -> int:
        return max(0, self.tx_queue_size - self._out_waiting())

    def _send(self, data: bytes) -> int:
        chunk = data[: self._tx_space()]
        if not chunk:
            return 0
        try:
            written = self._call("write", self._port.write, chunk)
        except serial.SerialTimeoutException:
            return 0
        return len(chunk) if written is None else int(written)

    def _rx_count(self) -> int:
        return int(self._call("in_waiting", lambda: self._port.in_waiting))

    def _receive(self, max_bytes: int) -> bytes:
        # with timeout=0 every pyserial handler returns what it has without waiting, and a
        # hung-up port reports itself through read() (EIO, "socket disconnected")
        if max_bytes > 0:
            return bytes(self._call("read", self._port.read, max_bytes))
        out = bytearray()
        while True:
            chunk = self._call("read", self._port.read, _READ_CHUNK)
            out += chunk
            if len(chunk) < _READ_CHUNK:
                return bytes(out)

    def _refresh_errors(self) -> None:
        if self._icount_base is None or self._icount_fd is None or self._lost_reason is not None:
            return
        now = read_icount(self._icount_fd)
        if now is not None:
            self._apply_icount(self._icount_base, now)

    def _apply_icount(self, base: IcountSnapshot, now: IcountSnapshot) -> None:
        lost = (now.overrun - base.overrun) + (now.buf_overrun - base.buf_overrun)
        self._errors.framing = now.frame - base.frame
        self._errors.overrun = lost
        self._errors.rx_lost = lost

    def _drain(self, timeout_s: float) -> bool:
        # tcdrain() on a tty (pyserial's flush): returns once the driver has sent the last stop bit
        deadline = time.monotonic() + timeout_s
        while self._out_waiting() and time.monotonic() < deadline:
            time.sleep(0.0002)
        self._call("flush", self._port.flush)
        return not self._out_waiting()

    def _close(self) -> None:
        try:
            self._port.close()
        except (*_PORT_ERRORS, HalError) as exc:
            log.debug("closing %s: %s", self.url, exc)

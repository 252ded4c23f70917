"""The CAN port the firmware is handed: frames, the bxCAN-shaped interface, its error counters.

Like :class:`hal.interfaces.Uart`, :class:`CanPort` holds the checks shared by every backend and asks
a few hooks of it (``_send``, ``_receive``, ``_tx_pending``, ``_drain``, ``_close``). Backends: the
virtual bxCAN (:mod:`hal.virtual.can`) and python-can buses (:mod:`hal.pycan`). The firmware imports
this module only.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

from mypy_extensions import mypyc_attr

from hal.errors import HalError

__all__ = ["CanErrors", "CanFrame", "CanPort"]


@dataclass(frozen=True)
class CanFrame:
    """One data frame: its identifier (11 or 29 bits), 0..8 data bytes, and whether the ID is extended."""

    arbitration_id: int
    data: bytes
    extended: bool = False

    def __post_init__(self) -> None:
        """Check the identifier and the length."""
        limit = (1 << 29) if self.extended else (1 << 11)
        if not 0 <= self.arbitration_id < limit:
            raise ValueError(f"CAN id {self.arbitration_id:#x} out of range 0..{limit - 1:#x} "
                             f"({'extended' if self.extended else 'standard'})")
        if len(self.data) > 8:
            raise ValueError(f"CAN frame of {len(self.data)} data bytes: at most 8")


@dataclass
class CanErrors:
    """What went wrong on a port: receive FIFO overruns (frames lost), frames refused for want of a mailbox."""

    overruns: int = 0
    tx_refused: int = 0


@mypyc_attr(allow_interpreted_subclasses=True)  # backends and test doubles subclass it
class CanPort(ABC):
    """A CAN controller: send into a transmit mailbox, receive from the FIFOs; HalError once closed or failed."""

    def __init__(self, bitrate: int, name: str = "can") -> None:
        """Keep the bit rate (bit/s, an int > 0) and a name for messages."""
        if isinstance(bitrate, bool) or not isinstance(bitrate, int) or bitrate <= 0:
            raise ValueError(f"bitrate {bitrate!r} out of range: a positive int (bit/s)")
        self.bitrate = bitrate
        self.name = name
        self.errors = CanErrors()
        self._closed = False

    @property
    def closed(self) -> bool:
        """True once closed."""
        return self._closed

    def send(self, frame: CanFrame) -> bool:
        """Queue frame in a free transmit mailbox; False (counted in errors.tx_refused) when none is free."""
        self._check_open()
        ok = self._send(frame)
        if not ok:
            self.errors.tx_refused += 1
        return ok

    def receive(self) -> CanFrame | None:
        """The oldest received frame (FIFO 0 before FIFO 1), or None."""
        self._check_open()
        return self._receive()

    def tx_pending(self) -> int:
        """Frames still in the transmit mailboxes."""
        self._check_open()
        return self._tx_pending()

    def flush(self, timeout_s: float = 0.5) -> bool:
        """Wait until every queued frame has left (True) or timeout_s has passed (False)."""
        self._check_open()
        return self._drain(timeout_s)

    def close(self) -> None:
        """Release the port; later calls raise HalError."""
        if not self._closed:
            self._closed = True
            self._close()

    def _check_open(self) -> None:
        if self._closed:
            raise HalError(f"{self.name}: port is closed")

    @abstractmethod
    def _send(self, frame: CanFrame) -> bool:
        """Backend hook: queue one frame; False when no mailbox is free."""

    @abstractmethod
    def _receive(self) -> CanFrame | None:
        """Backend hook: one received frame or None."""

    def _tx_pending(self) -> int:
        return 0

    def _drain(self, timeout_s: float) -> bool:
        return True

    def _close(self) -> None:  # noqa: B027 (optional hook)
        pass

"""Stand-in peripherals for the `null://` binding: present, harmless, and silent."""

from __future__ import annotations

from hal.interfaces import DigitalIn, DigitalOut, EncoderTimer, Uart

__all__ = ["NullDigitalIn", "NullDigitalOut", "NullEncoderTimer", "NullUart"]


class NullUart(Uart):
    """A UART to nowhere: every write is accepted and discarded, nothing is ever received.

    >>> u = NullUart(115200)
    >>> u.write(b"abc"), u.read(), u.in_waiting()
    (3, b'', 0)
    """

    def __init__(self, baud: int, name: str = "null") -> None:
        """A UART at baud that never receives."""
        super().__init__(baud, name)

    def _send(self, data: bytes) -> int:
        return len(data)

    def _receive(self, max_bytes: int) -> bytes:
        return b""

    def _rx_count(self) -> int:
        return 0

    def _tx_space(self) -> int:
        return 1 << 16


class NullEncoderTimer(EncoderTimer):
    """An encoder timer whose shaft never moves: CNT stays where it was last set (0 at reset)."""

    def __init__(self, bits: int = 16, arr: int | None = None) -> None:
        """A still counter of the given width."""
        super().__init__(bits, arr)
        self._cnt = 0

    def cnt(self) -> int:
        """The constant CNT."""
        return self._cnt

    def counting_down(self) -> bool:
        """Always False (DIR = 0 at reset)."""
        return False

    def _write_cnt(self, value: int) -> None:
        self._cnt = value


class NullDigitalIn(DigitalIn):
    """An input pin tied to a fixed level."""

    def __init__(self, level: bool = False) -> None:
        """Tie the pin to level."""
        self._level = bool(level)

    def read(self) -> bool:
        """The fixed level."""
        return self._level


class NullDigitalOut(DigitalOut):
    """An output pin connected to nothing (it only remembers its level)."""

    def _drive(self, level: bool) -> None:
        pass

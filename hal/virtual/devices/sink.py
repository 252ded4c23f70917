"""A UART peer that only listens: the laptop at the end of the telemetry link records every byte."""

from __future__ import annotations

from collections.abc import Sequence

from hal.virtual.events import Horizon

__all__ = ["ByteSink"]


class ByteSink(Horizon):
    """Records every byte the MCU sends, with the stop-bit end time of the last byte of each write.

    >>> sink = ByteSink()
    >>> sink.on_bytes(b"ab", [10, 20]); sink.advance_to(30); bytes(sink.data), sink.last_end_cycles
    (b'ab', 20)
    """

    def __init__(self, max_bytes: int | None = None) -> None:
        """Keep at most max_bytes (None: everything); older bytes beyond it are counted in ``discarded``."""
        if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, int)
                                      or max_bytes < 1):
            raise ValueError(f"max_bytes {max_bytes!r} out of range: None or an int >= 1")
        super().__init__()  # next_event stays NEVER: it never transmits, an RX window needs no catch-up
        self.max_bytes = max_bytes
        self.data = bytearray()
        self.discarded = 0
        self.last_end_cycles = -1

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        """Append the bytes (the line delivers them at their end times; a recorder need not wait)."""
        self.data += data
        if end_times_cycles:
            self.last_end_cycles = end_times_cycles[-1]
        if self.max_bytes is not None and len(self.data) > self.max_bytes:
            extra = len(self.data) - self.max_bytes
            del self.data[:extra]
            self.discarded += extra

    def advance_to(self, t_cycles: int) -> None:
        """Nothing to send back."""

    def received(self) -> bytes:
        """Everything recorded so far."""
        return bytes(self.data)

    def take(self) -> bytes:
        """The bytes recorded since the last take, forgotten here (a recorder streaming them to a file).

        >>> sink = ByteSink(); sink.on_bytes(b"ab", [10, 20]); sink.take(), sink.take(), sink.data
        (b'ab', b'', bytearray(b''))
        """
        data = bytes(self.data)
        self.data.clear()
        return data

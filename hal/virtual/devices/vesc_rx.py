"""Bytes received by a VESC device, held with their stop-bit end times until they can complete a frame.

A VESC frame ends with the byte 03, so a frame can only complete on an 03. :class:`TimedBytes` cuts the
received bytes into slices that end at each 03 (``next_at`` is that byte's end time) and hands them out
one by one, so a device feeding its decoder slice by slice knows, without per-byte work, the exact
instant each decoded message completed.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from hal.virtual.devices.world import NEVER

__all__ = ["TimedBytes"]

_COMPACT_AT: Final = 1024
"""Slices handed out before the lists drop them (when they are not emptied first)."""
_END: Final = 3


class TimedBytes:
    """Received bytes with their end times, handed out in slices ending at each 03 byte.

    >>> rx = TimedBytes()
    >>> rx.push(b"\\x02\\x01\\x04\\x40\\x84\\x03\\x00", [1, 2, 3, 4, 5, 6, 7])
    >>> rx.next_at, rx.take(), rx.next_at == NEVER, len(rx)
    (6, b'\\x02\\x01\\x04@\\x84\\x03', True, 1)
    """

    def __init__(self) -> None:
        """Start empty."""
        self._slices: list[bytes] = []
        """Complete slices (each ending with 03), from ``_taken`` on not handed out yet."""
        self._slice_ends: list[int] = []
        """End time of the last byte of each slice."""
        self._taken = 0
        self._tail = bytearray()
        """Bytes after the last 03 (the start of the next slice)."""
        self._held = 0
        self.next_at = NEVER
        """End time of the next 03 byte (NEVER if none is held)."""

    def __len__(self) -> int:
        """Bytes held and not handed out yet."""
        return self._held

    def push(self, data: bytes, end_times: Sequence[int]) -> None:
        """Add bytes and their stop-bit end times (non-decreasing, one per byte)."""
        if len(data) != len(end_times):
            raise ValueError(f"{len(data)} bytes but {len(end_times)} end times: need one per byte")
        self._held += len(data)
        start = 0
        j = data.find(_END)
        while j >= 0:
            piece = data[start : j + 1]
            if self._tail:
                piece = bytes(self._tail) + piece
                self._tail.clear()
            self._slices.append(piece)
            self._slice_ends.append(end_times[j])
            start = j + 1
            j = data.find(_END, start)
        if start < len(data):
            self._tail += data[start:]
        if self.next_at == NEVER and self._taken < len(self._slices):
            self.next_at = self._slice_ends[self._taken]

    def take(self) -> bytes:
        """Hand out the bytes up to and including the next 03 (empty if there is none)."""
        taken = self._taken
        slices = self._slices
        if taken == len(slices):
            return b""
        out = slices[taken]
        self._held -= len(out)
        taken += 1
        if taken == len(slices):
            slices.clear()
            self._slice_ends.clear()
            self._taken, self.next_at = 0, NEVER
            return out
        self.next_at = self._slice_ends[taken]
        if taken >= _COMPACT_AT:
            del slices[:taken]
            del self._slice_ends[:taken]
            taken = 0
        self._taken = taken
        return out

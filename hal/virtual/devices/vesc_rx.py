"""Bytes received by a VESC device, held with their stop-bit end times until they can complete a frame.

A VESC frame ends with the byte 03, so a frame can only complete on an 03. :class:`TimedBytes` keeps the
received bytes and hands them out in slices that end at each 03 (``next_at`` is that byte's end time),
so a device feeding its decoder slice by slice knows, without per-byte work, the exact instant each
decoded message completed.
"""

from __future__ import annotations

from collections.abc import Sequence

from hal.virtual.devices.world import NEVER

__all__ = ["TimedBytes"]

_COMPACT_AT = 4096
_END = 3


class TimedBytes:
    """Received bytes with their end times, handed out in slices ending at each 03 byte.

    >>> rx = TimedBytes()
    >>> rx.push(b"\\x02\\x01\\x04\\x40\\x84\\x03\\x00", [1, 2, 3, 4, 5, 6, 7])
    >>> rx.next_at, rx.take(), rx.next_at == NEVER, len(rx)
    (6, b'\\x02\\x01\\x04@\\x84\\x03', True, 1)
    """

    def __init__(self) -> None:
        """Start empty."""
        self._data = bytearray()
        self._ends: list[int] = []
        self._fed = 0
        self._idx = -1
        self.next_at = NEVER
        """End time of the next 03 byte (NEVER if none is held)."""

    def __len__(self) -> int:
        """Bytes held and not handed out yet."""
        return len(self._data) - self._fed

    def push(self, data: bytes, end_times: Sequence[int]) -> None:
        """Add bytes and their stop-bit end times (non-decreasing, one per byte)."""
        if len(data) != len(end_times):
            raise ValueError(f"{len(data)} bytes but {len(end_times)} end times: need one per byte")
        base = len(self._data)
        self._data += data
        self._ends.extend(end_times)
        if self._idx < 0:
            j = self._data.find(_END, base)
            if j >= 0:
                self._idx, self.next_at = j, self._ends[j]

    def take(self) -> bytes:
        """Hand out the bytes up to and including the next 03 (empty if there is none)."""
        if self._idx < 0:
            return b""
        end = self._idx + 1
        out = bytes(self._data[self._fed : end])
        self._fed = end
        if end == len(self._data):
            self._data.clear()
            self._ends.clear()
            self._fed, self._idx, self.next_at = 0, -1, NEVER
            return out
        if self._fed > _COMPACT_AT:
            del self._data[: self._fed]
            del self._ends[: self._fed]
            self._fed = 0
        j = self._data.find(_END, self._fed)
        self._idx, self.next_at = (j, self._ends[j]) if j >= 0 else (-1, NEVER)
        return out

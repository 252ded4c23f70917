"""Test doubles shared by the device-model tests."""

from __future__ import annotations


class SpyLink:
    """A device's transmit side that records what it sends, and when (each send ends at its start tick)."""

    def __init__(self) -> None:
        self.sent: list[tuple[bytes, int]] = []

    def transmit_to_mcu(self, data: bytes, start_cycles: int) -> list[int]:
        self.sent.append((data, start_cycles))
        return [start_cycles]

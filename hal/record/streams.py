"""The replay's comparison streams: the bytes each port carried, in the record and in the replay.

An output key is ``kind << 2 | port``; `port_name` names it, `item_bytes` gives the bytes an output item
stands for, and a `Stream` keeps the counts and SHA-256 of both sides. The module is compiled (setup.py's
COMPILED): every output of a replayed job is accounted here.
"""

from __future__ import annotations

import hashlib
from typing import Any, BinaryIO, Final

from hal.record.format import Kind
from hal.record.recorder import PORTS

__all__ = ["Stream", "item_bytes", "item_bytes_all", "port_name"]

_PORT_NAMES: Final = {v: k for k, v in PORTS.items()}
_OUTPUT_NAMES: Final = {Kind.ENC_SET: "encoder", Kind.LED: "led", Kind.KICK: "watchdog", Kind.CAN_TX: "can"}
_WRITE: Final = Kind.WRITE
_CAN_TX: Final = Kind.CAN_TX


def port_name(key: int) -> str:
    """The name of an output key (``kind << 2 | port``): motor, imu, telemetry, can, encoder, led, watchdog."""
    kind, port = key >> 2, key & 3
    return _PORT_NAMES[port] if kind == _WRITE else _OUTPUT_NAMES.get(kind, f"kind{kind}")


def item_bytes(key: int, item: Any) -> bytes:
    """The bytes an output item stands for in its port's stream (a write: the bytes the port accepted)."""
    kind = key >> 2
    if kind == _WRITE:
        accepted, data = item
        return data if accepted == len(data) else data[:accepted]
    if kind == _CAN_TX:
        ok, frame = item
        return bytes([ok, frame.extended]) + frame.arbitration_id.to_bytes(4, "little") + frame.data
    return repr(item).encode()


def item_bytes_all(key: int, items: list) -> bytes:
    """The bytes of a job's output items on one key, joined."""
    if len(items) == 1:
        return item_bytes(key, items[0])
    return b"".join([item_bytes(key, item) for item in items])


class Stream:
    """The bytes one port carried, in the record and in the replay: counts and SHA-256 (hashed ~64 KB at a time).

    `sink` (a binary file) receives the replayed bytes as they are hashed: the replay's telemetry.bin.
    """

    def __init__(self, sink: BinaryIO | None = None) -> None:
        """Empty; `sink` gets the replayed bytes."""
        self.expected_hash: Any = hashlib.sha256()
        self.produced_hash: Any = hashlib.sha256()
        self.expected = bytearray()
        self.produced = bytearray()
        self.expected_n = 0
        self.produced_n = 0
        self.sink = sink

    def flush(self) -> None:
        """Hash (and write to the sink) the pending bytes."""
        if self.expected:
            self.expected_hash.update(self.expected)
            self.expected = bytearray()
        if self.produced:
            self.produced_hash.update(self.produced)
            if self.sink is not None:
                self.sink.write(self.produced)
            self.produced = bytearray()

    def as_dict(self) -> dict:
        """Counts, digests and whether the replayed bytes are the recorded ones (flushes first)."""
        self.flush()
        same = self.expected_hash.digest() == self.produced_hash.digest() and self.expected_n == self.produced_n
        return {"recorded_items": self.expected_n, "replayed_items": self.produced_n, "identical": same,
                "recorded_sha256": self.expected_hash.hexdigest(), "replayed_sha256": self.produced_hash.hexdigest()}

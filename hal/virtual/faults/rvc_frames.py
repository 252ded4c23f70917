"""Rewriting UART-RVC frames on their way to the MCU (what the IMU frame faults share)."""

from __future__ import annotations

from collections.abc import Callable

from protocol.rvc import RvcFrame

__all__ = ["FRAME_BYTES", "rewrite_frames"]

FRAME_BYTES = 19


def rewrite_frames(data: bytes, fn: Callable[[RvcFrame], RvcFrame]) -> bytes:
    """data with every whole RVC frame replaced by fn(frame), re-encoded with its checksum; anything that is not a
    run of whole frames (the boot banner, a partial chunk) is passed unchanged."""
    if len(data) % FRAME_BYTES or not data.startswith(b"\xaa\xaa"):
        return data
    out = bytearray()
    for k in range(0, len(data), FRAME_BYTES):
        chunk = data[k:k + FRAME_BYTES]
        try:
            frame = RvcFrame.from_bytes(chunk)
        except ValueError:
            out += chunk
            continue
        out += fn(frame).encode()
    return bytes(out)

"""The input record's file format: a versioned header, then CRC-checked zlib chunks of events, then an end mark.

Layout (little endian)::

    b"PAFPREC\\0"  u16 version  u32 n  n bytes of JSON header (what was run: firmware config, tasks, ports)
                 u32 crc32(version, n and the header bytes)   (version 2; version 1 has no checksum)
    chunk*         u32 raw_len  u32 packed_len  u32 crc32(packed)  packed (zlib of raw_len bytes of events)
    end            u32 0  u32 0  u32 0  u32 n  n bytes of JSON footer (counts, how the run ended)

The header's checksum makes a flipped byte in it (a controller's or a task's name) a damaged record, not
another run. A chunk is about ``CHUNK_BYTES`` of events: memory stays bounded and a run that dies loses at
most the last chunk. An event is one tag byte (``kind << 2 | port``) and a fixed-size payload, or a u16 length and
that many bytes (`Event` below). A reader that meets a short or damaged chunk raises `RecordError` naming
the file offset, so ``pafp replay`` says where the record is bad in one line.
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO, Final

__all__ = ["CHUNK_BYTES", "MAGIC", "READS", "VERSION", "Kind", "RecordError", "read_header", "read_chunks",
           "write_header"]

MAGIC: Final = b"PAFPREC\0"
VERSION: Final = 2
READS: Final = (1, 2)
"""The versions this pafp reads: version 1 (no header checksum) as written before version 2."""
CHUNK_BYTES: Final = 1 << 16
_CHUNK = struct.Struct("<III")
_U32 = struct.Struct("<I")


class Kind:
    """Event kinds (the tag's upper six bits); the port number (0..3) is in its lower two bits."""

    JOB = 0  # <BQI: task id, start cycles, job index (a new section: the events after it belong to this job)
    READ = 1  # <H + bytes: what Uart.read returned
    IN_WAITING = 2  # <I
    TX_FREE = 3  # <I
    WRITE = 4  # <H accepted, <H + bytes: what the firmware wrote (an output: compared on replay)
    FLUSH = 5  # <B drained
    ERRORS = 6  # <5I overrun, framing, noise, tx_dropped, rx_lost
    ENC_CNT = 7  # <I
    ENC_DIR = 8  # <B
    ENC_SET = 9  # <I (an output)
    ESTOP = 10  # <B
    LED = 11  # <B (an output)
    KICK = 12  # no payload (an output)
    CLOCK = 13  # <Q: a reading of Board.now_cycles
    HEALTH = 14  # <II: the kernel's (deadline misses, current miss streak)
    RAISE = 15  # <B the kind of the call that raised, <H + utf-8 message (a HalError from the port)
    CAN_RX = 16  # <B flags (1 frame, 2 extended) <I id, <H + bytes
    CAN_TX = 17  # <B ok, <B extended, <I id, <H + bytes (an output)
    CAN_PENDING = 18  # <I
    CAN_FLUSH = 19  # <B drained


# fixed payload layouts; the kinds not listed carry a <H length and bytes after their fixed part
FIXED: Final = {Kind.JOB: struct.Struct("<BQI"), Kind.IN_WAITING: _U32, Kind.TX_FREE: _U32,
                Kind.FLUSH: struct.Struct("<B"), Kind.ERRORS: struct.Struct("<5I"), Kind.ENC_CNT: _U32,
                Kind.ENC_DIR: struct.Struct("<B"), Kind.ENC_SET: _U32, Kind.ESTOP: struct.Struct("<B"),
                Kind.LED: struct.Struct("<B"), Kind.KICK: struct.Struct(""), Kind.CLOCK: struct.Struct("<Q"),
                Kind.HEALTH: struct.Struct("<II"), Kind.CAN_PENDING: _U32, Kind.CAN_FLUSH: struct.Struct("<B")}
# kinds with a fixed part followed by <H length + bytes
VARIABLE: Final = {Kind.READ: struct.Struct(""), Kind.WRITE: struct.Struct("<H"), Kind.RAISE: struct.Struct("<B"),
                   Kind.CAN_RX: struct.Struct("<BI"), Kind.CAN_TX: struct.Struct("<BBI")}
LENGTH: Final = struct.Struct("<H")


class RecordError(ValueError):
    """The record cannot be read: names the file and the byte offset where it goes wrong."""


def write_header(f: BinaryIO, header: dict) -> None:
    """Write the magic, the version and the JSON header."""
    blob = json.dumps(header, sort_keys=True).encode("utf-8")
    lead = struct.pack("<HI", VERSION, len(blob))
    f.write(MAGIC + lead + blob + _U32.pack(zlib.crc32(lead + blob)))


def pack_chunk(raw: bytes, level: int = 1) -> bytes:
    """One chunk: its lengths, the CRC of the packed bytes, the packed bytes."""
    packed = zlib.compress(raw, level)
    return _CHUNK.pack(len(raw), len(packed), zlib.crc32(packed)) + packed


def pack_end(footer: dict) -> bytes:
    """The end mark and the JSON footer."""
    blob = json.dumps(footer, sort_keys=True).encode("utf-8")
    return _CHUNK.pack(0, 0, 0) + _U32.pack(len(blob)) + blob


def _exact(f: BinaryIO, n: int, path: Path, what: str) -> bytes:
    offset = f.tell()
    data = f.read(n)
    if len(data) != n:
        raise RecordError(f"record {path}: truncated at byte offset {offset}: {what} needs {n} bytes, "
                          f"{len(data)} left")
    return data


def read_header(f: BinaryIO, path: Path) -> dict:
    """Check the magic and version and return the JSON header (the file is left at the first chunk)."""
    magic = _exact(f, len(MAGIC), path, "the magic")
    if magic != MAGIC:
        raise RecordError(f"record {path}: not a pafp input record at byte offset 0 (magic {magic!r}, "
                          f"expected {MAGIC!r})")
    lead = _exact(f, 6, path, "the version and header length")
    version, n = struct.unpack("<HI", lead)
    if version not in READS:
        raise RecordError(f"record {path}: format version {version} at byte offset 8 not supported: this pafp reads "
                          f"versions {', '.join(map(str, READS))}")
    offset = f.tell()
    blob = _exact(f, n, path, "the header")
    if version >= 2:
        (crc,) = _U32.unpack(_exact(f, 4, path, "the header checksum"))
        if zlib.crc32(lead + blob) != crc:
            raise RecordError(f"record {path}: header at byte offset {offset} is damaged (checksum mismatch)")
    try:
        header = json.loads(blob.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RecordError(f"record {path}: header at byte offset {offset} is not JSON ({e})") from None
    if not isinstance(header, dict):
        raise RecordError(f"record {path}: header at byte offset {offset} is not a JSON object")
    return header


def read_chunks(f: BinaryIO, path: Path, footer: dict) -> Iterator[tuple[int, bytes]]:
    """(file offset, raw event bytes) of each chunk in order; at the end mark, fills `footer` and stops."""
    while True:
        offset = f.tell()
        raw_len, packed_len, crc = _CHUNK.unpack(_exact(f, _CHUNK.size, path, "a chunk header"))
        if raw_len == 0 and packed_len == 0:
            (n,) = _U32.unpack(_exact(f, 4, path, "the footer length"))
            try:
                footer.update(json.loads(_exact(f, n, path, "the footer").decode("utf-8")))
            except (UnicodeDecodeError, json.JSONDecodeError, TypeError, ValueError) as e:
                raise RecordError(f"record {path}: footer at byte offset {offset} is damaged ({e})") from None
            return
        packed = _exact(f, packed_len, path, f"the chunk starting at byte offset {offset}")
        if zlib.crc32(packed) != crc:
            raise RecordError(f"record {path}: chunk at byte offset {offset} is corrupted (CRC mismatch)")
        try:
            raw = zlib.decompress(packed)
        except zlib.error as e:
            raise RecordError(f"record {path}: chunk at byte offset {offset} is corrupted ({e})") from None
        if len(raw) != raw_len:
            raise RecordError(f"record {path}: chunk at byte offset {offset} holds {len(raw)} bytes, "
                              f"its header says {raw_len}")
        yield offset, raw

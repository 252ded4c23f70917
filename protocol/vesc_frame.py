"""VESC / CubeMars UART framing: CRC-16/XMODEM, frame encoder and a resynchronising streaming decoder.

Frame layout (PROTOCOLS.md A.1, vedderb/bldc ``comm/packet.c``)::

    short (payload 1..255):    02 | LEN            | PAYLOAD | CRC_HI CRC_LO | 03
    long  (payload 256..512):  03 | LEN_HI LEN_LO  | PAYLOAD | CRC_HI CRC_LO | 03

The CRC is CRC-16/XMODEM (poly 0x1021, init 0, no reflection) over the payload only, high byte first.
This module knows nothing about message meanings: :class:`FrameDecoder` hands each CRC-valid payload to a
per-command-id decode function given by the caller (see :mod:`protocol.vesc`).
"""

from __future__ import annotations

import binascii
import logging
import re
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Final, Generic, TypeVar

from mypy_extensions import mypyc_attr

__all__ = [
    "END_BYTE",
    "MAX_FRAME_LEN",
    "PACKET_MAX_PL_LEN",
    "START_LONG",
    "START_SHORT",
    "DecoderStats",
    "FrameDecoder",
    "ShortPayloadError",
    "crc16",
    "encode_frame",
]

_log: Final = logging.getLogger(__name__)

START_SHORT: Final = 0x02
"""Start byte of a frame with a one-byte length (payload 1..255 bytes)."""
START_LONG: Final = 0x03
"""Start byte of a frame with a two-byte length (payload 256..512 bytes)."""
END_BYTE: Final = 0x03
"""Last byte of every frame."""
PACKET_MAX_PL_LEN: Final = 512
"""Largest payload VESC >= 3.67 accepts (``comm/packet.h``)."""
MAX_FRAME_LEN: Final = PACKET_MAX_PL_LEN + 6
"""Largest frame on the wire: long header (3) + payload + CRC (2) + end byte (1)."""

_crc_hqx: Final = binascii.crc_hqx
_SHORT_HEAD: Final = struct.Struct(">BB")
_LONG_HEAD: Final = struct.Struct(">BH")
_SHORT_HEADS: Final = tuple(_SHORT_HEAD.pack(START_SHORT, n) for n in range(256))
"""Header of a short frame, indexed by payload length (index 0 unused)."""
_START_RE: Final = re.compile(b"[\x02\x03]")


def crc16(data: bytes) -> int:
    """Return the CRC-16/XMODEM of ``data`` (VESC ``crc16()``; the tests check it against crcmod).

    >>> hex(crc16(b"123456789"))
    '0x31c3'
    """
    return _crc_hqx(data, 0)


def encode_frame(payload: bytes) -> bytes:
    """Wrap ``payload`` (command id first) in a complete frame: start, length, payload, CRC, end byte.

    >>> encode_frame(bytes([4])).hex(" ")
    '02 01 04 40 84 03'
    """
    n = len(payload)
    if 0 < n <= 255:
        head = _SHORT_HEADS[n]
    elif 255 < n <= PACKET_MAX_PL_LEN:
        head = _LONG_HEAD.pack(START_LONG, n)
    else:
        raise ValueError(f"payload length {n} is outside the allowed range [1, {PACKET_MAX_PL_LEN}]")
    if type(payload) is not bytes:
        payload = bytes(payload)
    crc: int = _crc_hqx(payload, 0)
    return head + payload + (crc << 8 | END_BYTE).to_bytes(3, "big")  # CRC_HI CRC_LO 03


@mypyc_attr(native_class=False)  # a plain Python exception class in the compiled build (setup.py)
class ShortPayloadError(ValueError):
    """A payload is too short (or malformed) for its command id; the decoder counts and skips it."""


@dataclass
class DecoderStats:
    """Counters of a :class:`FrameDecoder`; bytes_in == frame bytes + dropped_bytes + buffered."""

    frames: int = 0
    """CRC-valid frames consumed (including unknown ids and short payloads)."""
    bytes_in: int = 0
    """Bytes fed to the decoder."""
    dropped_bytes: int = 0
    """Bytes discarded while resynchronising (not part of any CRC-valid frame)."""
    crc_errors: int = 0
    """Candidate frames with a correct end byte but a wrong CRC."""
    bad_end_bytes: int = 0
    """Candidate frames whose end byte was not 0x03 (checked before the CRC)."""
    unknown_ids: int = 0
    """CRC-valid frames with a command id this decoder has no message for (returned as Unknown)."""
    short_payloads: int = 0
    """CRC-valid frames whose payload was too short or malformed for their id (skipped)."""
    pending_skipped: int = 0
    """Pending candidate frames given up by :meth:`FrameDecoder.skip_pending` (an rx timeout)."""

    def as_dict(self) -> dict[str, int]:
        """Return the counters as a plain dict."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


M = TypeVar("M")


@mypyc_attr(allow_interpreted_subclasses=True)  # vesc.Decoder adds the message table
class FrameDecoder(Generic[M]):
    """Streaming VESC frame decoder: feed bytes in any chunking, get decoded messages out; never raises.

    Resynchronisation follows the VESC receiver (PROTOCOLS.md A.1): a 0x02 start with LEN 0, a 0x03 start
    with LEN < 255 or LEN > 512, a wrong end byte or a wrong CRC each drop ONE byte and the scan restarts at
    the next offset. A candidate frame that is not complete yet is kept until more bytes arrive (there is no
    inter-byte timeout, as in VESC >= 5.03), so at most one frame minus one byte, < ``MAX_FRAME_LEN``, is
    held between calls. The end byte is checked before the CRC (cheaper); a candidate failing both counts as
    a bad end byte.

    ``table`` maps a command id to a function turning the payload (command byte included) into a message;
    it may raise :class:`ShortPayloadError`, which is counted and the frame skipped. Ids missing from the
    table are handed to ``unknown(command_id, data)`` and counted in ``stats.unknown_ids``.
    """

    def __init__(
        self,
        table: Mapping[int, Callable[[bytes], M]],
        unknown: Callable[[int, bytes], M],
    ) -> None:
        """Create a decoder dispatching payloads through ``table`` (see the class docstring)."""
        self._unknown = unknown
        self._table: tuple[Callable[[bytes], M], ...] = tuple(
            table.get(i, self._decode_unknown) for i in range(256)
        )
        self._buf = b""
        self.stats = DecoderStats()

    def _decode_unknown(self, payload: bytes) -> M:
        """Table entry of every id without a decode function: count it and wrap it with ``unknown``."""
        self.stats.unknown_ids += 1
        return self._unknown(payload[0], bytes(payload[1:]))

    @property
    def buffered(self) -> int:
        """Number of bytes held back as the start of a possible frame (always < MAX_FRAME_LEN)."""
        return len(self._buf)

    def reset(self) -> None:
        """Forget any partially received frame (the dropped bytes are counted); keep the statistics."""
        self.stats.dropped_bytes += len(self._buf)
        self._buf = b""

    def skip_pending(self) -> list[M]:
        """Give up on the pending candidate frame: drop its start byte and rescan what follows.

        The receiver's timeout for a frame that never completes (VESC 3.x reset a half-received packet
        after ``PACKET_RX_TIMEOUT``; HEAD has none): a false header in line noise, e.g. ``03 01 FF``,
        would otherwise hold every good frame behind it until 511 more bytes have arrived. Dropping only
        the start byte, as for a bad CRC, keeps the frames that follow. Returns the messages they hold.

        >>> from protocol.vesc import Decoder, SetCurrent
        >>> d = Decoder("to-motor")
        >>> d.feed(bytes.fromhex("03 01 ff") + SetCurrent(2.5).encode())
        []
        >>> d.skip_pending(), d.stats.pending_skipped, d.buffered
        ([SetCurrent(current_a=2.5)], 1, 0)
        """
        if not self._buf:
            return []
        rest = self._buf[1:]
        self._buf = b""
        stats = self.stats
        stats.pending_skipped += 1
        stats.dropped_bytes += 1
        stats.bytes_in -= len(rest)  # fed again below: count each byte once
        return self.feed(rest)

    def feed(self, data: bytes | bytearray | memoryview) -> list[M]:
        """Consume ``data`` and return the messages of every complete valid frame, in stream order."""
        # Hot loop: literals instead of the module constants (2 = START_SHORT, 3 = START_LONG = END_BYTE,
        # 512 = PACKET_MAX_PL_LEN), counters in locals. A candidate frame whose header or end byte lies
        # beyond the buffer is not complete yet, which ends the scan.
        stats = self.stats
        stats.bytes_in += len(data)
        if self._buf:
            buf = self._buf + bytes(data)
        else:
            buf = data if type(data) is bytes else bytes(data)
        n = len(buf)
        pos = 0
        out: list[M] = []
        table = self._table
        crc = _crc_hqx
        dropped = crc_errors = bad_end = short = 0
        while pos < n:
            first = buf[pos]
            if first == 2:
                if pos + 1 >= n:
                    break
                start = pos + 2
                end = start + buf[pos + 1]
                if end == start:  # LEN 0
                    pos += 1
                    dropped += 1
                    continue
            elif first == 3:
                if pos + 2 >= n:
                    break
                length = (buf[pos + 1] << 8) | buf[pos + 2]
                if length < 255 or length > 512:
                    pos += 1
                    dropped += 1
                    continue
                start = pos + 3
                end = start + length
            else:
                match = _START_RE.search(buf, pos)
                nxt = match.start() if match is not None else len(buf)
                dropped += nxt - pos
                pos = nxt
                continue
            if end + 2 >= n:
                break
            # CRC over payload + its CRC is 0 exactly when they agree
            if buf[end + 2] != 3 or crc(buf[start : end + 2], 0):
                if buf[end + 2] != 3:
                    bad_end += 1
                else:
                    crc_errors += 1
                dropped += 1
                pos += 1
                continue
            pos = end + 3
            payload = buf[start:end]
            try:
                out.append(table[payload[0]](payload))
            except ShortPayloadError as exc:
                short += 1
                _log.debug("skipped frame: %s", exc)
        self._buf = buf[pos:] if pos else buf
        if out:
            stats.frames += len(out)
        if dropped:  # every CRC error and bad end byte also drops a byte
            stats.dropped_bytes += dropped
            stats.crc_errors += crc_errors
            stats.bad_end_bytes += bad_end
        if short:
            stats.frames += short
            stats.short_payloads += short
        return out

"""Telemetry framing, compiled (setup.py): CRC-16/CCITT-FALSE, COBS + delimiter, and the record framer.

The record layout itself (fields, versions, error explanations, decoding) is in
:mod:`protocol.telemetry`, which stays interpreted (docs/compiled.md, "Enum fields"); this
module is what the logger runs for every record.
"""

from __future__ import annotations

import binascii
import struct
from collections.abc import Callable
from typing import Final

from protocol.cobs import cobs_encode

__all__ = ["RecordFramer", "crc16", "frame_payload"]

_crc_hqx: Final = binascii.crc_hqx


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor).

    >>> hex(crc16(b"123456789"))
    '0x29b1'
    """
    return _crc_hqx(data, 0xFFFF)


def frame_payload(payload: bytes) -> bytes:
    """Frame a payload for the wire: COBS-encode it and append the 0x00 delimiter."""
    return cobs_encode(payload) + b"\x00"


class RecordFramer:
    """Frames one record given as its field values: header and fields packed by ``layout``, CRC, COBS, 0x00.

    ``explain(values)`` builds the ValueError for values ``layout`` cannot pack (wrong count, a value
    out of its wire type's range).
    """

    def __init__(
        self, layout: struct.Struct, version: int, field_count: int,
        explain: Callable[[tuple[object, ...]], ValueError],
    ) -> None:
        """Bind the struct of header (version, field count) and fields, and the error explanation."""
        self._pack = layout.pack
        self._version = version
        self._field_count = field_count
        self._explain = explain

    def frame(self, seq: object, time_cycles: object, values: tuple[object, ...]) -> bytes:
        """Return the wire frame of the record ``(seq, time_cycles, *values)``; ValueError if it cannot."""
        try:
            data = self._pack(self._version, self._field_count, seq, time_cycles, *values)
        except (struct.error, OverflowError, TypeError):
            raise self._explain((seq, time_cycles, *values)) from None
        crc: int = _crc_hqx(data, 0xFFFF)
        return frame_payload(data + crc.to_bytes(2, "little"))  # the CRC little-endian

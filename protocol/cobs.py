"""Consistent Overhead Byte Stuffing (Cheshire & Baker, IEEE/ACM ToN 1999): frames free of 0x00.

The encoded block is a run of groups ``code, data[code - 1]``; every group except one with code
0xFF (254 data bytes) and the last group stands for its data followed by one zero byte. The
encoded output never contains 0x00, so 0x00 can delimit frames on the wire. Overhead: one byte
per started 254 bytes of input.
"""

from __future__ import annotations

from typing import Final

from mypy_extensions import i64

_MAX_RUN: Final = 254


def cobs_encode(data: bytes) -> bytes:
    """Encode bytes so that the result holds no 0x00 (the delimiter is not appended).

    >>> cobs_encode(b"\\x11\\x00\\x22\\x33").hex(" ")
    '02 11 03 22 33'
    """
    n: i64 = len(data)
    if n < _MAX_RUN:  # no group can fill up: each zero becomes the code of the group after it
        out = bytearray(b"\x01" + data)  # out[k + 1] is data[k]; out[0] is the first group's code
        code_at: i64 = 0
        k: i64 = 0
        while k < n:
            if data[k] == 0:
                out[code_at] = k + 1 - code_at
                code_at = k + 1
            k += 1
        out[code_at] = n + 1 - code_at
        return bytes(out)
    segments = bytes(data).split(b"\x00")
    out = bytearray()
    last = len(segments) - 1
    for j, segment in enumerate(segments):
        full_runs = False
        while len(segment) >= _MAX_RUN:
            out.append(0xFF)
            out += segment[:_MAX_RUN]
            segment = segment[_MAX_RUN:]
            full_runs = True
        if j < last or segment or not full_runs:  # a final 0xFF group needs no empty group after it
            out.append(len(segment) + 1)
            out += segment
    return bytes(out)


def cobs_decode(encoded: bytes) -> bytes:
    """Invert cobs_encode (input without the delimiter); ValueError if it is not valid COBS.

    >>> cobs_decode(bytes.fromhex("02 11 03 22 33")).hex(" ")
    '11 00 22 33'
    """
    out = bytearray()
    i, n = 0, len(encoded)
    while i < n:
        code = encoded[i]
        end = i + code
        if code == 0:
            raise ValueError(f"COBS byte 0x00 at offset {i} is invalid: no 0x00 may occur inside a frame")
        if end > n:
            raise ValueError(f"COBS code 0x{code:02x} at offset {i} runs past the frame end ({n} bytes)")
        block = encoded[i + 1 : end]
        if 0 in block:
            raise ValueError(f"COBS group at offset {i} contains 0x00, which cannot occur inside a frame")
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)

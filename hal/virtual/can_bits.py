"""Bits of a CAN 2.0 data frame on the wire: exact bit stuffing of the actual bits, and the worst case.

A data frame is SOF, the arbitration field (standard: 11-bit ID, RTR, IDE, r0; extended: 11-bit base
ID, SRR, IDE, 18-bit extension, RTR, r1, r0), a 4-bit DLC, the data, a 15-bit CRC (polynomial 0x4599),
then a fixed tail: CRC delimiter, ACK slot and delimiter, 7-bit EOF, 3-bit intermission. From SOF to
the end of the CRC the transmitter inserts a complementary bit after five equal bits (the stuff bit
counts towards the next run). With 8 data bytes: standard 111 bits unstuffed, 135 at worst; extended
131 and 160 (PROTOCOLS.md G). :func:`frame_bits` counts the stuff bits of the frame's actual bits (the
virtual bus uses this); :func:`worst_case_bits` is the bound ``unstuffed + (stuffable - 1) // 4``.
"""

from __future__ import annotations

from typing import Final

__all__ = ["TAIL_BITS", "frame_bits", "stuffable_bits", "unstuffed_bits", "worst_case_bits"]

TAIL_BITS: Final = 13  # CRC delimiter 1, ACK 2, EOF 7, intermission 3


def _push(bits: list[int], value: int, n: int) -> None:
    for i in range(n - 1, -1, -1):
        bits.append((value >> i) & 1)


def _crc15(bits: list[int]) -> int:
    crc = 0
    for b in bits:
        nxt = b ^ ((crc >> 14) & 1)
        crc = (crc << 1) & 0x7FFF
        if nxt:
            crc ^= 0x4599
    return crc


def stuffable_bits(arbitration_id: int, data: bytes, extended: bool) -> list[int]:
    """SOF to the end of the CRC, before stuffing."""
    bits: list[int] = [0]
    if extended:
        _push(bits, arbitration_id >> 18, 11)
        bits += [1, 1]  # SRR, IDE
        _push(bits, arbitration_id & 0x3FFFF, 18)
        bits += [0, 0, 0]  # RTR, r1, r0
    else:
        _push(bits, arbitration_id, 11)
        bits += [0, 0, 0]  # RTR, IDE, r0
    _push(bits, len(data), 4)
    for byte in data:
        _push(bits, byte, 8)
    _push(bits, _crc15(bits), 15)
    return bits


def unstuffed_bits(n_data: int, extended: bool) -> int:
    """Bits of a frame with n_data bytes before stuffing (intermission included)."""
    return (39 if extended else 19) + 8 * n_data + 15 + TAIL_BITS


def worst_case_bits(n_data: int, extended: bool) -> int:
    """The most bits such a frame can take with stuffing."""
    stuffable = unstuffed_bits(n_data, extended) - TAIL_BITS
    return unstuffed_bits(n_data, extended) + (stuffable - 1) // 4


def frame_bits(arbitration_id: int, data: bytes, extended: bool) -> int:
    """Bits this exact frame takes on the wire: its stuff bits counted, intermission included."""
    bits = stuffable_bits(arbitration_id, data, extended)
    stuffed = 0
    run_bit, run = -1, 0
    for b in bits:
        if b == run_bit:
            run += 1
        else:
            run_bit, run = b, 1
        if run == 5:
            stuffed += 1
            run_bit, run = 1 - b, 1  # the stuff bit starts the next run
    return len(bits) + stuffed + TAIL_BITS

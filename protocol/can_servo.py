"""AK-series servo mode over CAN: 29-bit extended IDs, big-endian payloads, the periodic status frame.

PROTOCOLS.md G (CubeMars AK-series driver manual, CAN chapter, "servo mode"). A command's ID is
``(packet_id << 8) | driver_id``; its payload is big-endian: SET_DUTY int32 (duty x 100 000),
SET_CURRENT and SET_CURRENT_BRAKE int32 (mA), SET_RPM int32 (ERPM), SET_POS int32 (degrees x 10 000),
SET_ORIGIN_HERE uint8 (0 temporary, 1 permanent), SET_POS_SPD int32 position (degrees x 10 000), int16
speed, int16 acceleration (raw). Values outside a field's integer range saturate at it.

The motor sends, at its configured rate and whether or not a command arrived, an 8-byte status frame
with ID ``(0x29 << 8) | driver_id``: ``>hhhbB`` = position x 0.1 deg (motor side; the output angle
wraps within +-3200 deg), speed x 10 ERPM, current x 0.01 A, temperature deg C, error code (the UART
fault code table).

No import from the rest of pafp: the codec stands alone (firmware, device models and host tools use it).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Final

__all__ = [
    "STATUS_PACKET", "PacketId", "ServoCommand", "ServoStatus", "command_id", "decode_command",
    "decode_status", "encode_command", "encode_status", "split_id", "status_id",
]

STATUS_PACKET: Final = 0x29
_STATUS = struct.Struct(">hhhbB")
_I32 = struct.Struct(">i")
_POS_SPD = struct.Struct(">ihh")
_I32_MIN, _I32_MAX = -(1 << 31), (1 << 31) - 1


class PacketId(IntEnum):
    """The servo-mode command packets (the high bits of the extended ID)."""

    SET_DUTY = 0
    SET_CURRENT = 1
    SET_CURRENT_BRAKE = 2
    SET_RPM = 3
    SET_POS = 4
    SET_ORIGIN_HERE = 5
    SET_POS_SPD = 6


_SCALE: Final = {PacketId.SET_DUTY: 100_000.0, PacketId.SET_CURRENT: 1000.0, PacketId.SET_CURRENT_BRAKE: 1000.0,
                 PacketId.SET_RPM: 1.0, PacketId.SET_POS: 10_000.0}
"""Raw = round(value x scale): duty, current in A (mA on the wire), ERPM, position in degrees."""


def _sat(x: float, lo: int, hi: int) -> int:
    if math.isnan(x):
        return 0
    return int(round(max(lo, min(hi, x))))


def command_id(packet: int, driver_id: int) -> int:
    """The 29-bit ID of a command packet to driver_id (0..255)."""
    if not 0 <= driver_id <= 0xFF:
        raise ValueError(f"driver_id {driver_id!r} out of range 0..255")
    return (int(packet) << 8) | driver_id


def status_id(driver_id: int) -> int:
    """The 29-bit ID of driver_id's status frames."""
    return command_id(STATUS_PACKET, driver_id)


def split_id(arbitration_id: int) -> tuple[int, int]:
    """(packet_id, driver_id) of a 29-bit ID."""
    return arbitration_id >> 8, arbitration_id & 0xFF


@dataclass(frozen=True)
class ServoCommand:
    """A decoded command: its packet, the value in SI-ish units (A, duty, ERPM, deg), speed/accel raw."""

    packet: PacketId
    value: float
    speed: int = 0
    accel: int = 0


def encode_command(packet: PacketId, value: float, speed: float = 0.0, accel: float = 0.0) -> bytes:
    """The payload of a command (value in A, duty, ERPM or degrees; saturated at the field's range)."""
    if packet == PacketId.SET_ORIGIN_HERE:
        return bytes((_sat(value, 0, 1),))
    if packet == PacketId.SET_POS_SPD:
        return _POS_SPD.pack(_sat(value * 10_000.0, _I32_MIN, _I32_MAX), _sat(speed, -32768, 32767),
                             _sat(accel, -32768, 32767))
    return _I32.pack(_sat(value * _SCALE[packet], _I32_MIN, _I32_MAX))


def decode_command(arbitration_id: int, data: bytes) -> ServoCommand:
    """The command in a frame (ValueError for an unknown packet or a payload of the wrong length)."""
    packet_raw = arbitration_id >> 8
    try:
        packet = PacketId(packet_raw)
    except ValueError:
        raise ValueError(f"servo packet id {packet_raw} unknown: 0..6") from None
    want = 1 if packet == PacketId.SET_ORIGIN_HERE else (8 if packet == PacketId.SET_POS_SPD else 4)
    if len(data) < want:
        raise ValueError(f"{packet.name} needs {want} data bytes, got {len(data)}")
    if packet == PacketId.SET_ORIGIN_HERE:
        return ServoCommand(packet, float(data[0]))
    if packet == PacketId.SET_POS_SPD:
        pos, spd, acc = _POS_SPD.unpack_from(data)
        return ServoCommand(packet, pos / 10_000.0, spd, acc)
    return ServoCommand(packet, _I32.unpack_from(data)[0] / _SCALE[packet])


@dataclass(frozen=True)
class ServoStatus:
    """A status frame: position (deg, motor side), speed (ERPM), current (A), temperature (deg C), error."""

    position_deg: float
    speed_erpm: float
    current_a: float
    temperature_c: int = 0
    error: int = 0


def encode_status(s: ServoStatus) -> bytes:
    """The 8-byte status payload (each field saturated at its integer range)."""
    return _STATUS.pack(_sat(s.position_deg * 10.0, -32768, 32767), _sat(s.speed_erpm / 10.0, -32768, 32767),
                        _sat(s.current_a * 100.0, -32768, 32767), _sat(s.temperature_c, -128, 127),
                        _sat(s.error, 0, 255))


def decode_status(data: bytes) -> ServoStatus:
    """The status in 8 data bytes (ValueError for another length)."""
    if len(data) != 8:
        raise ValueError(f"servo status has {len(data)} data bytes, not 8")
    pos, spd, cur, temp, err = _STATUS.unpack(data)
    return ServoStatus(pos / 10.0, spd * 10.0, cur / 100.0, temp, err)

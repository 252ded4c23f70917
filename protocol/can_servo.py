"""AK-series servo mode over CAN: 29-bit extended IDs, big-endian payloads, the periodic status frame.

CubeMars AK Series Actuator Driver Manual V1.0.8, section 5.1 "Servo mode" (pp. 32-39) and 5.2.1 (p. 39);
PROTOCOLS.md G. A command's ID is ``(packet_id << 8) | driver_id`` (ID bits 28..8: the control mode, 7..0: the
driver id); its payload is big-endian:

=================  =======================================================================================
packet             payload (manual section)
=================  =======================================================================================
0 SET_DUTY         int32 duty x 100 000 (5.1.1)
1 SET_CURRENT      int32 mA (5.1.2)
2 SET_CURRENT_BRAKE int32 mA (5.1.3)
3 SET_RPM          int32 ERPM, +-100 000 (5.1.4)
4 SET_POS          int32 degrees x 10 000, +-36 000 deg (5.1.5; the drive's own speed 12 000 ERPM and
                   acceleration 40 000 ERPM/s, 5.1)
5 SET_ORIGIN_HERE  uint8: 0 temporary origin, 1 permanent zero, 2 restore the default zero (5.1.6)
6 SET_POS_SPD      int32 degrees x 10 000, int16 speed in units of 10 ERPM, int16 acceleration in units of
                   10 ERPM/s (5.1.7: the routine appends ``spd / 10`` and ``RPA / 10``)
=================  =======================================================================================

Values outside a field's integer range saturate at it. Any other packet id (opensourceleg sends a "mode switch"
on packet 7, which the manual does not define) is :class:`UnknownPacket`, a ValueError a decoder counts and skips.
The MIT-mode special frames (``FF x7 FC/FD/FE``, manual 5.3) that clients also send to a servo-mode drive, on
the extended ID ``driver_id`` (packet 0), are recognised by :func:`special_frame` before decoding.

The motor sends, at its configured rate (1..500 Hz, set in the maker's tool: 5.2.1) and whether or not a command
arrived, an 8-byte status frame with ID ``(0x29 << 8) | driver_id``: ``>hhhbB`` = position x 0.1 deg (motor side;
the output angle wraps within +-3200 deg), speed x 10 ERPM, current x 0.01 A, temperature deg C (int8), error
code (uint8, the manual's servo-mode table :class:`ErrorCode`, 5.2.1).

No import from outside protocol/: the codec stands alone (firmware, device models and host tools use it).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Final

from protocol import can_mit

__all__ = [
    "STATUS_HZ_MAX", "STATUS_HZ_MIN", "STATUS_PACKET", "ErrorCode", "PacketId", "ServoCommand", "ServoStatus",
    "UnknownPacket", "command_id", "decode_command", "decode_status", "encode_command", "encode_status",
    "error_code", "special_frame", "split_id", "status_id",
]

STATUS_PACKET: Final = 0x29
STATUS_HZ_MIN: Final = 1
STATUS_HZ_MAX: Final = 500
"""The status frame's upload rate, as the drive can be configured (manual 5.2.1)."""
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


class ErrorCode(IntEnum):
    """The error code of the servo-mode status frame (manual 5.2.1, p. 39)."""

    NONE = 0
    OVER_TEMPERATURE = 1
    OVER_CURRENT = 2
    OVER_VOLTAGE = 3
    UNDER_VOLTAGE = 4
    ENCODER = 5
    PHASE_CURRENT_UNBALANCE = 6


_FROM_VESC: Final = {1: ErrorCode.OVER_VOLTAGE, 2: ErrorCode.UNDER_VOLTAGE, 3: ErrorCode.OVER_CURRENT,
                     4: ErrorCode.OVER_CURRENT, 5: ErrorCode.OVER_TEMPERATURE, 6: ErrorCode.OVER_TEMPERATURE,
                     7: ErrorCode.OVER_VOLTAGE, 8: ErrorCode.UNDER_VOLTAGE, 9: ErrorCode.UNDER_VOLTAGE,
                     11: ErrorCode.ENCODER, 12: ErrorCode.ENCODER, 13: ErrorCode.ENCODER,
                     18: ErrorCode.PHASE_CURRENT_UNBALANCE}


def error_code(vesc_fault: int) -> int:
    """The status frame's error code for a VESC ``mc_fault_code`` (the UART's table, PROTOCOLS.md B.7).

    DRV and gate-driver faults map to the nearest name (over current, over/under voltage); faults the CAN table
    has no name for (watchdog reset, flash corruption, current-sensor offsets: VESC 10, 14-17) keep their VESC
    number, above 6, so that a client still sees a non-zero error.

    >>> error_code(0), error_code(6), error_code(4), error_code(2), error_code(14)
    (0, 1, 2, 4, 14)
    """
    if vesc_fault == 0:
        return 0
    return int(_FROM_VESC.get(vesc_fault, vesc_fault))


class UnknownPacket(ValueError):
    """A servo-mode command packet id the manual does not define (counted and ignored by decoders)."""


def special_frame(arbitration_id: int, data: bytes) -> str:
    """'enter', 'exit' or 'zero' for a MIT-mode special frame sent on the extended ID ``driver_id`` (packet 0),
    '' for anything else (a real SET_DUTY has 4 data bytes)."""
    if arbitration_id >> 8:
        return ""
    return can_mit.special_frame(data)


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
    """A decoded command: its packet, the value (A, duty, ERPM, degrees, origin mode); SET_POS_SPD's speed (ERPM)
    and acceleration (ERPM/s)."""

    packet: PacketId
    value: float
    speed_erpm: float = 0.0
    accel_erpm_s: float = 0.0


def encode_command(packet: PacketId, value: float, speed_erpm: float = 0.0, accel_erpm_s: float = 0.0) -> bytes:
    """The payload of a command (value in A, duty, ERPM, degrees or origin mode; saturated at the field's range)."""
    if packet == PacketId.SET_ORIGIN_HERE:
        return bytes((_sat(value, 0, 2),))
    if packet == PacketId.SET_POS_SPD:
        return _POS_SPD.pack(_sat(value * 10_000.0, _I32_MIN, _I32_MAX), _sat(speed_erpm / 10.0, -32768, 32767),
                             _sat(accel_erpm_s / 10.0, -32768, 32767))
    return _I32.pack(_sat(value * _SCALE[packet], _I32_MIN, _I32_MAX))


def decode_command(arbitration_id: int, data: bytes) -> ServoCommand:
    """The command in a frame (UnknownPacket for a packet id outside 0..6, ValueError for a short payload)."""
    packet_raw = arbitration_id >> 8
    try:
        packet = PacketId(packet_raw)
    except ValueError:
        raise UnknownPacket(f"servo packet id {packet_raw} unknown: 0..6") from None
    want = 1 if packet == PacketId.SET_ORIGIN_HERE else (8 if packet == PacketId.SET_POS_SPD else 4)
    if len(data) < want:
        raise ValueError(f"{packet.name} needs {want} data bytes, got {len(data)}")
    if packet == PacketId.SET_ORIGIN_HERE:
        return ServoCommand(packet, float(data[0]))
    if packet == PacketId.SET_POS_SPD:
        pos, spd, acc = _POS_SPD.unpack_from(data)
        return ServoCommand(packet, pos / 10_000.0, spd * 10.0, acc * 10.0)
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

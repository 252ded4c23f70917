"""CubeMars AK60-6 servo-mode UART messages (VESC packets) in SI units, both directions, and the Decoder.

Every message is a frozen dataclass with ``COMMAND_ID``, ``payload()``, ``encode()`` (the whole frame) and
``from_payload(payload)``. Units: currents A (``current_a``), duty and relative current as fractions,
speeds as electrical RPM (``erpm``, an int on the wire), angles in **radians** in the API and degrees on the
wire (``position_rad``; ``from_degrees`` constructors are offered), temperatures degC, voltages V.
Encoding truncates toward zero like the firmware's C cast (see :mod:`protocol.vesc_message`);
a value the wire cannot carry raises ValueError naming the value and the range.

>>> SetCurrent(2.5).encode().hex(" ")
'02 05 06 00 00 09 c4 ee d5 03'
>>> Decoder("to-motor").feed(bytes.fromhex("02 05 06 00 00 09 C4 EE D5 03"))
[SetCurrent(current_a=2.5)]

Framing, CRC and the streaming machinery live in :mod:`protocol.vesc_frame`, the GET_VALUES
layout in :mod:`protocol.vesc_values`; everything public is re-exported here.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, ClassVar, Literal, Self

from protocol.vesc_frame import (
    MAX_FRAME_LEN,
    PACKET_MAX_PL_LEN,
    DecoderStats,
    FrameDecoder,
    ShortPayloadError,
    crc16,
    encode_frame,
)
from protocol.vesc_message import CommandId, Message, Unknown, WireField, field_setter, to_raw
from protocol.vesc_values import FIELDS, VALUES_FIELDS, FaultCode, Values, ValuesSelective

__all__ = [
    "FIELDS", "Direction", "MAX_FRAME_LEN", "MESSAGES_FROM_MOTOR", "MESSAGES_TO_MOTOR", "PACKET_MAX_PL_LEN",
    "VALUES_FIELDS", "Alive", "CommandId", "Decoder", "DecoderStats", "DetectMode", "FaultCode",
    "FwVersion", "GetFwVersion", "GetValues", "GetValuesSelective", "GetValuesSetup", "Message", "OriginMode",
    "RotorPosition", "SetCurrent", "SetCurrentBrake", "SetCurrentRel", "SetDetect", "SetDuty",
    "SetHandbrake", "SetPos", "SetPosMulti", "SetPosOrigin", "SetPosSingle", "SetPosSpd", "SetRpm",
    "ShortPayloadError", "Unknown", "Values", "ValuesSelective", "WireField", "crc16", "encode_frame",
]

Direction = Literal["to-motor", "from-motor"]
_INT32 = struct.Struct(">i")


class DetectMode(IntEnum):
    """SET_DETECT argument (VESC ``disp_pos_mode``); PID_POS makes the driver stream ROTOR_POSITION."""

    NONE = 0
    INDUCTANCE = 1
    OBSERVER = 2
    ENCODER = 3
    PID_POS = 4
    PID_POS_ERROR = 5
    ENCODER_OBSERVER_ERROR = 6
    HALL_OBSERVER_ERROR = 7


class OriginMode(IntEnum):
    """SET_POS_ORIGIN argument (CubeMars): temporary origin, permanent (saved) zero, restore default zero."""

    TEMPORARY = 0
    PERMANENT = 1
    RESTORE_DEFAULT = 2


# --- host -> motor ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class GetFwVersion(Message):
    """COMM_FW_VERSION request (0), no arguments."""

    COMMAND_ID: ClassVar[int] = CommandId.FW_VERSION


@dataclass(frozen=True, slots=True)
class GetValues(Message):
    """COMM_GET_VALUES request (4), no arguments; the motor answers with :class:`Values`."""

    COMMAND_ID: ClassVar[int] = CommandId.GET_VALUES


@dataclass(frozen=True, slots=True)
class Alive(Message):
    """COMM_ALIVE (30), no arguments: resets the driver's command timeout."""

    COMMAND_ID: ClassVar[int] = CommandId.ALIVE


@dataclass(frozen=True, slots=True)
class SetDuty(Message):
    """COMM_SET_DUTY (5): duty cycle as a fraction (-1..1); wire int32 x 100000."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_DUTY
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("duty", "i", 100_000),)
    duty: float


@dataclass(frozen=True, slots=True)
class SetCurrent(Message):
    """COMM_SET_CURRENT (6): q-axis current in A; wire int32 mA."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_CURRENT
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("current_a", "i", 1000),)
    current_a: float


@dataclass(frozen=True, slots=True)
class SetCurrentBrake(Message):
    """COMM_SET_CURRENT_BRAKE (7): braking current in A; wire int32 mA."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_CURRENT_BRAKE
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("current_a", "i", 1000),)
    current_a: float


@dataclass(frozen=True, slots=True)
class SetRpm(Message):
    """COMM_SET_RPM (8): speed in electrical RPM (mechanical RPM x pole pairs); wire int32."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_RPM
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("erpm", "i", 1),)
    erpm: int


@dataclass(frozen=True, slots=True)
class SetPos(Message):
    """COMM_SET_POS (9): position in rad; wire int32 degrees x 1e6 (90 deg = pi/2 -> 05 5D 4A 80)."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_POS
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("position_rad", "i", 1_000_000, angle=True),)
    position_rad: float

    @classmethod
    def from_degrees(cls, position_deg: float) -> Self:
        """Build the command from a position in degrees."""
        return cls(math.radians(position_deg))


@dataclass(frozen=True, slots=True)
class SetHandbrake(Message):
    """COMM_SET_HANDBRAKE (10): handbrake current in A; wire int32 mA."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_HANDBRAKE
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("current_a", "i", 1000),)
    current_a: float


@dataclass(frozen=True, slots=True)
class SetDetect(Message):
    """COMM_SET_DETECT (11): uint8 display-position mode (:class:`DetectMode`; 4 = stream position)."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_DETECT
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("mode", "B", 1),)
    mode: int


@dataclass(frozen=True, slots=True)
class GetValuesSelective(Message):
    """COMM_GET_VALUES_SELECTIVE request (50, CubeMars GET_VALUES_SETUP): uint32 mask of FIELDS bits."""

    COMMAND_ID: ClassVar[int] = CommandId.GET_VALUES_SELECTIVE
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("mask", "I", 1),)
    mask: int


@dataclass(frozen=True, slots=True)
class SetCurrentRel(Message):
    """COMM_SET_CURRENT_REL (84): current as a fraction of the configured maximum; wire int32 x 1e5."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_CURRENT_REL
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("current_rel", "i", 100_000),)
    current_rel: float


@dataclass(frozen=True, slots=True)
class SetPosSpd(Message):
    """CubeMars SET_POS_SPD (91): position rad (wire deg x 1000), speed ERPM, acceleration ERPM/s; int32s."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_POS_SPD
    _WIRE: ClassVar[tuple[WireField, ...]] = (
        WireField("position_rad", "i", 1000, angle=True),
        WireField("erpm", "i", 1),
        WireField("accel_erpm_per_s", "i", 1),
    )
    position_rad: float
    erpm: int
    accel_erpm_per_s: int

    @classmethod
    def from_degrees(cls, position_deg: float, erpm: int, accel_erpm_per_s: int) -> Self:
        """Build the command from a position in degrees."""
        return cls(math.radians(position_deg), erpm, accel_erpm_per_s)


@dataclass(frozen=True, slots=True)
class SetPosMulti(Message):
    """CubeMars SET_POS_MULTI (92): select multi-turn (+-100 turns) position mode; 4 reserved bytes (0)."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_POS_MULTI
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("reserved", "I", 1),)
    reserved: int = 0


@dataclass(frozen=True, slots=True)
class SetPosSingle(Message):
    """CubeMars SET_POS_SINGLE (93): select single-turn (0..360 deg) position mode; 4 reserved bytes (0)."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_POS_SINGLE
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("reserved", "I", 1),)
    reserved: int = 0


@dataclass(frozen=True, slots=True)
class SetPosOrigin(Message):
    """CubeMars SET_POS_ORIGIN (95): uint8 :class:`OriginMode` (0 temporary, 1 permanent, 2 default)."""

    COMMAND_ID: ClassVar[int] = CommandId.SET_POS_ORIGIN
    _WIRE: ClassVar[tuple[WireField, ...]] = (WireField("mode", "B", 1),)
    mode: int


# --- motor -> host (Values and ValuesSelective are in vesc_values) ------------------------------------


@dataclass(frozen=True, slots=True)
class RotorPosition(Message):
    """COMM_ROTOR_POSITION (22) streamed after SET_DETECT 4: position rad; wire int32 degrees x ``scale``.

    CubeMars uses scale 1e4 (PROTOCOLS.md B.5), VESC 1e5; ``scale`` is not sent.
    """

    COMMAND_ID: ClassVar[int] = CommandId.ROTOR_POSITION
    position_rad: float
    scale: float = 1e4

    def payload(self) -> bytes:
        """Return the payload: id 22, int32 of degrees x scale (truncated)."""
        _check_scale(self.scale)
        raw = to_raw(self.position_rad, self.scale * 180.0 / math.pi, "i", "position_rad", False)
        return bytes((self.COMMAND_ID,)) + raw.to_bytes(4, "big", signed=True)

    @classmethod
    def from_payload(cls, payload: bytes, scale: float = 1e4) -> Self:
        """Decode a payload with the given wire scale; ShortPayloadError when shorter than 5 bytes."""
        return cls.payload_decoder(scale)(payload)

    @classmethod
    def payload_decoder(cls, scale: float = 1e4) -> Callable[[bytes], Self]:
        """Return a fast payload decoder for the wire scale ``scale`` (used by :class:`Decoder`)."""
        _check_scale(scale)
        divisor = scale * 180.0 / math.pi
        unpack = _INT32.unpack_from
        new = object.__new__
        set_position = field_setter(cls, "position_rad")
        set_scale = field_setter(cls, "scale")

        def decode(payload: bytes) -> Any:
            try:
                (raw,) = unpack(payload, 1)
            except struct.error:
                raise ShortPayloadError(f"RotorPosition needs 5 payload bytes, got {len(payload)}") from None
            obj = new(cls)
            set_position(obj, raw / divisor)
            set_scale(obj, scale)
            return obj

        return decode

    @classmethod
    def from_degrees(cls, position_deg: float, scale: float = 1e4) -> Self:
        """Build the message from a position in degrees."""
        return cls(math.radians(position_deg), scale)


def _check_scale(scale: float) -> None:
    """Raise ValueError unless ``scale`` is a usable ROTOR_POSITION wire scale (finite, > 0)."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale={scale!r} must be finite and > 0")


@dataclass(frozen=True, slots=True)
class FwVersion(Message):
    """COMM_FW_VERSION reply (0), short 3.x form: major, minor, NUL-terminated hw name, 12-byte UUID.

    ``hw_name`` is Latin-1 text without NUL; ``extra`` keeps any later-firmware trailing bytes verbatim.
    """

    COMMAND_ID: ClassVar[int] = CommandId.FW_VERSION
    major: int
    minor: int
    hw_name: str
    uuid: bytes = bytes(12)
    extra: bytes = b""

    def payload(self) -> bytes:
        """Return the payload: id 0, major, minor, hw name, NUL, UUID, extra."""
        for name, value in (("major", self.major), ("minor", self.minor)):
            if not 0 <= value <= 255:
                raise ValueError(f"{name}={value!r} is outside the uint8 range [0, 255]")
        if "\0" in self.hw_name or any(ord(c) > 255 for c in self.hw_name):
            raise ValueError(f"hw_name={self.hw_name!r} must be Latin-1 without NUL (code points 1-255)")
        if len(self.uuid) != 12:
            raise ValueError(f"uuid length {len(self.uuid)} must be exactly 12 bytes")
        raw_name = self.hw_name.encode("latin-1")
        return bytes((self.COMMAND_ID, self.major, self.minor)) + raw_name + b"\0" + bytes(self.uuid) + self.extra

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode a reply; ShortPayloadError when the name is not NUL-terminated or the UUID is cut short."""
        nul = payload.find(0, 3)
        if len(payload) < 3 or nul < 0 or len(payload) < nul + 13:
            raise ShortPayloadError(f"FwVersion payload ({len(payload)} bytes) lacks the NUL or 12-byte UUID")
        name = bytes(payload[3:nul]).decode("latin-1")
        uuid = bytes(payload[nul + 1 : nul + 13])
        return cls(payload[1], payload[2], name, uuid, bytes(payload[nul + 13 :]))


GetValuesSetup = GetValuesSelective
"""CubeMars name of id 50 (``COMM_GET_VALUES_SETUP``); VESC's own GET_VALUES_SETUP is id 47."""

MESSAGES_TO_MOTOR: dict[int, type[Message]] = {
    cls.COMMAND_ID: cls
    for cls in (GetFwVersion, GetValues, SetDuty, SetCurrent, SetCurrentBrake, SetRpm, SetPos, SetHandbrake,
                SetDetect, Alive, GetValuesSelective, SetCurrentRel, SetPosSpd, SetPosMulti, SetPosSingle,
                SetPosOrigin)
}
"""Message class of every command id the host sends (id 22 has no request: Unknown in this direction)."""

MESSAGES_FROM_MOTOR: dict[int, type[Message]] = {
    cls.COMMAND_ID: cls for cls in (FwVersion, Values, RotorPosition, ValuesSelective)
}
"""Message class of every command id the motor sends."""


class Decoder(FrameDecoder[Message]):
    """Streaming decoder for one direction of the link: ``feed(bytes) -> list[Message]``, never raises.

    Id 0/4/50 are requests towards the motor and replies from it; id 22 exists only from the motor.
    ``rotor_position_scale`` is the wire scale of ROTOR_POSITION; with ``selective_mask_echo`` False the
    selective reply carries no mask, so set ``selective_mask`` to the mask last requested (until then such
    a reply is returned as :class:`Unknown` and counted in ``stats.unknown_ids``). See
    :class:`~protocol.vesc_frame.FrameDecoder` for resynchronisation and statistics.
    """

    def __init__(
        self,
        direction: Direction,
        rotor_position_scale: float = 1e4,
        selective_mask_echo: bool = True,
        selective_mask: int | None = None,
    ) -> None:
        """Create a decoder for ``direction`` ("to-motor" or "from-motor")."""
        if direction not in ("to-motor", "from-motor"):
            raise ValueError(f"direction={direction!r} must be 'to-motor' or 'from-motor'")
        self.direction: Direction = direction
        _check_scale(rotor_position_scale)
        self.rotor_position_scale = float(rotor_position_scale)
        self.selective_mask_echo = selective_mask_echo
        self.selective_mask = selective_mask
        if direction == "to-motor":
            table = {cid: cls.payload_decoder() for cid, cls in MESSAGES_TO_MOTOR.items()}
        else:
            table = {cid: cls.payload_decoder() for cid, cls in MESSAGES_FROM_MOTOR.items()}
            table[CommandId.ROTOR_POSITION] = RotorPosition.payload_decoder(rotor_position_scale)
            if not selective_mask_echo:
                table[CommandId.GET_VALUES_SELECTIVE] = self._selective_without_echo
        super().__init__(table, Unknown)

    def _selective_without_echo(self, payload: bytes) -> Message:
        """Decode a selective reply without mask echo using ``selective_mask``."""
        if self.selective_mask is None:
            self.stats.unknown_ids += 1
            return Unknown(payload[0], bytes(payload[1:]))
        return ValuesSelective.from_payload(payload, self.selective_mask)

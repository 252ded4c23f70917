"""Building blocks of VESC messages: command ids, scaled wire fields, the Message base class, Unknown.

Scaling (PROTOCOLS.md A.3): the firmware sends ``int32(value * scale)`` (or int16/uint8), a C cast, i.e.
**truncation toward zero**, and reads ``raw / scale``. :class:`WireField` does the same in SI units, with one
deliberate refinement: a product within 4 ulp of an integer is taken as that integer. Without it float noise
would truncate an intended integer down by one (``(1750531 / 1e4) * 1e4`` may come out as 1750530.9999999998),
so values decoded from the wire would not re-encode to the same bytes; genuine fractions are truncated
(2.4999 A -> 2499 mA, -2.4999 A -> -2499 mA). Angles are radians in the API and degrees on the wire: the
divisor of an angle field is ``scale * 180 / pi`` (one multiplication each way).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum
from operator import truediv
from typing import Any, ClassVar, Self

from firmware.protocol.vesc_frame import ShortPayloadError, encode_frame

__all__ = ["CommandId", "Message", "Unknown", "WireField"]

_RANGES: dict[str, tuple[int, int, str]] = {
    "b": (-(1 << 7), (1 << 7) - 1, "int8"),
    "B": (0, (1 << 8) - 1, "uint8"),
    "h": (-(1 << 15), (1 << 15) - 1, "int16"),
    "H": (0, (1 << 16) - 1, "uint16"),
    "i": (-(1 << 31), (1 << 31) - 1, "int32"),
    "I": (0, (1 << 32) - 1, "uint32"),
}
_SNAP_ULPS = 4.0


class CommandId(IntEnum):
    """Command ids (payload byte 0) used by the CubeMars servo-mode UART protocol (PROTOCOLS.md B.1)."""

    FW_VERSION = 0
    GET_VALUES = 4
    SET_DUTY = 5
    SET_CURRENT = 6
    SET_CURRENT_BRAKE = 7
    SET_RPM = 8
    SET_POS = 9
    SET_HANDBRAKE = 10
    SET_DETECT = 11
    ROTOR_POSITION = 22
    ALIVE = 30
    GET_VALUES_SELECTIVE = 50
    SET_CURRENT_REL = 84
    SET_POS_SPD = 91
    SET_POS_MULTI = 92
    SET_POS_SINGLE = 93
    SET_POS_ORIGIN = 95


def to_raw(value: float, divisor: float, code: str, name: str, is_int: bool) -> int:
    """Return the wire integer for ``value`` (truncated toward zero, see module doc) or raise ValueError."""
    lo, hi, ctype = _RANGES[code]
    if is_int and isinstance(value, int):
        raw = int(value)
    else:
        try:
            x = float(value) * divisor
        except (TypeError, ValueError):
            raise ValueError(f"{name}={value!r} is not a number") from None
        if not math.isfinite(x):
            raise ValueError(f"{name}={value!r} is not finite; allowed [{lo / divisor:g}, {hi / divisor:g}]")
        raw = int(x)
        nearest = round(x)
        if nearest != raw and abs(x - nearest) <= _SNAP_ULPS * math.ulp(x):
            raw = nearest
    if raw < lo or raw > hi:
        scale = f" x {divisor:g}" if divisor != 1.0 else ""
        raise ValueError(
            f"{name}={value!r} is outside the wire range [{lo / divisor:g}, {hi / divisor:g}] "
            f"({ctype} of the value{scale})"
        )
    return raw


@dataclass(frozen=True, slots=True)
class WireField:
    """One field on the wire: name, struct code, value = raw / scale (angles: deg on wire, rad in API)."""

    name: str
    code: str
    scale: float = 1.0
    angle: bool = False
    bit: int | None = None

    @property
    def divisor(self) -> float:
        """Raw units per API unit (``scale``, times 180/pi for an angle field)."""
        return self.scale * 180.0 / math.pi if self.angle else float(self.scale)

    @property
    def is_int(self) -> bool:
        """True when the API value is the raw integer itself (scale 1, not an angle)."""
        return self.scale == 1 and not self.angle

    def to_raw(self, value: float) -> int:
        """Return the wire integer for ``value``; ValueError naming value and range if it does not fit."""
        return to_raw(value, self.divisor, self.code, self.name, self.is_int)

    def from_raw(self, raw: int) -> float | int:
        """Return the API value of the wire integer ``raw``."""
        return raw if self.is_int else raw / self.divisor


class Message:
    """Base of every VESC message (each subclass is a frozen dataclass).

    Subclasses set ``COMMAND_ID`` and either ``_WIRE`` (the fields after the command byte, in wire order,
    giving a generic codec) or override :meth:`payload` and :meth:`from_payload`. Bytes after a message's
    layout are ignored on decoding, as the firmware does.
    """

    __slots__ = ()
    COMMAND_ID: ClassVar[int]
    _WIRE: ClassVar[tuple[WireField, ...]] = ()
    _STRUCT: ClassVar[struct.Struct] = struct.Struct(">B")
    _ARGS: ClassVar[struct.Struct] = struct.Struct(">")
    _NAMES: ClassVar[tuple[str, ...]] = ()
    _DIVISORS: ClassVar[tuple[float, ...]] = ()
    _INT_INDEX: ClassVar[tuple[int, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Precompile the struct and conversion tables of a subclass that declares ``_WIRE``."""
        super().__init_subclass__(**kwargs)
        if "_WIRE" in cls.__dict__:
            wire = cls._WIRE
            cls._STRUCT = struct.Struct(">B" + "".join(f.code for f in wire))
            cls._ARGS = struct.Struct(">" + "".join(f.code for f in wire))
            cls._NAMES = tuple(f.name for f in wire)
            cls._DIVISORS = tuple(f.divisor for f in wire)
            cls._INT_INDEX = tuple(i for i, f in enumerate(wire) if f.is_int)

    def payload(self) -> bytes:
        """Return the payload: command id byte followed by the arguments."""
        return self._STRUCT.pack(self.COMMAND_ID, *[f.to_raw(getattr(self, f.name)) for f in self._WIRE])

    def encode(self) -> bytes:
        """Return the complete frame (start byte, length, payload, CRC, end byte)."""
        return encode_frame(self.payload())

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode a payload (command id byte first); raise ShortPayloadError when it is too short."""
        try:
            raws = cls._ARGS.unpack_from(payload, 1)
        except struct.error:
            raise ShortPayloadError(
                f"{cls.__name__} needs {cls._STRUCT.size} payload bytes, got {len(payload)}"
            ) from None
        values = list(map(truediv, raws, cls._DIVISORS))
        for i in cls._INT_INDEX:
            values[i] = raws[i]
        return cls._build(cls._NAMES, values)

    @classmethod
    def _build(cls, names: tuple[str, ...], values: Any) -> Self:
        """Create an instance from already-valid field values without running the dataclass __init__."""
        obj = object.__new__(cls)
        obj.__dict__.update(zip(names, values, strict=True))
        return obj


@dataclass(frozen=True)
class Unknown(Message):
    """A CRC-valid frame whose command id the decoder has no message class for (kept verbatim)."""

    COMMAND_ID: ClassVar[int] = -1
    command_id: int
    data: bytes = b""

    def payload(self) -> bytes:
        """Return the payload: ``command_id`` byte followed by ``data``."""
        if not 0 <= self.command_id <= 255:
            raise ValueError(f"command_id={self.command_id!r} is outside the range [0, 255]")
        return bytes((self.command_id,)) + bytes(self.data)

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Keep the id and the argument bytes of ``payload``; raise ShortPayloadError when it is empty."""
        if not payload:
            raise ShortPayloadError("Unknown needs at least the command id byte")
        return cls(payload[0], bytes(payload[1:]))

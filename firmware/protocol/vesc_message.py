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
from collections.abc import Callable
from dataclasses import dataclass, fields
from enum import IntEnum
from typing import Any, ClassVar, Self

from firmware.protocol.vesc_frame import ShortPayloadError, encode_frame

__all__ = ["CommandId", "Message", "Unknown", "WireField", "lazy_fields", "to_raw"]

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
    _decode: ClassVar[Callable[[bytes], Any] | None] = None
    _INDEX: ClassVar[dict[str, int]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Precompile the structs and the payload decoder of a subclass using the generic codec."""
        super().__init_subclass__(**kwargs)
        cls._STRUCT = struct.Struct(">B" + "".join(f.code for f in cls._WIRE))
        cls._ARGS = struct.Struct(">" + "".join(f.code for f in cls._WIRE))
        cls._INDEX = {f.name: i for i, f in enumerate(cls._WIRE)}
        cls._decode = None if "from_payload" in cls.__dict__ else staticmethod(_make_decoder(cls))

    def __getattr__(self, name: str) -> Any:
        """Convert a field of a lazily decoded message from its wire integer, on first access only."""
        if name.startswith("__"):
            raise AttributeError(name)
        index = self._INDEX.get(name)
        raws = self.__dict__.get("_raws")
        if index is None or raws is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        value = self._WIRE[index].from_raw(raws[index])
        self.__dict__[name] = value
        return value

    def payload(self) -> bytes:
        """Return the payload: command id byte followed by the arguments."""
        return self._STRUCT.pack(self.COMMAND_ID, *[f.to_raw(getattr(self, f.name)) for f in self._WIRE])

    def encode(self) -> bytes:
        """Return the complete frame (start byte, length, payload, CRC, end byte)."""
        return encode_frame(self.payload())

    @classmethod
    def from_payload(cls, payload: bytes) -> Self:
        """Decode a payload (command id byte first); raise ShortPayloadError when it is too short."""
        if not payload:
            raise ShortPayloadError(f"{cls.__name__} payload is empty")
        if payload[0] != cls.COMMAND_ID:
            raise ValueError(f"payload id {payload[0]} is not {cls.__name__}'s id {cls.COMMAND_ID}")
        assert cls._decode is not None
        return cls._decode(payload)

    @classmethod
    def payload_decoder(cls) -> Callable[[bytes], Self]:
        """Return the fastest function turning a payload of this class's id into a message (for Decoder)."""
        return cls._decode if cls._decode is not None else cls.from_payload


def lazy_fields(cls: type[Message]) -> type[Message]:
    """Class decorator put above ``@dataclass``: drop class-level field defaults (``__init__`` keeps them).

    A lazily decoded message holds only its wire integers; a default left on the class would be found by
    attribute lookup before :meth:`Message.__getattr__` could convert the field.
    """
    for f in fields(cls):  # type: ignore[arg-type]
        if f.name in cls.__dict__:
            delattr(cls, f.name)
    return cls


def _make_decoder(cls: type[Message]) -> Callable[[bytes], Any]:
    """Build the payload decoder of a generic message class (closures: the decoder's hot path).

    Instances are created without the dataclass ``__init__`` (values from the wire are valid by
    construction), so message classes using the generic codec must not use ``slots=True``. A message
    with several fields keeps the unpacked integers and converts each field on first access: decoding a
    73-byte GET_VALUES reply then costs one ``struct.unpack_from`` instead of 23 float conversions.
    """
    unpack = cls._ARGS.unpack_from
    size = cls._STRUCT.size
    new = object.__new__
    names = tuple(f.name for f in cls._WIRE)
    divisors = tuple(f.divisor for f in cls._WIRE)
    int_index = tuple(i for i, f in enumerate(cls._WIRE) if f.is_int)

    def short(payload: bytes) -> ShortPayloadError:
        return ShortPayloadError(f"{cls.__name__} needs {size} payload bytes, got {len(payload)}")

    def decode_none(payload: bytes) -> Any:
        return new(cls)

    def decode_one_int(payload: bytes) -> Any:
        try:
            (raw,) = unpack(payload, 1)
        except struct.error:
            raise short(payload) from None
        obj = new(cls)
        obj.__dict__[name] = raw
        return obj

    def decode_one(payload: bytes) -> Any:
        try:
            (raw,) = unpack(payload, 1)
        except struct.error:
            raise short(payload) from None
        obj = new(cls)
        obj.__dict__[name] = raw / divisor
        return obj

    def decode_many(payload: bytes) -> Any:
        try:
            raws = unpack(payload, 1)
        except struct.error:
            raise short(payload) from None
        obj = new(cls)
        obj.__dict__["_raws"] = raws  # fields are converted on first access (Message.__getattr__)
        return obj

    if not names:
        return decode_none
    if len(names) > 1:
        return decode_many
    (name,), (divisor,) = names, divisors
    return decode_one_int if int_index else decode_one


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

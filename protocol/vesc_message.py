"""Building blocks of VESC messages: command ids, scaled wire fields, the Message base class, Unknown.

Scaling (PROTOCOLS.md A.3): the firmware sends ``int32(value * scale)`` (or int16/uint8), a C cast, i.e.
**truncation toward zero**, and reads ``raw / scale``. :class:`WireField` does the same in SI units, with one
deliberate refinement: a product within 4 ulp of an integer is taken as that integer. Without it float
noise would truncate an intended integer down by one (``0.57 * 1e5`` is 56999.99999999999 and
``(1001 / 1000) * 1000`` is 1000.9999999999999), and values decoded from the wire would not re-encode to
the same bytes; genuine fractions are still truncated (2.4999 A -> 2499 mA, -2.4999 A -> -2499 mA).

Angles are radians in the API and degrees on the wire. The divisor of an angle field is
``scale * 180 / pi``, one multiplication each way, so ``SetPos(math.pi / 2)`` gives exactly 90 000 000
(``05 5D 4A 80``) and every int32 read from the wire re-encodes to itself.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from functools import partial
from operator import attrgetter, truediv
from types import MemberDescriptorType
from typing import Any, ClassVar, Self

from protocol.vesc_codec import MessageCodec, WireField, to_raw
from protocol.vesc_frame import ShortPayloadError, encode_frame

__all__ = ["CommandId", "Message", "Unknown", "WireField", "field_setter", "to_raw"]

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


class Message:
    """Base of every VESC message (each subclass is a ``@dataclass(frozen=True, slots=True)``).

    Subclasses set ``COMMAND_ID`` and either ``_WIRE`` (the fields after the command byte, in wire order,
    giving a generic codec) or override :meth:`payload` and :meth:`from_payload`. Bytes after a message's
    layout are ignored on decoding, as the firmware does.
    """

    __slots__ = ("_raws",)
    COMMAND_ID: ClassVar[int]
    _WIRE: ClassVar[tuple[WireField, ...]] = ()
    _STRUCT: ClassVar[struct.Struct] = struct.Struct(">B")
    _ARGS: ClassVar[struct.Struct] = struct.Struct(">")
    _decode: ClassVar[Callable[[bytes], Any] | None] = None
    _INDEX: ClassVar[dict[str, int]] = {}
    _DIVISORS: ClassVar[tuple[float, ...]] = ()
    _INT_INDEX: ClassVar[tuple[int, ...]] = ()
    _SETTERS: ClassVar[tuple[Callable[[Any, Any], None], ...]] = ()
    _CODEC: ClassVar[MessageCodec | None] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Precompile the structs, conversion tables, codec and payload decoder of a subclass."""
        super().__init_subclass__(**kwargs)
        wire = cls._WIRE
        cls._STRUCT = struct.Struct(">B" + "".join(f.code for f in wire))
        cls._ARGS = struct.Struct(">" + "".join(f.code for f in wire))
        cls._INDEX = {f.name: i for i, f in enumerate(wire)}
        cls._DIVISORS = tuple(f.divisor for f in wire)
        cls._INT_INDEX = tuple(i for i, f in enumerate(wire) if f.is_int)
        cls._SETTERS = tuple(field_setter(cls, f.name) for f in wire)
        command_id = getattr(cls, "COMMAND_ID", None)
        cls._CODEC = None if command_id is None else MessageCodec(
            cls, command_id, tuple((f.name, f.code, f.divisor, f.is_int) for f in wire), cls._SETTERS, _set_raws
        )
        own_decoder = "from_payload" in cls.__dict__ or cls._CODEC is None
        cls._decode = None if own_decoder else staticmethod(cls._CODEC.decode)  # type: ignore[union-attr]
        if cls.payload is Message.payload or getattr(cls.payload, "compiled_from_wire", False):
            cls.payload = _make_payload(cls)  # type: ignore[method-assign,assignment]

    def __getattr__(self, name: str) -> Any:
        """Convert all fields of a lazily decoded message from its wire integers (on the first access)."""
        index = self._INDEX.get(name)
        if index is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        try:
            raws = _get_raws(self)
        except AttributeError:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}") from None
        values = list(map(truediv, raws, self._DIVISORS))
        for i in self._INT_INDEX:
            values[i] = raws[i]
        for set_value, value in zip(self._SETTERS, values, strict=True):
            set_value(self, value)
        try:
            _del_raws(self)
        except AttributeError:
            pass  # another thread converted the same message concurrently (same values)
        return values[index]

    def payload(self) -> bytes:
        """Return the payload: command id byte followed by the arguments (compiled per class)."""
        return _make_payload(type(self))(self)

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

    @classmethod
    def codec(cls) -> MessageCodec:
        """Return the compiled codec of a generic (``_WIRE``) class: its frames straight from field values.

        ``SetCurrent.codec().frame((2.5,))`` is ``SetCurrent(2.5).encode()`` without building the message.
        """
        if cls._CODEC is None or not getattr(cls.payload, "compiled_from_wire", False):
            raise TypeError(f"{cls.__name__} has its own payload layout, not a generic codec")
        return cls._CODEC


_get_raws = Message._raws.__get__  # type: ignore[attr-defined]
_set_raws = Message._raws.__set__  # type: ignore[attr-defined]
_del_raws = Message._raws.__delete__  # type: ignore[attr-defined]


def field_setter(cls: type, name: str) -> Callable[[Any, Any], None]:
    """Return a fast ``set(obj, value)`` for field ``name`` of a slots class, bypassing frozen checks."""
    member = cls.__dict__.get(name)
    if isinstance(member, MemberDescriptorType):
        return member.__set__
    return partial(_set_named, name)


def _set_named(name: str, obj: Any, value: Any) -> None:
    """object.__setattr__ with the name first (fallback of :func:`field_setter` before slots exist)."""
    object.__setattr__(obj, name, value)


def _make_payload(cls: type[Message]) -> Callable[[Any], bytes]:
    """Build the ``payload`` method of a generic message class from its ``_WIRE`` layout (encode hot path).

    The method hands the field values to the class's compiled :class:`MessageCodec`: each field goes
    through :func:`to_raw` with its precomputed divisor, then one ``struct`` packs the command id and all
    raw integers.
    """
    codec = cls._CODEC
    assert codec is not None
    names = tuple(f.name for f in cls._WIRE)
    get = attrgetter(*names) if names else None

    def payload_none(self: Any) -> bytes:
        """Return the payload: command id byte followed by the arguments."""
        return codec.payload(())

    def payload_one(self: Any) -> bytes:
        """Return the payload: command id byte followed by the arguments."""
        return codec.payload((get(self),))  # type: ignore[misc]

    def payload_many(self: Any) -> bytes:
        """Return the payload: command id byte followed by the arguments."""
        return codec.payload(get(self))  # type: ignore[misc]

    method = payload_none if not names else payload_one if len(names) == 1 else payload_many
    method.compiled_from_wire = True  # type: ignore[attr-defined]  # a subclass recompiles for its own _WIRE
    return method


@dataclass(frozen=True, slots=True)
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

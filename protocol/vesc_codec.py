"""The per-message hot path of the VESC codec, compiled (setup.py): wire scaling, packing and unpacking.

The message classes (:mod:`protocol.vesc_message`, :mod:`~protocol.vesc`,
:mod:`~protocol.vesc_values`) are built by ``__init_subclass__`` metaprogramming and stay
interpreted (docs/compiled.md, "Metaprogramming stays interpreted"); what they do per message lives
here: :func:`to_raw` (scaling, see the vesc_message module doc), :class:`MessageCodec` (one generic
message class's payload both ways) and :class:`SelectiveCodec` (the GET_VALUES_SELECTIVE reply).
Instances are created without the dataclass ``__init__`` (values from the wire are valid by
construction) and their slots written through the setters the classes hand over.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Final

from protocol.vesc_frame import ShortPayloadError, encode_frame

__all__ = ["MessageCodec", "SelectiveCodec", "WireField", "to_raw"]

RANGES: Final[dict[str, tuple[int, int, str]]] = {
    "b": (-(1 << 7), (1 << 7) - 1, "int8"),
    "B": (0, (1 << 8) - 1, "uint8"),
    "h": (-(1 << 15), (1 << 15) - 1, "int16"),
    "H": (0, (1 << 16) - 1, "uint16"),
    "i": (-(1 << 31), (1 << 31) - 1, "int32"),
    "I": (0, (1 << 32) - 1, "uint32"),
}
"""Range and C type of each struct code a wire field may use."""
_SNAP_ULPS: Final = 4.0
_MASK: Final = struct.Struct(">I")
_MAX_TABLES: Final = 256  # selective decode tables kept (as the lru_cache of selective_layout)
_new: Final[Callable[[type], Any]] = object.__new__

Payload = bytes | bytearray | memoryview
Setter = Callable[[Any, Any], None]


def to_raw(value: object, divisor: float, code: str, name: str, is_int: bool) -> int:
    """Return the wire integer for ``value`` (truncated toward zero, see module doc) or raise ValueError."""
    if is_int and type(value) is int:
        raw = value
    else:
        try:
            raw = _truncate(_scaled(value, divisor))
        except (TypeError, ValueError, OverflowError):
            lo, hi, _ = RANGES[code]
            raise ValueError(
                f"{name}={value!r} is not a finite number; allowed [{lo / divisor:g}, {hi / divisor:g}]"
            ) from None
    lo, hi, ctype = RANGES[code]
    if raw < lo or raw > hi:
        scale = f" x {divisor:g}" if divisor != 1.0 else ""
        raise ValueError(
            f"{name}={value!r} is outside the wire range [{lo / divisor:g}, {hi / divisor:g}] "
            f"({ctype} of the value{scale})"
        )
    return raw


def _scaled(value: Any, divisor: float) -> float:
    """``value * divisor`` as a float (an int is converted first, as Python's mixed arithmetic does)."""
    if isinstance(value, float):
        return value * divisor
    if isinstance(value, int):
        return float(value) * divisor
    return value * divisor  # e.g. a Fraction; TypeError for what has no float product


def _truncate(x: float) -> int:
    """``int(x)`` (ValueError for NaN, OverflowError for inf), a product within 4 ulp of an integer snapped."""
    raw = int(x)
    if x != raw:
        frac = abs(x - raw)
        # Only a product within 0.001 of an integer can be within 4 ulp of one while |x| < 2**40
        # (4 ulp <= 2**-11 there); beyond that every code's range is exceeded with or without a snap.
        if frac < 0.001 or frac > 0.999:
            nearest = round(x)
            if abs(x - nearest) <= _SNAP_ULPS * math.ulp(x):
                raw = nearest
    return raw


@dataclass(frozen=True)
class WireField:
    """One field on the wire: name, struct code, value = raw / scale (angles: deg on wire, rad in API)."""

    name: str
    code: str
    scale: int | float = 1.0  # kept as given (an int scale stays an int)
    angle: bool = False
    bit: int | None = None
    divisor: float = field(init=False, repr=False, compare=False)
    """Raw units per API unit (``scale``, times 180/pi for an angle field)."""
    is_int: bool = field(init=False, repr=False, compare=False)
    """True when the API value is the raw integer itself (scale 1, not an angle)."""

    def __init__(
        self, name: str, code: str, scale: int | float = 1.0, angle: bool = False, bit: int | None = None
    ) -> None:
        """Check the struct code and precompute the divisor (written out: compiled, unlike a generated one)."""
        if code not in RANGES:
            raise ValueError(f"code={code!r} must be one of {sorted(RANGES)}")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "code", code)
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "angle", angle)
        object.__setattr__(self, "bit", bit)
        object.__setattr__(self, "divisor", scale * 180.0 / math.pi if angle else float(scale))
        object.__setattr__(self, "is_int", scale == 1 and not angle)

    def to_raw(self, value: object) -> int:
        """Return the wire integer for ``value``; ValueError naming value and range if it does not fit."""
        return to_raw(value, self.divisor, self.code, self.name, self.is_int)


class MessageCodec:
    """Payload codec of one generic message class (its ``_WIRE`` fields after the command id byte).

    ``payload(values)`` scales each value with :func:`to_raw` and packs them behind the id;
    ``decode(payload)`` builds an instance: a message with one field gets its value (int fields keep the
    wire integer), one with several keeps the integers for ``set_raws`` (converted on first access),
    one without fields is a shared singleton.
    """

    def __init__(
        self,
        cls: type,
        command_id: int,
        fields: tuple[tuple[str, str, float, bool], ...],
        setters: tuple[Setter, ...],
        set_raws: Setter,
    ) -> None:
        """Precompile the structs for ``fields`` ((name, struct code, divisor, is_int) in wire order)."""
        codes = "".join(code for _, code, _, _ in fields)
        args = struct.Struct(">" + codes)
        self.cls = cls
        self.command_id = command_id
        self.fields = fields
        self.size = 1 + args.size
        self._pack = struct.Struct(">B" + codes).pack
        self._unpack = args.unpack_from
        self._setters = setters
        self._set_raws = set_raws
        self._singleton: Any = _new(cls) if not fields else None

    def payload(self, values: tuple[object, ...]) -> bytes:
        """Return the payload: command id byte followed by ``values`` (one per field) on the wire."""
        fields = self.fields
        if len(values) != len(fields):
            raise ValueError(f"{len(values)} values for the {len(fields)} fields of {self.cls.__name__}")
        if len(fields) == 1:  # a command's single argument: no list of raw values to unpack
            name, code, divisor, is_int = fields[0]
            return self._pack(self.command_id, to_raw(values[0], divisor, code, name, is_int))
        raws: list[int] = []
        for i, (name, code, divisor, is_int) in enumerate(fields):
            raws.append(to_raw(values[i], divisor, code, name, is_int))
        return self._pack(self.command_id, *raws)

    def frame(self, values: tuple[object, ...]) -> bytes:
        """Return the complete frame of the message with ``values`` (the same bytes as its ``encode()``)."""
        return encode_frame(self.payload(values))

    def decode(self, payload: Payload) -> Any:
        """Build the message of ``payload`` (id byte first, not checked); ShortPayloadError if too short."""
        fields = self.fields
        if not fields:
            return self._singleton  # a frozen message without fields: every instance is equal, share one
        try:
            raws = self._unpack(payload, 1)
        except struct.error:
            raise ShortPayloadError(
                f"{self.cls.__name__} needs {self.size} payload bytes, got {len(payload)}"
            ) from None
        obj: Any = _new(self.cls)
        if len(fields) > 1:
            self._set_raws(obj, raws)  # fields are converted on first access (Message.__getattr__)
            return obj
        raw = raws[0]
        _, _, divisor, is_int = fields[0]
        self._setters[0](obj, raw if is_int else raw / divisor)
        return obj


class SelectiveCodec:
    """Decoder of GET_VALUES_SELECTIVE replies: ``values`` maps the fields present to SI values.

    ``layout(mask)`` gives the struct and the wire fields (objects with ``name``, ``divisor`` and
    ``is_int``) of a mask; each mask's decode table is built once.
    """

    def __init__(
        self, cls: type, layout: Callable[[int], tuple[struct.Struct, tuple[Any, ...]]],
        set_mask: Setter, set_values: Setter, set_echo: Setter,
    ) -> None:
        """Bind the message class, its layout function and the setters of its three slots."""
        self.cls = cls
        self._layout = layout
        self._set_mask = set_mask
        self._set_values = set_values
        self._set_echo = set_echo
        self._tables: dict[int, _SelectiveTable] = {}
        self._last: _SelectiveTable | None = None

    def decode(self, payload: Payload, mask: int | None = None) -> Any:
        """Decode a reply; ``mask=None``: the mask is echoed in the payload, else it is the mask asked for."""
        if mask is not None:
            return self._decode(payload, mask, 1, False)
        if len(payload) < 5:
            raise ShortPayloadError(f"ValuesSelective needs 5 bytes for the mask, got {len(payload)}")
        (echoed,) = _MASK.unpack_from(payload, 1)
        return self._decode(payload, echoed, 5, True)

    def _decode(self, payload: Payload, mask: int, offset: int, echo: bool) -> Any:
        """Decode the fields of ``mask`` starting at ``offset`` into a new message."""
        table = self._table(mask & 0x3FFFFF)
        try:
            raws = table.unpack(payload, offset)
        except struct.error:
            raise ShortPayloadError(
                f"ValuesSelective mask 0x{mask:08X} needs {offset + table.size} bytes, got {len(payload)}"
            ) from None
        values: dict[str, object] = {}
        divisors = table.divisors
        for i, name in enumerate(table.names):
            raw = raws[i]
            values[name] = raw if table.is_int[i] else raw / divisors[i]
        obj: Any = _new(self.cls)
        self._set_mask(obj, mask)
        self._set_values(obj, values)
        self._set_echo(obj, echo)
        return obj

    def _table(self, mask: int) -> _SelectiveTable:
        """The decode table of ``mask`` (bits > 21 already cleared), built on first use."""
        table = self._last
        if table is not None and table.mask == mask:  # the driver asks for the same mask every time
            return table
        table = self._tables.get(mask)
        if table is None:
            if len(self._tables) >= _MAX_TABLES:  # masks come off the wire: keep the cache bounded
                self._tables.clear()
            unpacker, present = self._layout(mask)
            table = _SelectiveTable(mask, unpacker, present)
            self._tables[mask] = table
        self._last = table
        return table


class _SelectiveTable:
    """Decode table of one selective mask: unpack_from, size, and each field's name, divisor, int-ness."""

    def __init__(self, mask: int, unpacker: struct.Struct, present: tuple[Any, ...]) -> None:
        self.mask = mask
        self.unpack = unpacker.unpack_from
        self.size = unpacker.size
        self.names: list[str] = [f.name for f in present]
        self.divisors: list[float] = [f.divisor for f in present]
        self.is_int: list[bool] = [f.is_int for f in present]

"""Telemetry records streamed MCU -> host (921600 baud UART): versioned, extensible, COBS framed, CRC-16.

Frame on the wire: ``COBS(payload) 00``; payload = ``version(u8) field_count(u8) fields... crc16``,
fields little-endian in the fixed order of RECORD_SPECS, CRC-16/CCITT-FALSE (poly 0x1021, init
0xFFFF) over version..last field, stored little-endian. Byte-by-byte description: docs/telemetry.md.
A writer may append fields (count > known): readers ignore them. A reader that knows more fields
than a record carries fills the missing ones with their defaults. Version 1 records always carry
at least the BASE_FIELD_COUNT base fields.
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import MISSING, dataclass, field, fields
from enum import IntEnum
from operator import attrgetter, itemgetter
from typing import Any, NamedTuple, TypeVar

from protocol.cobs import cobs_decode
from protocol.telemetry_frame import RecordFramer, crc16
from protocol.telemetry_frame import frame_payload as frame_payload  # re-exported

logger = logging.getLogger(__name__)

TELEMETRY_VERSION: int = 1
SUPPORTED_VERSIONS: frozenset[int] = frozenset({TELEMETRY_VERSION})
TELEMETRY_BAUD: int = 921600
MAX_PAYLOAD_LEN: int = 253  # keeps a COBS frame at <= 254 bytes + delimiter
MAX_ENCODED_LEN: int = MAX_PAYLOAD_LEN + 1
_HEADER = struct.Struct("<BB")
_CRC = struct.Struct("<H")
_INT_RANGES = {"B": (0, 0xFF, "uint8"), "I": (0, 0xFFFF_FFFF, "uint32"), "Q": (0, 2**64 - 1, "uint64")}
_SEQ_MOD = 2**32
_F32_MAX = 3.4028234663852886e38


class SupervisorState(IntEnum):
    """State of the safety supervisor."""

    INIT = 0
    RUN = 1
    SAFE = 2


class FaultReason(IntEnum):
    """Why the supervisor entered (or stays in) the safe state; NONE while running."""

    NONE = 0
    ANGLE_LIMIT = 1
    CURRENT_LIMIT = 2
    MOTOR_TIMEOUT = 3
    IMU_TIMEOUT = 4
    SENSOR_DISAGREEMENT = 5
    MOTOR_FAULT = 6
    DEADLINE_MISSES = 7
    ESTOP = 8
    WATCHDOG = 9
    TASK_OVERRUN = 10
    LINK_LOST = 11
    COMMAND_STALE = 12
    CONTROLLER_ERROR = 13
    MOTOR_ENCODER_DISAGREEMENT = 14
    OVER_TEMPERATURE = 15
    IMU_FROZEN = 16
    MOTOR_JAM = 17


def _wire(fmt: str, default: Any = MISSING) -> Any:
    """Dataclass field carrying its struct format character (the wire type)."""
    return field(default=default, metadata={"fmt": fmt})


@dataclass(frozen=True)
class TelemetryRecord:
    """One telemetry sample (version 1 fields, SI units; floats travel as float32)."""

    seq: int = _wire("I")
    time_cycles: int = _wire("Q")
    reference_rad: float = _wire("f", 0.0)
    encoder_angle_rad: float = _wire("f", 0.0)
    imu_pitch_rad: float = _wire("f", 0.0)
    fused_angle_rad: float = _wire("f", 0.0)
    velocity_rad_s: float = _wire("f", 0.0)
    current_cmd_a: float = _wire("f", 0.0)
    current_meas_a: float = _wire("f", 0.0)
    torque_est_nm: float = _wire("f", 0.0)
    supervisor_state: SupervisorState | int = _wire("B", SupervisorState.INIT)
    fault_reason: FaultReason | int = _wire("B", FaultReason.NONE)
    deadline_misses: int = _wire("I", 0)


@dataclass(frozen=True)
class PublishedRecord(TelemetryRecord):
    """A record with the values a controller published: float32 fields after the base ones (``extra``)."""

    extra: tuple[float, ...] = ()


class FieldSpec(NamedTuple):
    """One wire field: name, struct format character (little-endian, no padding) and reader default."""

    name: str
    fmt: str
    default: int | float = 0


RECORD_SPECS: tuple[FieldSpec, ...] = tuple(
    FieldSpec(f.name, f.metadata["fmt"], 0 if f.default is MISSING else f.default)
    for f in fields(TelemetryRecord)
)
RECORD_FIELDS: tuple[str, ...] = tuple(s.name for s in RECORD_SPECS)
BASE_FIELD_COUNT: int = len(RECORD_SPECS)  # every version-1 record carries at least these
_RECORD_BODY = struct.Struct("<" + "".join(s.fmt for s in RECORD_SPECS))
_RECORD_DATA = struct.Struct(_HEADER.format + "".join(s.fmt for s in RECORD_SPECS))  # header + body
_record_values = attrgetter(*RECORD_FIELDS)
RECORD_PAYLOAD_LEN: int = _HEADER.size + _RECORD_BODY.size + _CRC.size  # 54 bytes
RECORD_FRAME_LEN: int = RECORD_PAYLOAD_LEN + 2  # + COBS code byte + 0x00 delimiter = 56 bytes


def _deg_name(name: str) -> str:
    """CSV column holding the degree version of an angle column (``x_rad`` -> ``x_deg``)."""
    return name.replace("_rad", "_deg", 1)


_ANGLE_FIELDS = ("reference_rad", "encoder_angle_rad", "imu_pitch_rad", "fused_angle_rad", "velocity_rad_s")
RECORD_COLUMNS: tuple[str, ...] = tuple(
    col
    for name in RECORD_FIELDS
    for col in (
        (name, _deg_name(name)) if name in _ANGLE_FIELDS
        else (name, name + "_name") if name in ("supervisor_state", "fault_reason")
        else (name,)
    )
)


class FrameError(ValueError):
    """A telemetry frame that cannot be decoded (bad COBS, length or field count)."""


class CrcError(FrameError):
    """A telemetry frame whose CRC-16 does not match its contents."""


class UnknownVersionError(FrameError):
    """A telemetry frame with a valid CRC but a version this reader does not know."""


def _explain_pack_error(values: Sequence[int | float], specs: Sequence[FieldSpec]) -> ValueError:
    """Build the ValueError naming the first value its wire type cannot hold."""
    for spec, value in zip(specs, values, strict=True):
        if spec.fmt == "f":
            try:
                struct.pack("<f", value)
            except (struct.error, OverflowError, TypeError):
                return ValueError(f"{spec.name}={value!r} is out of range: float32 allows |x| <= {_F32_MAX}")
        else:
            lo, hi, kind = _INT_RANGES[spec.fmt]
            if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
                return ValueError(f"{spec.name}={value!r} is out of range: {kind} allows integers {lo}..{hi}")
    return ValueError(f"cannot pack {list(values)!r} as {[s.fmt for s in specs]}")


def encode_payload(
    values: Sequence[int | float], specs: Sequence[FieldSpec] = RECORD_SPECS, version: int = TELEMETRY_VERSION
) -> bytes:
    """Build an unframed payload (version, count, fields, CRC); ValueError names a value out of range."""
    if len(values) != len(specs) or not 0 < len(specs) <= 255:
        raise ValueError(f"{len(values)} values for {len(specs)} fields: need one per field, 1..255 fields")
    if not 0 <= version <= 255:
        raise ValueError(f"version={version} is out of range: uint8 allows 0..255")
    body_fmt = "<" + "".join(s.fmt for s in specs)
    try:
        body = struct.pack(body_fmt, *values)
    except (struct.error, OverflowError, TypeError):
        raise _explain_pack_error(values, specs) from None
    data = _HEADER.pack(version, len(specs)) + body
    if len(data) + _CRC.size > MAX_PAYLOAD_LEN:
        raise ValueError(f"payload of {len(data) + _CRC.size} bytes is too long: at most {MAX_PAYLOAD_LEN}")
    return data + _CRC.pack(crc16(data))


def encode_record(rec: TelemetryRecord) -> bytes:
    """Encode a record as its full wire frame (RECORD_FRAME_LEN bytes, 0x00-terminated)."""
    return encode_record_values(*_record_values(rec))


def encode_record_values(seq: int, time_cycles: int, *values: int | float) -> bytes:
    """Encode one record given as its field values in RECORD_FIELDS order as its full wire frame.

    The same bytes as ``encode_record(TelemetryRecord(seq, time_cycles, *values))`` without building the
    record (the logger's path); ValueError for a wrong number of values or a value its type cannot hold.

    >>> encode_record_values(7, 99, 0.5, 0.25, 0, 0, 0, 0, 0, 0, 1, 0, 0) == encode_record(
    ...     TelemetryRecord(seq=7, time_cycles=99, reference_rad=0.5, encoder_angle_rad=0.25, supervisor_state=1))
    True
    """
    return RECORD_FRAMER.frame(seq, time_cycles, values)


def _explain_record_error(every: tuple[object, ...]) -> ValueError:
    """Build the ValueError for record values that cannot be packed (wrong count or a value out of range)."""
    if len(every) != BASE_FIELD_COUNT:
        return ValueError(f"{len(every)} values for the {BASE_FIELD_COUNT} record fields: need one per field "
                          f"({', '.join(RECORD_FIELDS)})")
    return _explain_pack_error(every, RECORD_SPECS)  # type: ignore[arg-type]


RECORD_FRAMER: RecordFramer = RecordFramer(_RECORD_DATA, TELEMETRY_VERSION, BASE_FIELD_COUNT, _explain_record_error)
"""Frames records from their field values (:func:`encode_record_values`; the logger calls it directly)."""


def record_framer(extra_floats: int) -> RecordFramer:
    """The framer of records carrying `extra_floats` float32 fields after the base ones (0: RECORD_FRAMER)."""
    if extra_floats == 0:
        return RECORD_FRAMER
    if not 0 < extra_floats <= (MAX_PAYLOAD_LEN - RECORD_PAYLOAD_LEN) // 4:
        raise ValueError(f"{extra_floats} extra fields out of range: 0..{(MAX_PAYLOAD_LEN - RECORD_PAYLOAD_LEN) // 4}")
    specs = RECORD_SPECS + tuple(FieldSpec(f"extra_{k}", "f", math.nan) for k in range(extra_floats))
    layout = struct.Struct(_RECORD_DATA.format + "f" * extra_floats)
    return RecordFramer(layout, TELEMETRY_VERSION, len(specs),
                        lambda every: _explain_pack_error(every, specs))  # type: ignore[arg-type]


def decode_payload(payload: bytes, specs: Sequence[FieldSpec] = RECORD_SPECS) -> dict[str, int | float]:
    """Decode an unframed payload into {name: value} for `specs`; FrameError subclasses on bad input."""
    if len(payload) < _HEADER.size + _CRC.size:
        raise FrameError(f"payload of {len(payload)} bytes is too short: at least {_HEADER.size + _CRC.size}")
    data, (crc,) = payload[:-2], _CRC.unpack(payload[-2:])
    if crc16(data) != crc:
        raise CrcError(f"CRC 0x{crc:04x} does not match the contents (0x{crc16(data):04x})")
    version, count = _HEADER.unpack_from(data)
    if version not in SUPPORTED_VERSIONS:
        raise UnknownVersionError(f"version {version} is unknown: known {sorted(SUPPORTED_VERSIONS)}")
    if count < BASE_FIELD_COUNT:
        raise FrameError(f"field count {count} is invalid: version {version} has at least {BASE_FIELD_COUNT}")
    known = min(count, len(specs))
    fmt = "<" + "".join(s.fmt for s in specs[:known])
    size, body_len = struct.calcsize(fmt), len(data) - _HEADER.size
    extra = count - known  # fields of a newer writer, each at least one byte
    fits = body_len == size if extra == 0 else body_len >= size + extra
    if not fits:
        raise FrameError(f"{body_len} field bytes do not fit {count} fields ({size} for the first {known})")
    values = struct.unpack_from(fmt, data, _HEADER.size)
    out = {s.name: v for s, v in zip(specs, values, strict=False)}
    out.update({s.name: s.default for s in specs[known:]})
    return out


def _enum_or_int(enum: type[IntEnum], value: int) -> IntEnum | int:
    """The enum member for a known code, else the plain int (a newer writer's code)."""
    try:
        return enum(value)
    except ValueError:
        return value


def record_from_values(values: dict[str, int | float], extra: tuple[float, ...] = ()) -> TelemetryRecord:
    """Build a record from decoded field values (unknown enum codes stay plain ints), `extra` appended."""
    kw: dict[str, Any] = {name: values[name] for name in RECORD_FIELDS}
    kw["supervisor_state"] = _enum_or_int(SupervisorState, int(kw["supervisor_state"]))
    kw["fault_reason"] = _enum_or_int(FaultReason, int(kw["fault_reason"]))
    return PublishedRecord(**kw, extra=extra) if extra else TelemetryRecord(**kw)  # type: ignore[arg-type]


def decode_frame(frame: bytes, extra_fields: int = 0) -> TelemetryRecord:
    """Decode one frame (COBS bytes, with or without the trailing 0x00); FrameError on bad input.

    With ``extra_fields`` the first that many float32 fields after the base ones (a controller's published
    values) land in ``record.extra`` (NaN for those the frame lacks).
    """
    encoded = frame[:-1] if frame.endswith(b"\x00") else frame
    if extra_fields:
        return _record_extra(_unstuff(encoded), extra_fields)[1]
    return record_from_values(decode_payload(_unstuff(encoded)))


def _unstuff(encoded: bytes) -> bytes:
    """The payload of a COBS-encoded frame (no delimiter); FrameError if the encoding is broken."""
    try:
        return cobs_decode(encoded)
    except ValueError as exc:
        raise FrameError(str(exc)) from None


_values_tuple: Callable[[dict[str, int | float]], tuple[int | float, ...]] = itemgetter(*RECORD_FIELDS)


def decode_values(payload: bytes) -> tuple[int, tuple[int | float, ...]]:
    """(seq, field values in RECORD_FIELDS order) of an unframed payload; FrameError subclasses on bad input.

    A version-1 record of exactly the known fields is unpacked in one go; anything else (a newer writer's
    extra fields) goes through :func:`decode_payload`.
    """
    if len(payload) == RECORD_PAYLOAD_LEN:
        data = payload[:-2]
        version, count, *values = _RECORD_DATA.unpack(data)
        if version in SUPPORTED_VERSIONS and count == BASE_FIELD_COUNT:
            if crc16(data) != _CRC.unpack(payload[-2:])[0]:
                decode_payload(payload)  # raises the CrcError with its message
            return int(values[0]), tuple(values)
    values_tuple = _values_tuple(decode_payload(payload))
    return int(values_tuple[0]), values_tuple


def _record(payload: bytes) -> tuple[int, TelemetryRecord]:
    rec = record_from_values(decode_payload(payload))
    return rec.seq, rec


def _extra_specs(extra_fields: int) -> tuple[FieldSpec, ...]:
    return RECORD_SPECS + tuple(FieldSpec(f"extra_{k}", "f", math.nan) for k in range(extra_fields))


def decode_values_extra(payload: bytes, extra_fields: int) -> tuple[int, tuple[int | float, ...]]:
    """As :func:`decode_values`, the first extra_fields float32 fields after the base ones appended (NaN if absent)."""
    values = decode_payload(payload, _extra_specs(extra_fields))
    out = tuple(values[s.name] for s in RECORD_SPECS) + tuple(float(values[f"extra_{k}"]) for k in range(extra_fields))
    return int(out[0]), out


def _record_extra(payload: bytes, extra_fields: int) -> tuple[int, TelemetryRecord]:
    values = decode_payload(payload, _extra_specs(extra_fields))
    rec = record_from_values(values, tuple(float(values[f"extra_{k}"]) for k in range(extra_fields)))
    return rec.seq, rec


def record_to_row(rec: TelemetryRecord, extra_names: Sequence[str] = ()) -> dict[str, int | float | str]:
    """One CSV row (keys = RECORD_COLUMNS, then extra_names): SI values, ``*_deg`` columns, enum names."""
    row: dict[str, int | float | str] = dict(zip(extra_names, getattr(rec, "extra", ()), strict=False))
    for name in RECORD_FIELDS:
        value = getattr(rec, name)
        if name in _ANGLE_FIELDS:
            row[name] = value
            row[_deg_name(name)] = math.degrees(value)
        elif isinstance(value, IntEnum):
            row[name], row[name + "_name"] = int(value), value.name
        elif name in ("supervisor_state", "fault_reason"):
            row[name], row[name + "_name"] = value, f"UNKNOWN_{value}"
        else:
            row[name] = value
    return row


@dataclass
class TelemetryStats:
    """Counters of a TelemetryDecoder: each input byte is in a record, dropped_bytes or pending."""

    records: int = 0
    bytes_in: int = 0
    dropped_bytes: int = 0
    crc_errors: int = 0
    bad_frames: int = 0
    lost_records: int = 0
    unknown_versions: int = 0
    sequence_resets: int = 0


T = TypeVar("T")


class TelemetryDecoder:
    """Streaming decoder: splits on 0x00, decodes each frame, counts every failure; never raises."""

    def __init__(self, extra_fields: int = 0) -> None:
        """Start with empty counters and an empty buffer; keep `extra_fields` appended floats per record."""
        self.extra_fields = extra_fields
        self.stats = TelemetryStats()
        self._buf = bytearray()
        self._discarding = False  # inside an overlong frame: drop until the next delimiter
        self._last_seq: int | None = None

    @property
    def pending_bytes(self) -> int:
        """Bytes of an unfinished frame held back (never more than MAX_ENCODED_LEN)."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[TelemetryRecord]:
        """Consume bytes and return the records whose frames they complete."""
        n = self.extra_fields
        return self._feed(data, (lambda payload: _record_extra(payload, n)) if n else _record)

    def feed_values(self, data: bytes | bytearray | memoryview) -> list[tuple[int | float, ...]]:
        """As :meth:`feed`, but each record as the tuple of its field values (RECORD_FIELDS order, enums as ints).

        The same counters; no record objects (a long run's CSV is written from these).
        """
        n = self.extra_fields
        return self._feed(data, (lambda payload: decode_values_extra(payload, n)) if n else decode_values)

    def _feed(self, data: bytes | bytearray | memoryview, build: Callable[[bytes], tuple[int, T]]) -> list[T]:
        if not isinstance(data, bytes):
            data = bytes(data)
        self.stats.bytes_in += len(data)
        records: list[T] = []
        start, n = 0, len(data)
        while start <= n:
            end = data.find(b"\x00", start)
            piece = data[start:] if end < 0 else data[start:end]
            if self._discarding:
                self.stats.dropped_bytes += len(piece)
            elif len(self._buf) + len(piece) > MAX_ENCODED_LEN:
                logger.debug("telemetry frame longer than %d bytes: dropping it", MAX_ENCODED_LEN)
                self.stats.bad_frames += 1
                self.stats.dropped_bytes += len(self._buf) + len(piece)
                self._buf.clear()
                self._discarding = True
            else:
                self._buf += piece
            if end < 0:
                break
            if self._discarding:
                self.stats.dropped_bytes += 1
                self._discarding = False
            else:
                rec = self._decode(bytes(self._buf), build)
                self._buf.clear()
                if rec is not None:
                    records.append(rec)
            start = end + 1
        return records

    def reset(self) -> None:
        """Drop buffered bytes (counted in dropped_bytes) and forget the last sequence number."""
        self.stats.dropped_bytes += len(self._buf)
        self._buf.clear()
        self._discarding = False
        self._last_seq = None

    def _decode(self, encoded: bytes, build: Callable[[bytes], tuple[int, T]]) -> T | None:
        """Decode one delimited frame (its delimiter included in the byte counts) or count why not."""
        if not encoded:
            self.stats.dropped_bytes += 1  # idle delimiter
            return None
        try:
            seq, result = build(_unstuff(encoded))
        except UnknownVersionError:
            self.stats.unknown_versions += 1
        except CrcError:
            self.stats.crc_errors += 1
        except FrameError as exc:
            logger.debug("bad telemetry frame: %s", exc)
            self.stats.bad_frames += 1
        else:
            self._count_sequence(seq)
            self.stats.records += 1
            return result
        self.stats.dropped_bytes += len(encoded) + 1
        return None

    def _count_sequence(self, seq: int) -> None:
        """Add sequence gaps to lost_records; a step backwards (restart, repeat) is a reset."""
        if self._last_seq is not None:
            gap = (seq - self._last_seq - 1) % _SEQ_MOD
            if gap < _SEQ_MOD // 2:
                self.stats.lost_records += gap
            else:
                logger.debug("telemetry seq went back %d -> %d", self._last_seq, seq)
                self.stats.sequence_resets += 1
        self._last_seq = seq

"""BNO08x UART-RVC frames: codec for one 19-byte frame and a streaming, resynchronising decoder.

Wire format (BNO080 datasheet 1000-3927 §1.3.5.2; see shared PROTOCOLS.md D.2): ``AA AA`` header,
index (uint8), yaw/pitch/roll (int16 little-endian, 0.01 degree), x/y/z acceleration (int16 LE,
milli-g), motion intent (byte 15), motion request (byte 16), reserved (byte 17, sent as 0) and a
checksum = sum of bytes 2..17 mod 256. 115200 baud 8N1, 100 Hz, output only.

A frame whose checksum holds but whose angles are outside the sensor's ranges (yaw and roll +-180 deg, pitch
+-90 deg: datasheet §1.3.5.2) is damaged data that matched the 8-bit checksum by chance (about 1 in 256 damaged
frames): the decoder counts it in ``range_errors`` and slides on, as it does past a checksum error.

SI -> wire truncates toward zero (like a C cast), after snapping a scaled value within 1e-6 LSB of an
integer to that integer: float round-off of a decoded value must not push it one LSB down, so every
decoded frame re-encodes to the same bytes (tests check all 65536 int16 values).
"""

from __future__ import annotations

import logging
import math
import struct
from dataclasses import dataclass
from typing import Final, NamedTuple

logger: Final = logging.getLogger(__name__)

RVC_HEADER: Final[bytes] = b"\xaa\xaa"
RVC_FRAME_LEN: Final[int] = 19
RVC_BAUD: Final[int] = 115200
RVC_RATE_HZ: Final[int] = 100
MG_TO_MPS2: Final[float] = 0.00980665  # 1 milli-g in m/s^2 (standard gravity 9.80665 m/s^2 / 1000)
CENTIDEG_TO_RAD: Final[float] = math.pi / 18000.0  # one LSB of yaw/pitch/roll (0.01 degree) in radians
BANNER_START: Final[int] = 0x25  # '%': every boot banner line of the BNO08x starts with it (datasheet §5.1)
MAX_BANNER_LINE: Final[int] = 128  # longest banner line accepted before the '%' is treated as junk

YAW_ROLL_MAX_CDEG: Final[int] = 18000  # the sensor's yaw and roll range, +-180 deg (datasheet §1.3.5.2)
PITCH_MAX_CDEG: Final[int] = 9000  # its pitch range, +-90 deg
_INT16_MIN: Final = -32768
_INT16_MAX: Final = 32767
_SNAP_LSB: Final = 1e-6  # a scaled value this close to an integer is that integer (float round-off, not data)
_BODY: Final = struct.Struct("<B6hBBB")  # bytes 2..17: index, yaw, pitch, roll, ax, ay, az, MI, MR, reserved
_CHECKSUM_BYTES: Final = tuple(bytes((n,)) for n in range(256))
_new_tuple: Final = tuple.__new__
_PRINTABLE: Final = frozenset(range(0x20, 0x7F)) | {0x09}
_LINE_END: Final = frozenset({0x0A, 0x0D})


class RvcRaw(NamedTuple):
    """One RVC frame in wire units: angles in 0.01 degree, accelerations in milli-g."""

    index: int  # type: ignore[assignment]  # the frame index byte (shadows tuple.index on purpose)
    yaw_cdeg: int
    pitch_cdeg: int
    roll_cdeg: int
    accel_x_mg: int
    accel_y_mg: int
    accel_z_mg: int
    motion_intent: int = 0
    motion_request: int = 0


def rvc_checksum(body: bytes | bytearray) -> int:
    """Checksum of an RVC frame: the sum of bytes 2..17 (the 16 bytes after the header) mod 256."""
    return sum(body) & 0xFF


def pack_raw(raw: RvcRaw) -> bytes:
    """Build the 19 wire bytes from wire-unit values; ValueError names any value out of its range."""
    return _pack_wire(raw)


_WireValues = tuple[int, int, int, int, int, int, int, int, int]
"""The nine wire-unit values of :class:`RvcRaw`, as a plain tuple (unboxed in the compiled build)."""


def _pack_wire(values: _WireValues) -> bytes:
    """:func:`pack_raw` of the values in RvcRaw order (the shared path of pack_raw and RvcFrame.encode)."""
    index, yaw, pitch, roll, ax, ay, az, intent, request = values
    for k in (0, 7, 8):
        if not 0 <= values[k] <= 0xFF:
            raise ValueError(f"{RvcRaw._fields[k]}={values[k]} is out of range: uint8 allows 0..255")
    for k in range(1, 7):
        if not _INT16_MIN <= values[k] <= _INT16_MAX:
            raise ValueError(
                f"{RvcRaw._fields[k]}={values[k]} is out of range: int16 allows {_INT16_MIN}..{_INT16_MAX}"
            )
    body = _BODY.pack(index, yaw, pitch, roll, ax, ay, az, intent, request, 0)
    return RVC_HEADER + body + _CHECKSUM_BYTES[rvc_checksum(body)]


def unpack_raw(frame: bytes) -> RvcRaw:
    """Parse 19 wire bytes into wire-unit values; ValueError on a bad length, header or checksum."""
    if len(frame) != RVC_FRAME_LEN:
        raise ValueError(f"RVC frame length {len(frame)} is invalid: must be exactly {RVC_FRAME_LEN} bytes")
    if frame[:2] != RVC_HEADER:
        raise ValueError(f"RVC header {frame[:2].hex(' ')} is invalid: must be aa aa")
    expected = rvc_checksum(frame[2:18])
    if frame[18] != expected:
        raise ValueError(f"RVC checksum 0x{frame[18]:02x} is wrong: bytes 2..17 sum to 0x{expected:02x}")
    return _raw_at(frame, 0)


def _raw_at(buf: bytes | bytearray, start: int) -> RvcRaw:
    """Wire-unit values of the frame at buf[start:], its length, header and checksum already verified."""
    # the namedtuple's own __new__ is interpreted Python; tuple.__new__ builds the same tuple directly
    return _new_tuple(RvcRaw, _BODY.unpack_from(buf, start + 2)[:9])  # without the reserved byte


def _in_range(raw: RvcRaw) -> bool:
    """Whether a frame's angles are within the sensor's ranges (yaw and roll +-180 deg, pitch +-90 deg)."""
    return (-YAW_ROLL_MAX_CDEG <= raw.yaw_cdeg <= YAW_ROLL_MAX_CDEG and -PITCH_MAX_CDEG <= raw.pitch_cdeg
            <= PITCH_MAX_CDEG and -YAW_ROLL_MAX_CDEG <= raw.roll_cdeg <= YAW_ROLL_MAX_CDEG)


def _to_lsb(name: str, value_si: float, lsb_si: float, unit: str) -> int:
    """Scale an SI value to integer LSBs, truncating toward zero; ValueError if it does not fit int16."""
    scaled = value_si / lsb_si
    if math.isfinite(scaled):
        nearest = round(scaled)
        lsb = nearest if abs(scaled - nearest) <= _SNAP_LSB else math.trunc(scaled)
        if _INT16_MIN <= lsb <= _INT16_MAX:
            return lsb
    raise ValueError(
        f"{name}={value_si} is out of range: the int16 wire field allows "
        f"{_INT16_MIN * lsb_si:.6g}..{_INT16_MAX * lsb_si:.6g} {unit}"
    )


@dataclass(frozen=True)
class RvcFrame:
    """One UART-RVC report in SI units (angles in rad, accelerations in m/s^2, gravity included)."""

    index: int
    yaw_rad: float
    pitch_rad: float
    roll_rad: float
    accel_x_mps2: float
    accel_y_mps2: float
    accel_z_mps2: float
    motion_intent: int = 0
    motion_request: int = 0

    def __init__(
        self, index: int, yaw_rad: float, pitch_rad: float, roll_rad: float, accel_x_mps2: float,
        accel_y_mps2: float, accel_z_mps2: float, motion_intent: int = 0, motion_request: int = 0,
    ) -> None:
        """Set the fields (written out: docs/compiled.md, "Constructors written out")."""
        object.__setattr__(self, "index", index)
        object.__setattr__(self, "yaw_rad", yaw_rad)
        object.__setattr__(self, "pitch_rad", pitch_rad)
        object.__setattr__(self, "roll_rad", roll_rad)
        object.__setattr__(self, "accel_x_mps2", accel_x_mps2)
        object.__setattr__(self, "accel_y_mps2", accel_y_mps2)
        object.__setattr__(self, "accel_z_mps2", accel_z_mps2)
        object.__setattr__(self, "motion_intent", motion_intent)
        object.__setattr__(self, "motion_request", motion_request)

    @classmethod
    def from_raw(cls, raw: RvcRaw) -> RvcFrame:
        """Convert wire units to SI (exactly invertible by to_raw)."""
        index, yaw, pitch, roll, ax, ay, az, intent, request = raw
        return cls(
            index,
            yaw * CENTIDEG_TO_RAD,
            pitch * CENTIDEG_TO_RAD,
            roll * CENTIDEG_TO_RAD,
            ax * MG_TO_MPS2,
            ay * MG_TO_MPS2,
            az * MG_TO_MPS2,
            intent,
            request,
        )

    def to_raw(self) -> RvcRaw:
        """Convert to wire units, truncating toward zero; ValueError names a value that does not fit."""
        return RvcRaw(*self._wire_values())

    def _wire_values(self) -> _WireValues:
        """The wire-unit values in RvcRaw order (:meth:`to_raw` as a plain tuple)."""
        return (
            self.index,
            _to_lsb("yaw_rad", self.yaw_rad, CENTIDEG_TO_RAD, "rad"),
            _to_lsb("pitch_rad", self.pitch_rad, CENTIDEG_TO_RAD, "rad"),
            _to_lsb("roll_rad", self.roll_rad, CENTIDEG_TO_RAD, "rad"),
            _to_lsb("accel_x_mps2", self.accel_x_mps2, MG_TO_MPS2, "m/s^2"),
            _to_lsb("accel_y_mps2", self.accel_y_mps2, MG_TO_MPS2, "m/s^2"),
            _to_lsb("accel_z_mps2", self.accel_z_mps2, MG_TO_MPS2, "m/s^2"),
            self.motion_intent,
            self.motion_request,
        )

    def encode(self) -> bytes:
        """Encode as the 19 wire bytes (header, fields, reserved 0, checksum).

        >>> RvcFrame(42, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0).encode().hex(" ")
        'aa aa 2a 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 2a'
        """
        return _pack_wire(self._wire_values())

    @classmethod
    def from_bytes(cls, frame: bytes) -> RvcFrame:
        """Decode exactly one 19-byte frame; ValueError on a bad length, header or checksum."""
        return cls.from_raw(unpack_raw(frame))


@dataclass
class RvcStats:
    """Counters of an RvcDecoder: each input byte is in a frame, banner_bytes, dropped_bytes or pending."""

    frames: int = 0
    bytes_in: int = 0
    dropped_bytes: int = 0
    checksum_errors: int = 0
    range_errors: int = 0  # checksum right, angles outside the sensor's ranges: damage the checksum missed
    banner_bytes: int = 0
    lost_frames: int = 0


class RvcDecoder:
    """Streaming UART-RVC decoder: sliding-window resync, banner skipping, bounded buffer, never raises."""

    def __init__(self) -> None:
        """Start with empty counters and an empty buffer."""
        self.stats = RvcStats()
        self._buf = bytearray()
        self._last_index: int | None = None
        self._after_banner = False

    def feed(self, data: bytes | bytearray | memoryview) -> list[RvcFrame]:
        """Consume bytes and return the frames they complete (the buffer never exceeds MAX_BANNER_LINE)."""
        self.stats.bytes_in += len(data)
        buf = self._buf
        buf += data
        frames: list[RvcFrame] = []
        i, n = 0, len(buf)
        while i < n:
            byte = buf[i]
            if byte == 0xAA:
                if n - i < RVC_FRAME_LEN:
                    if n - i == 1 or buf[i + 1] == 0xAA:
                        break  # maybe the start of a frame: wait for the rest
                elif buf[i + 1] == 0xAA:
                    if rvc_checksum(buf[i + 2 : i + 18]) == buf[i + 18]:
                        raw = _raw_at(buf, i)  # header and checksum just checked
                        if _in_range(raw):
                            frames.append(self._accept(raw))
                            i += RVC_FRAME_LEN
                            continue
                        self.stats.range_errors += 1
                    else:
                        self.stats.checksum_errors += 1
                self._drop(1)  # slide the window by one byte: 0xAA may also be a data byte
                i += 1
            elif byte == BANNER_START or (self._after_banner and byte in _LINE_END):
                line_len = self._banner_line_len(buf, i, n)
                if line_len is None:
                    break  # a banner line still arriving
                if line_len == 0:
                    self._drop(1)
                    i += 1
                else:
                    self.stats.banner_bytes += line_len
                    self._after_banner = True
                    i += line_len
            else:
                nxt = self._next_candidate(buf, i + 1, n)
                self._drop(nxt - i)
                i = nxt
        del buf[:i]
        return frames

    @property
    def pending_bytes(self) -> int:
        """Bytes held back waiting for the rest of a frame or banner line (always < MAX_BANNER_LINE)."""
        return len(self._buf)

    def reset(self) -> None:
        """Drop buffered bytes (counted in dropped_bytes) and forget the last index."""
        self.stats.dropped_bytes += len(self._buf)
        self._buf.clear()
        self._last_index = None
        self._after_banner = False

    def _accept(self, raw: RvcRaw) -> RvcFrame:
        """Count a good frame, its index gap, and convert it."""
        self._after_banner = False
        msg = RvcFrame.from_raw(raw)
        if self._last_index is not None:
            gap = (msg.index - self._last_index - 1) % 256
            if gap:
                logger.debug("RVC index jumped %d -> %d: %d frames lost", self._last_index, msg.index, gap)
            self.stats.lost_frames += gap
        self._last_index = msg.index
        self.stats.frames += 1
        return msg

    def _drop(self, count: int) -> None:
        """Count junk bytes."""
        self._after_banner = False
        self.stats.dropped_bytes += count

    def _banner_line_len(self, buf: bytearray, i: int, n: int) -> int | None:
        """Length of the banner line (or line-end run) at i; 0 if it is not one, None if incomplete."""
        if buf[i] in _LINE_END:
            j = i
            while j < n and buf[j] in _LINE_END:
                j += 1
            return j - i
        end = min(n, i + MAX_BANNER_LINE)
        for j in range(i + 1, end):
            b = buf[j]
            if b in _LINE_END:
                return j + 1 - i
            if b not in _PRINTABLE:
                return 0
        return None if end == n and n - i < MAX_BANNER_LINE else 0

    @staticmethod
    def _next_candidate(buf: bytearray, start: int, n: int) -> int:
        """Index of the next byte at or after start that could begin a frame or a banner line."""
        a = buf.find(0xAA, start)
        p = buf.find(BANNER_START, start)
        hits = [k for k in (a, p) if k >= 0]
        return min(hits) if hits else n

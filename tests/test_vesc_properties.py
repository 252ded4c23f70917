"""Hypothesis properties of the VESC codec: lossless round trips, chunking, resynchronisation, bounds.

What the garbage properties assert, and why that is the honest claim:
* Garbage without 0x02/0x03 bytes cannot start a candidate frame, so every frame around it must come out,
  and exactly the garbage bytes are counted as dropped.
* Arbitrary garbage may end in a valid-looking header whose claimed length runs into the real frames; the
  VESC rule then waits for that many bytes, rejects the candidate (end byte or CRC) and rescans one byte
  further. So (a) the decoder must agree byte for byte with an independent, plain re-implementation of the
  receiver rule of PROTOCOLS.md A.1 (`reference_scan`), and (b) once a clean gap of MAX_FRAME_LEN bytes has
  followed, all real frames are recovered. (b) fails only if a false candidate starting in the garbage
  passes both the end-byte check and the CRC-16 (probability 2^-24 per candidate); (a) has no such caveat.
* A single flipped bit inside a payload or CRC is always detected (CRC-16/XMODEM detects every 1-bit error);
  a flip in the start/length byte changes the framing and is rejected by the end byte + CRC checks with the
  same 2^-24 caveat. The property asserts that the damaged frame is lost and every other frame comes out.
"""

from __future__ import annotations

import binascii
import math
import struct

import pytest
from crc_oracle import crc16_reference
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.vesc import (
    MAX_FRAME_LEN,
    MESSAGES_TO_MOTOR,
    VALUES_FIELDS,
    Decoder,
    FwVersion,
    Message,
    RotorPosition,
    SetCurrent,
    SetPos,
    ShortPayloadError,
    Unknown,
    Values,
    ValuesSelective,
    WireField,
    crc16,
    encode_frame,
)
from protocol.vesc_frame import FrameDecoder
from protocol.vesc_values import FIELDS

RANGES = {"B": (0, 255), "h": (-(2**15), 2**15 - 1), "i": (-(2**31), 2**31 - 1), "I": (0, 2**32 - 1)}
GENERIC = [cls for cls in MESSAGES_TO_MOTOR.values()] + [Values]
UNKNOWN_TO_MOTOR = sorted(set(range(256)) - set(MESSAGES_TO_MOTOR))


def raw_tuple(fields: tuple[WireField, ...]) -> st.SearchStrategy[tuple[int, ...]]:
    """Raw wire integers covering each field's full range."""
    return st.tuples(*[st.integers(*RANGES[f.code]) for f in fields])


@st.composite
def to_motor_payloads(draw: st.DrawFn) -> bytes:
    """A payload the host may send: any known command with any wire values, or an unknown id."""
    cls = draw(st.sampled_from([*MESSAGES_TO_MOTOR.values(), Unknown]))
    if cls is Unknown:
        return bytes([draw(st.sampled_from(UNKNOWN_TO_MOTOR))]) + draw(st.binary(max_size=40))
    return cls._STRUCT.pack(cls.COMMAND_ID, *draw(raw_tuple(cls._WIRE)))


@st.composite
def from_motor_payloads(draw: st.DrawFn) -> bytes:
    """A payload the motor may send: GET_VALUES, ROTOR_POSITION, selective reply (mask echoed), FW version."""
    kind = draw(st.sampled_from(["values", "rotor", "selective", "fw"]))
    if kind == "values":
        return Values._STRUCT.pack(4, *draw(raw_tuple(VALUES_FIELDS)))
    if kind == "rotor":
        return struct.pack(">Bi", 22, draw(st.integers(*RANGES["i"])))
    if kind == "selective":
        mask = draw(st.integers(0, 2**32 - 1))
        present = tuple(f for f in FIELDS if mask >> f.bit & 1)
        body = struct.pack(">" + "".join(f.code for f in present), *draw(raw_tuple(present)))
        return struct.pack(">BI", 50, mask) + body
    name = draw(st.binary(max_size=20)).replace(b"\0", b"")
    return bytes([0, draw(st.integers(0, 255)), draw(st.integers(0, 255))]) + name + b"\0" + draw(
        st.binary(min_size=12, max_size=12)
    ) + draw(st.binary(max_size=8))


PAYLOADS = {"to-motor": to_motor_payloads(), "from-motor": from_motor_payloads()}


def single(direction: str, payload: bytes) -> Message:
    """The message a fresh decoder makes of one frame carrying ``payload``."""
    (message,) = Decoder(direction).feed(encode_frame(payload))  # type: ignore[arg-type]
    return message


def feed_chunks(decoder: FrameDecoder, stream: bytes, cuts: list[int]) -> list:
    """Feed ``stream`` split at the sorted offsets ``cuts``; return all messages."""
    out, last = [], 0
    for cut in [*sorted(set(cuts)), len(stream)]:
        out += decoder.feed(stream[last:cut])
        last = cut
    return out


def reference_scan(stream: bytes) -> tuple[list[bytes], dict[str, int]]:
    """Receiver rule of PROTOCOLS.md A.1 written the plain way: try each offset, drop one byte on failure."""
    i, payloads = 0, []
    counts = {"dropped_bytes": 0, "crc_errors": 0, "bad_end_bytes": 0}
    while i < len(stream):
        if stream[i] == 2 and i + 1 < len(stream):
            length, head, ok = stream[i + 1], 2, stream[i + 1] >= 1
        elif stream[i] == 3 and i + 2 < len(stream):
            length = int.from_bytes(stream[i + 1 : i + 3], "big")
            head, ok = 3, 255 <= length <= 512
        elif stream[i] in (2, 3):
            break  # header not complete yet
        else:
            counts["dropped_bytes"] += 1
            i += 1
            continue
        if ok and i + head + length + 3 > len(stream):
            break  # candidate not complete yet
        if ok:
            payload = stream[i + head : i + head + length]
            crc_rx = int.from_bytes(stream[i + head + length : i + head + length + 2], "big")
            if stream[i + head + length + 2] != 3:
                counts["bad_end_bytes"] += 1
            elif crc16_reference(payload) != crc_rx:
                counts["crc_errors"] += 1
            else:
                payloads.append(payload)
                i += head + length + 3
                continue
        counts["dropped_bytes"] += 1
        i += 1
    counts["buffered"] = len(stream) - i
    return payloads, counts


def raw_decoder() -> FrameDecoder:
    """A frame decoder that returns every CRC-valid payload as bytes."""
    return FrameDecoder(dict.fromkeys(range(256), bytes), Unknown)


# ---- lossless round trips over each field's full wire range -------------------------------------


@pytest.mark.parametrize("cls", GENERIC, ids=lambda c: c.__name__)
@given(data=st.data())
def test_generic_messages_round_trip_full_range(cls: type[Message], data: st.DataObject) -> None:
    payload = cls._STRUCT.pack(cls.COMMAND_ID, *data.draw(raw_tuple(cls._WIRE)))
    direction = "from-motor" if cls is Values else "to-motor"
    (message,) = Decoder(direction).feed(encode_frame(payload))
    assert isinstance(message, cls) and message.payload() == payload
    assert message == cls.from_payload(payload) and message.encode() == encode_frame(payload)
    for f in cls._WIRE:
        assert type(getattr(message, f.name)) is (int if f.is_int else float), f.name
    rebuilt = cls(**{f.name: getattr(message, f.name) for f in cls._WIRE})  # eager construction path
    assert rebuilt == message and rebuilt.payload() == payload


@given(raw=st.integers(*RANGES["i"]), scale=st.sampled_from([1e4, 1e5, 1e3, 1e6, 3.7]))
def test_rotor_position_round_trip(raw: int, scale: float) -> None:
    payload = struct.pack(">Bi", 22, raw)
    (message,) = Decoder("from-motor", rotor_position_scale=scale).feed(encode_frame(payload))
    assert message == RotorPosition.from_payload(payload, scale) and message.payload() == payload
    assert RotorPosition(message.position_rad, scale).payload() == payload


@given(data=st.data(), echo=st.booleans())
def test_selective_reply_round_trip(data: st.DataObject, echo: bool) -> None:
    mask = data.draw(st.integers(0, 2**32 - 1))
    present = tuple(f for f in FIELDS if mask >> f.bit & 1)
    body = struct.pack(">" + "".join(f.code for f in present), *data.draw(raw_tuple(present)))
    payload = (struct.pack(">BI", 50, mask) if echo else bytes([50])) + body
    decoder = Decoder("from-motor", selective_mask_echo=echo, selective_mask=None if echo else mask)
    (message,) = decoder.feed(encode_frame(payload))
    assert isinstance(message, ValuesSelective) and message.mask == mask and message.mask_echo == echo
    assert set(message.values) == {f.name for f in present} and message.payload() == payload


@given(payload=from_motor_payloads().filter(lambda p: p[0] == 0))
def test_fw_version_round_trip(payload: bytes) -> None:
    message = single("from-motor", payload)
    assert isinstance(message, FwVersion) and message.payload() == payload


@given(command_id=st.sampled_from(UNKNOWN_TO_MOTOR), data=st.binary(max_size=511))
def test_unknown_round_trip(command_id: int, data: bytes) -> None:
    payload = bytes([command_id]) + data
    decoder = Decoder("to-motor")
    assert decoder.feed(encode_frame(payload)) == [Unknown(command_id, data)]
    assert decoder.stats.unknown_ids == 1 and Unknown(command_id, data).payload() == payload


@given(current_a=st.floats(-2147483.648, 2147483.647), position_rad=st.floats(-37.4, 37.4))
def test_si_values_truncate_toward_zero_within_one_lsb(current_a: float, position_rad: float) -> None:
    (current,) = Decoder("to-motor").feed(SetCurrent(current_a).encode())
    assert abs(current.current_a) <= abs(current_a) * (1 + 1e-15) + 1e-300
    assert abs(current_a - current.current_a) < 1e-3 * (1 + 1e-9)
    (pos,) = Decoder("to-motor").feed(SetPos(position_rad).encode())
    lsb_rad = math.radians(1e-6)
    assert abs(pos.position_rad) <= abs(position_rad) * (1 + 1e-15) + 1e-300
    assert abs(position_rad - pos.position_rad) < lsb_rad * (1 + 1e-6)


ALL_CLASSES = [*GENERIC, RotorPosition, ValuesSelective, FwVersion]


@pytest.mark.parametrize("cls", ALL_CLASSES, ids=lambda c: c.__name__)
@given(tail=st.binary(max_size=90))
def test_from_payload_on_arbitrary_bytes_returns_or_raises_short(cls: type[Message], tail: bytes) -> None:
    try:
        message = cls.from_payload(bytes([cls.COMMAND_ID]) + tail)
    except ShortPayloadError:
        return
    assert isinstance(message, cls)


# ---- streaming ----------------------------------------------------------------------------------


@pytest.mark.parametrize("direction", ["to-motor", "from-motor"])
@given(data=st.data())
@settings(max_examples=60)
def test_any_chunking_yields_the_same_messages(direction: str, data: st.DataObject) -> None:
    payloads = data.draw(st.lists(PAYLOADS[direction], max_size=12))
    stream = b"".join(encode_frame(p) for p in payloads)
    cuts = data.draw(st.lists(st.integers(0, len(stream)), max_size=20))
    expected = [single(direction, p) for p in payloads]
    assert Decoder(direction).feed(stream) == expected  # type: ignore[arg-type]
    decoder = Decoder(direction)  # type: ignore[arg-type]
    assert feed_chunks(decoder, stream, cuts) == expected
    assert decoder.stats.frames == len(payloads)
    assert decoder.stats.dropped_bytes == 0 and decoder.buffered == 0
    byte_by_byte = Decoder(direction)  # type: ignore[arg-type]
    assert [m for i in range(len(stream)) for m in byte_by_byte.feed(stream[i : i + 1])] == expected


NO_START = st.binary(max_size=40).map(lambda b: b.replace(b"\x02", b"\x55").replace(b"\x03", b"\xaa"))


@given(data=st.data())
@settings(max_examples=60)
def test_garbage_without_start_bytes_between_frames_loses_nothing(data: st.DataObject) -> None:
    payloads = data.draw(st.lists(to_motor_payloads(), min_size=1, max_size=10))
    gaps = data.draw(st.lists(NO_START, min_size=len(payloads) + 1, max_size=len(payloads) + 1))
    stream = gaps[0] + b"".join(encode_frame(p) + g for p, g in zip(payloads, gaps[1:], strict=True))
    decoder = Decoder("to-motor")
    out = feed_chunks(decoder, stream, data.draw(st.lists(st.integers(0, len(stream)), max_size=10)))
    assert out == [single("to-motor", p) for p in payloads]
    assert decoder.stats.dropped_bytes == sum(map(len, gaps)) and decoder.buffered == 0


GARBAGE_PIECES = st.one_of(
    st.binary(max_size=60),
    st.sampled_from([b"\x02", b"\x03", b"\x03\x01\x00", b"\x03\x02\x00", b"\x02\xff", b"\x02\x00"]),
    to_motor_payloads().map(lambda p: encode_frame(p)[: len(p) // 2 + 3]),  # truncated real frame
)


@given(data=st.data())
@settings(max_examples=80)
def test_decoder_agrees_with_reference_receiver_rule(data: st.DataObject) -> None:
    piece = st.one_of(GARBAGE_PIECES, to_motor_payloads().map(encode_frame))
    pieces = data.draw(st.lists(piece, max_size=12))
    stream = b"".join(pieces)
    decoder = raw_decoder()
    out = feed_chunks(decoder, stream, data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    payloads, counts = reference_scan(stream)
    assert out == payloads
    stats = decoder.stats
    assert (stats.dropped_bytes, stats.crc_errors, stats.bad_end_bytes, decoder.buffered) == (
        counts["dropped_bytes"], counts["crc_errors"], counts["bad_end_bytes"], counts["buffered"])
    assert stats.frames == len(payloads) and stats.bytes_in == len(stream)
    frame_bytes = sum(len(encode_frame(p)) for p in payloads)
    assert stats.bytes_in == frame_bytes + stats.dropped_bytes + decoder.buffered


@given(garbage=st.lists(GARBAGE_PIECES, max_size=8).map(b"".join), payloads=st.lists(to_motor_payloads(),
       min_size=1, max_size=6), data=st.data())
@settings(max_examples=80)
def test_frames_after_arbitrary_garbage_are_recovered_after_a_clean_gap(
    garbage: bytes, payloads: list[bytes], data: st.DataObject
) -> None:
    stream = garbage + b"".join(encode_frame(p) for p in payloads) + bytes(MAX_FRAME_LEN)
    decoder = Decoder("to-motor")
    out = feed_chunks(decoder, stream, data.draw(st.lists(st.integers(0, len(stream)), max_size=8)))
    expected = [single("to-motor", p) for p in payloads]
    assert out[len(out) - len(expected) :] == expected and decoder.buffered == 0


@given(data=st.data())
@settings(max_examples=100)
def test_single_bit_flip_loses_only_that_frame(data: st.DataObject) -> None:
    payloads = data.draw(st.lists(to_motor_payloads(), min_size=1, max_size=6))
    frames = [encode_frame(p) for p in payloads]
    victim = data.draw(st.integers(0, len(frames) - 1))
    bit = data.draw(st.integers(0, 8 * len(frames[victim]) - 1))
    damaged = bytearray(frames[victim])
    damaged[bit // 8] ^= 1 << (bit % 8)
    frames[victim] = bytes(damaged)
    decoder = Decoder("to-motor")
    out = decoder.feed(b"".join(frames) + bytes(MAX_FRAME_LEN))
    assert out == [single("to-motor", p) for i, p in enumerate(payloads) if i != victim]
    if 2 <= bit // 8 < len(damaged) - 1:  # payload or CRC of a short frame: the CRC check must catch it
        assert decoder.stats.crc_errors >= 1


@given(chunks=st.lists(st.one_of(st.binary(max_size=700), GARBAGE_PIECES), max_size=30),
       direction=st.sampled_from(["to-motor", "from-motor"]), echo=st.booleans())
@settings(max_examples=80)
def test_memory_bounded_and_never_raises_on_arbitrary_input(
    chunks: list[bytes], direction: str, echo: bool
) -> None:
    decoder = Decoder(direction, selective_mask_echo=echo)  # type: ignore[arg-type]
    for chunk in chunks:
        decoder.feed(chunk)
        assert decoder.buffered < MAX_FRAME_LEN
    assert decoder.stats.bytes_in == sum(map(len, chunks))


def test_memory_bounded_on_long_adversarial_garbage() -> None:
    decoder = Decoder("to-motor")
    pattern = b"\x03\x02\x00" + b"\x02\xff" + bytes(range(256))
    for _ in range(400):
        decoder.feed(pattern)
        assert decoder.buffered < MAX_FRAME_LEN
    assert decoder.stats.frames == 0 and decoder.stats.bytes_in == 400 * len(pattern)


# ---- CRC ----------------------------------------------------------------------------------------


@given(payload=st.binary(max_size=600))
def test_crc_equals_crc_hqx_and_crcmod(payload: bytes) -> None:
    assert crc16(payload) == binascii.crc_hqx(payload, 0) == crc16_reference(payload)
    assert crc16(payload + crc16(payload).to_bytes(2, "big")) == 0  # the residue the decoder checks


@given(payload=st.binary(min_size=1, max_size=512))
def test_any_payload_frames_and_unframes(payload: bytes) -> None:
    frame = encode_frame(payload)
    assert len(frame) == len(payload) + (5 if len(payload) <= 255 else 6)
    assert raw_decoder().feed(frame) == [payload]

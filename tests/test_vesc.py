"""Fixed tests of the VESC / CubeMars codec: PROTOCOLS.md B.8 vectors, manual replies, errors, regressions."""

from __future__ import annotations

import binascii
import copy
import dataclasses
import inspect
import math
import pickle
import random
import struct
import sys
import types

import pytest
from crc_oracle import crc16_reference

from protocol.vesc import (
    FIELDS,
    MAX_FRAME_LEN,
    MESSAGES_FROM_MOTOR,
    MESSAGES_TO_MOTOR,
    VALUES_FIELDS,
    Alive,
    CommandId,
    Decoder,
    DetectMode,
    FaultCode,
    FwVersion,
    GetFwVersion,
    GetValues,
    GetValuesSelective,
    Message,
    OriginMode,
    RotorPosition,
    SetCurrent,
    SetCurrentBrake,
    SetCurrentRel,
    SetDetect,
    SetDuty,
    SetHandbrake,
    SetPos,
    SetPosMulti,
    SetPosOrigin,
    SetPosSingle,
    SetPosSpd,
    SetRpm,
    ShortPayloadError,
    Unknown,
    Values,
    ValuesSelective,
    crc16,
    encode_frame,
)
from protocol.vesc_frame import FrameDecoder

H = bytes.fromhex

# PROTOCOLS.md B.8 (host -> motor); each frame verified against VESC's packet.c there.
TO_MOTOR_VECTORS: list[tuple[Message, str]] = [
    (SetCurrent(2.5), "02 05 06 00 00 09 C4 EE D5 03"),
    (SetCurrent(-2.5), "02 05 06 FF FF F6 3C 07 FD 03"),
    (SetCurrent(0.0), "02 05 06 00 00 00 00 CD 85 03"),
    (GetValues(), "02 01 04 40 84 03"),
    (GetFwVersion(), "02 01 00 00 00 03"),
    (Alive(), "02 01 1E F3 FF 03"),
    (SetDuty(0.10), "02 05 05 00 00 27 10 AE 17 03"),
    (SetCurrentBrake(2.5), "02 05 07 00 00 09 C4 44 84 03"),
    (SetRpm(1000), "02 05 08 00 00 03 E8 2B 58 03"),
    (SetPos(math.pi / 2), "02 05 09 05 5D 4A 80 7B 29 03"),
    (SetPos(math.pi), "02 05 09 0A BA 95 00 1E F7 03"),
    (SetHandbrake(2.5), "02 05 0A 00 00 09 C4 65 FE 03"),
    (SetCurrentRel(0.5), "02 05 54 00 00 C3 50 85 C6 03"),
    (GetValuesSelective(0x00018080), "02 05 32 00 01 80 80 F5 4D 03"),
    (SetDetect(DetectMode.PID_POS), "02 02 0B 04 9C 7E 03"),
    (SetPosSpd(math.pi / 2, 5000, 30000), "02 0D 5B 00 01 5F 90 00 00 13 88 00 00 75 30 39 C5 03"),
    (SetPosOrigin(OriginMode.TEMPORARY), "02 02 5F 00 1E 81 03"),
    (SetPosOrigin(OriginMode.PERMANENT), "02 02 5F 01 0E A0 03"),
]

MANUAL_REPLY = H(
    "02 49 04 01 66 FC D0 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 FF FF FF F3 00"
    " F6 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 FF FF FF FF 00 16 D7 AD 00 0A 6F 19 40"
    " 7E 00 00 00 00 00 00 00 00 00 00 00 00 00 04 4D 53 03"
)
ROTOR_FRAME = H("02 05 16 00 1A B6 03 C9 B5 03")


@pytest.mark.parametrize(("message", "frame_hex"), TO_MOTOR_VECTORS)
def test_b8_vector_encodes_and_decodes(message: Message, frame_hex: str) -> None:
    frame = H(frame_hex)
    assert message.encode() == frame
    assert message.payload() == frame[2:-3]
    decoder = Decoder("to-motor")
    assert decoder.feed(frame) == [message]
    assert type(message).from_payload(frame[2:-3]) == message
    assert decoder.stats.frames == 1 and decoder.stats.dropped_bytes == 0 and decoder.buffered == 0


def test_set_pos_from_degrees_matches_radians() -> None:
    assert SetPos.from_degrees(90.0).encode() == H("02 05 09 05 5D 4A 80 7B 29 03")
    assert SetPosSpd.from_degrees(90.0, 5000, 30000).encode() == SetPosSpd(math.pi / 2, 5000, 30000).encode()
    assert math.degrees(Decoder("to-motor").feed(H("02 05 09 0A BA 95 00 1E F7 03"))[0].position_rad) == 180.0


def test_manual_set_pos_180_typo_is_rejected_by_crc() -> None:
    decoder = Decoder("to-motor")
    assert decoder.feed(H("02 05 09 0A BA 95 00 1E E7 03")) == []
    assert decoder.stats.crc_errors == 1


def test_long_form_300_byte_payload() -> None:
    payload = bytes(i % 256 for i in range(300))
    frame = encode_frame(payload)
    assert frame[:3] == H("03 01 2C") and frame[-3:] == H("C1 76 03") and len(frame) == 306
    assert frame[3:-3] == payload
    raw = FrameDecoder({}, Unknown).feed(frame)
    assert raw == [Unknown(0, payload[1:])] and raw[0].encode() == frame
    reply = Decoder("from-motor").feed(frame)
    assert len(reply) == 1 and isinstance(reply[0], FwVersion) and reply[0].encode() == frame


def test_manual_get_values_reply() -> None:
    decoder = Decoder("from-motor")
    (v,) = decoder.feed(MANUAL_REPLY)
    assert isinstance(v, Values)
    assert v.v_in_v == 24.6 and v.temp_fet_c == 35.8 and v.temp_motor_c == -81.6
    assert math.degrees(v.pid_pos_rad) == pytest.approx(175.05312, abs=1e-9)
    assert (v.erpm, v.tachometer, v.tachometer_abs, v.fault, v.controller_id) == (-13, -1, 1_497_005, 0, 0x7E)
    assert v.avg_vq_v == 0.004 and v.avg_vd_v == 0.0
    zero = ("avg_motor_current_a", "avg_input_current_a", "avg_id_a", "avg_iq_a", "duty", "amp_hours",
            "amp_hours_charged", "watt_hours", "watt_hours_charged", "temp_mos1_c", "temp_mos2_c",
            "temp_mos3_c")
    assert all(getattr(v, name) == 0 for name in zero)
    assert FaultCode(v.fault) is FaultCode.NONE
    assert v.encode() == MANUAL_REPLY
    assert Values(**dataclasses.asdict(v)).encode() == MANUAL_REPLY


def test_synthesised_reply_round_trip() -> None:
    values = Values(temp_fet_c=36.5, temp_motor_c=41.2, avg_motor_current_a=2.47, avg_input_current_a=-0.31,
                    avg_id_a=0.05, avg_iq_a=2.46, duty=0.125, erpm=2100, v_in_v=24.3, amp_hours=0.0123,
                    amp_hours_charged=0.0004, watt_hours=0.2987, watt_hours_charged=0.0099, tachometer=-4242,
                    tachometer_abs=98765, fault=FaultCode.OVER_TEMP_FET, pid_pos_rad=math.radians(123.456789),
                    controller_id=7, temp_mos1_c=36.1, temp_mos2_c=36.2, temp_mos3_c=-5.5, avg_vd_v=-0.123,
                    avg_vq_v=11.5)
    frame = values.encode()
    assert frame[1] == 73 and len(frame) == 78
    assert frame[2 + 54 : 2 + 58] == (123456789).to_bytes(4, "big")  # pid_pos deg x 1e6 at offset 54
    (back,) = Decoder("from-motor").feed(frame)
    for f in VALUES_FIELDS:
        if f.name != "pid_pos_rad":
            assert getattr(back, f.name) == getattr(values, f.name), f.name
    assert back.pid_pos_rad == pytest.approx(values.pid_pos_rad, rel=1e-12)
    assert back.encode() == frame and back == Values.from_payload(frame[2:-3])


def test_values_decode_against_hand_written_b3_layout() -> None:
    # PROTOCOLS.md B.3 written out independently of FIELDS: (name, struct code, raw, expected SI value)
    b3 = [("temp_fet_c", "h", 365, 36.5), ("temp_motor_c", "h", -412, -41.2), ("avg_motor_current_a", "i", 247, 2.47),
          ("avg_input_current_a", "i", -31, -0.31), ("avg_id_a", "i", 5, 0.05), ("avg_iq_a", "i", 246, 2.46),
          ("duty", "h", -125, -0.125), ("erpm", "i", -2100, -2100), ("v_in_v", "h", 243, 24.3),
          ("amp_hours", "i", 123, 0.0123), ("amp_hours_charged", "i", 4, 0.0004), ("watt_hours", "i", 2987, 0.2987),
          ("watt_hours_charged", "i", 99, 0.0099), ("tachometer", "i", -4242, -4242),
          ("tachometer_abs", "i", 98765, 98765), ("fault", "B", 5, 5), ("pid_pos_rad", "i", -123456789, None),
          ("controller_id", "B", 7, 7), ("temp_mos1_c", "h", 361, 36.1), ("temp_mos2_c", "h", 362, 36.2),
          ("temp_mos3_c", "h", -55, -5.5), ("avg_vd_v", "i", -123, -0.123), ("avg_vq_v", "i", 11500, 11.5)]
    payload = struct.pack(">B" + "".join(c for _, c, _, _ in b3), 4, *[raw for _, _, raw, _ in b3])
    assert len(payload) == 73
    (v,) = Decoder("from-motor").feed(encode_frame(payload))
    for name, _, _, expected in b3:
        if expected is not None:
            assert getattr(v, name) == expected and type(getattr(v, name)) is type(expected), name
    assert math.degrees(v.pid_pos_rad) == pytest.approx(-123.456789, abs=1e-12)
    assert v.payload() == payload


def test_rotor_position_manual_vector() -> None:
    (pos,) = Decoder("from-motor").feed(ROTOR_FRAME)
    assert isinstance(pos, RotorPosition) and pos.scale == 1e4
    assert math.degrees(pos.position_rad) == pytest.approx(175.0531, abs=1e-9)
    assert pos.encode() == ROTOR_FRAME
    assert RotorPosition.from_degrees(175.05312).encode() == ROTOR_FRAME  # 1750531.2 truncates to 1750531
    (vesc,) = Decoder("from-motor", rotor_position_scale=1e5).feed(ROTOR_FRAME)
    assert math.degrees(vesc.position_rad) == pytest.approx(17.50531, abs=1e-9)
    assert vesc.encode() == ROTOR_FRAME


def test_values_layout_matches_b3_offsets() -> None:
    b3_offsets = {0: 1, 1: 3, 2: 5, 3: 9, 4: 13, 5: 17, 6: 21, 7: 23, 8: 27, 9: 29, 10: 33, 11: 37, 12: 41,
                  13: 45, 14: 49, 15: 53, 16: 54, 17: 58, 18: 59, 19: 65, 20: 69, 21: 73}
    sizes = {"h": 2, "i": 4, "B": 1}
    offset, first_offset = 1, {}
    for f in FIELDS:
        first_offset.setdefault(f.bit, offset)
        offset += sizes[f.code]
    assert first_offset == b3_offsets and offset == 74
    assert [f.name for f in dataclasses.fields(Values)] == [f.name for f in VALUES_FIELDS]
    assert len(Values().payload()) == 73


def test_fault_codes() -> None:
    assert len(FaultCode) == 19 and FaultCode(18) is FaultCode.UNBALANCED_CURRENTS
    assert FaultCode.OVER_TEMP_MOTOR == 6 and FaultCode.BOOTING_FROM_WATCHDOG_RESET == 10


def test_truncation_toward_zero_not_rounding() -> None:
    assert SetCurrent(2.4999).payload() == H("06 00 00 09 C3")  # 2499 mA, not 2500
    assert SetCurrent(-2.4999).payload() == bytes([6]) + (-2499).to_bytes(4, "big", signed=True)
    assert SetCurrent(-0.0009).payload() == H("06 00 00 00 00")
    assert SetDuty(0.999999).payload() == bytes([5]) + (99999).to_bytes(4, "big")
    assert SetRpm(1000.9).payload() == H("08 00 00 03 E8")  # type: ignore[arg-type]
    assert SetDuty(0.57).payload() == bytes([5]) + (57000).to_bytes(4, "big")  # float noise is not a fraction
    assert Values(temp_fet_c=-12.39).payload()[1:3] == (-123).to_bytes(2, "big", signed=True)


@pytest.mark.parametrize(
    ("message", "pattern"),
    [
        (SetCurrent(2147483.648), r"current_a=2147483\.648 is outside the wire range \[-2\.14748e\+06, 2\.1"),
        (SetCurrent(-3e6), r"int32"),
        (SetDetect(256), r"mode=256 .*\[0, 255\]"),
        (SetPosOrigin(-1), r"mode=-1 .*uint8"),
        (GetValuesSelective(2**32), r"mask=4294967296 .*\[0, 4\.29497e\+09\]"),
        (Values(temp_fet_c=3276.8), r"temp_fet_c=3276\.8 .*int16"),
        (Values(fault=300), r"fault=300 .*uint8"),
        (SetPos(1e9), r"position_rad=1000000000\.0 .*int32"),
        (SetDuty(math.nan), r"duty=nan is not a finite number; allowed \[-21474\.8, 21474\.8\]"),
        (SetCurrent(math.inf), r"current_a=inf is not a finite number"),
        (SetCurrent("2.5"), r"current_a='2\.5' is not a finite number"),  # type: ignore[arg-type]
        (RotorPosition(1e9), r"position_rad=1000000000\.0"),
        (FwVersion(256, 0, "x"), r"major=256"),
        (FwVersion(3, 40, "a\0b"), r"hw_name"),
        (FwVersion(3, 40, "hw", b"short"), r"uuid length 5"),
        (Unknown(300, b""), r"command_id=300"),
        (ValuesSelective(0x80, {}), r"missing \['erpm'\]"),
        (ValuesSelective(0x80, {"erpm": 1, "duty": 0.1}), r"unexpected \['duty'\]"),
        (ValuesSelective(-1, {}), r"mask=-1"),
    ],
)
def test_out_of_range_values_raise_naming_value_and_range(message: Message, pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        message.encode()


def test_largest_values_that_fit_encode() -> None:
    assert SetCurrent(2147483.647).payload() == H("06 7F FF FF FF")
    assert SetCurrent(-2147483.648).payload() == H("06 80 00 00 00")
    assert Values(temp_fet_c=3276.7).payload()[1:3] == H("7F FF")
    assert GetValuesSelective(2**32 - 1).payload() == H("32 FF FF FF FF")


def test_encode_frame_length_limits() -> None:
    with pytest.raises(ValueError, match=r"payload length 0 is outside the allowed range \[1, 512\]"):
        encode_frame(b"")
    with pytest.raises(ValueError, match=r"payload length 513 is outside the allowed range \[1, 512\]"):
        encode_frame(bytes(513))
    assert encode_frame(bytes(255))[:2] == H("02 FF")
    assert encode_frame(bytes(256))[:3] == H("03 01 00")
    assert len(encode_frame(bytes(512))) == MAX_FRAME_LEN


def test_crc() -> None:
    assert crc16(b"123456789") == 0x31C3 == crc16_reference(b"123456789")
    assert crc16(b"\x00") == 0 and crc16(bytes([4])) == 0x4084 == binascii.crc_hqx(bytes([4]), 0)


def test_direction_changes_meaning_of_ids() -> None:
    request = GetValues().encode()
    assert Decoder("to-motor").feed(request) == [GetValues()]
    from_motor = Decoder("from-motor")
    assert from_motor.feed(request) == [] and from_motor.stats.short_payloads == 1  # not a 73-byte reply
    to_motor = Decoder("to-motor")
    assert to_motor.feed(ROTOR_FRAME) == [Unknown(22, ROTOR_FRAME[3:-3])] and to_motor.stats.unknown_ids == 1
    assert Decoder("from-motor").feed(SetCurrent(1.0).encode()) == [Unknown(6, H("00 00 03 E8"))]
    assert set(MESSAGES_TO_MOTOR) & set(MESSAGES_FROM_MOTOR) == {0, 4, 50}


def test_selective_reply_with_mask_echo() -> None:
    reply = ValuesSelective(0x00018080, {"erpm": -2100, "fault": 3, "pid_pos_rad": math.radians(-45.5)})
    payload = reply.payload()
    assert payload[:5] == H("32 00 01 80 80") and len(payload) == 5 + 4 + 1 + 4
    (back,) = Decoder("from-motor").feed(reply.encode())
    assert back.mask == 0x00018080 and back.mask_echo and back.values["erpm"] == -2100
    assert back.values["fault"] == 3 and math.degrees(back.values["pid_pos_rad"]) == pytest.approx(-45.5)
    assert back.encode() == reply.encode()
    full = Values(erpm=-2100, fault=3, pid_pos_rad=math.radians(-45.5))
    assert ValuesSelective.from_values(full, 0x00018080).encode() == reply.encode()
    everything = ValuesSelective.from_values(full, 0xFFFFFFFF, status=2)
    assert len(everything.payload()) == 5 + 73 and everything.values["status"] == 2


def test_selective_reply_without_mask_echo_manual_example() -> None:
    frame = H("02 03 32 00 81 2A 6C 03")  # CubeMars manual p.42: motor temperature, no mask echo
    echo = Decoder("from-motor")
    assert echo.feed(frame) == [] and echo.stats.short_payloads == 1
    blind = Decoder("from-motor", selective_mask_echo=False)
    assert blind.feed(frame) == [Unknown(50, H("00 81"))] and blind.stats.unknown_ids == 1
    blind.selective_mask = 1 << 1
    (reply,) = blind.feed(frame)
    assert reply == ValuesSelective(2, {"temp_motor_c": 12.9}, mask_echo=False)
    assert reply.encode() == frame


def test_fw_version_round_trip_and_malformed() -> None:
    uuid = bytes(range(12))
    reply = FwVersion(3, 40, "AK60-6", uuid)
    frame = reply.encode()
    assert frame[2:-3] == H("00 03 28") + b"AK60-6\0" + uuid
    decoder = Decoder("from-motor")
    assert decoder.feed(frame) == [reply]
    assert decoder.feed(encode_frame(H("00 03 28") + b"AK60-6" + uuid)) == []  # NUL missing
    assert decoder.feed(encode_frame(H("00 03 28") + b"AK\0" + uuid[:11])) == []  # UUID cut short
    assert decoder.stats.short_payloads == 2
    later = FwVersion(6, 5, "60_MK6", uuid, extra=H("01 00 00"))
    assert FwVersion.from_payload(later.payload()) == later


def test_from_payload_checks_id_and_length() -> None:
    with pytest.raises(ValueError, match="payload id 7 is not SetCurrent's id 6"):
        SetCurrent.from_payload(H("07 00 00 00 00"))
    with pytest.raises(ShortPayloadError, match="SetCurrent needs 5 payload bytes, got 3"):
        SetCurrent.from_payload(H("06 00 00"))
    with pytest.raises(ShortPayloadError):
        Values.from_payload(MANUAL_REPLY[2:-4])
    with pytest.raises(ShortPayloadError):
        Alive.from_payload(b"")
    assert SetCurrent.from_payload(H("06 00 00 09 C4 FF")) == SetCurrent(2.5)  # trailing bytes ignored


def test_lazily_decoded_values_behave_like_constructed_ones() -> None:
    (v,) = Decoder("from-motor").feed(MANUAL_REPLY)
    built = Values(**{f.name: getattr(v, f.name) for f in VALUES_FIELDS})
    (fresh,) = Decoder("from-motor").feed(MANUAL_REPLY)
    assert fresh == built and hash(fresh) == hash(built) and repr(fresh) == repr(built)
    assert pickle.loads(pickle.dumps(Decoder("from-motor").feed(MANUAL_REPLY)[0])) == built
    assert copy.deepcopy(Decoder("from-motor").feed(MANUAL_REPLY)[0]) == built
    assert dataclasses.replace(v, erpm=5).erpm == 5 and dataclasses.replace(v, erpm=5).v_in_v == 24.6
    assert not hasattr(v, "no_such_field")
    with pytest.raises(dataclasses.FrozenInstanceError):
        v.erpm = 3  # type: ignore[misc]


def test_decoder_rejects_bad_configuration() -> None:
    with pytest.raises(ValueError, match="direction='sideways'"):
        Decoder("sideways")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="scale=0 must be finite and > 0"):
        Decoder("from-motor", rotor_position_scale=0)
    with pytest.raises(ValueError, match="scale=nan"):
        RotorPosition(1.0, math.nan).encode()


def test_short_form_with_zero_length_and_long_form_with_short_length_are_rejected() -> None:
    good = SetCurrent(1.0).encode()
    decoder = Decoder("to-motor")
    # 02 00: LEN 0 rejected; 03 00 05: long form claiming 5 bytes rejected (must use 02)
    assert decoder.feed(H("02 00") + H("03 00 05") + good[2:] + good) == [SetCurrent(1.0)]
    assert decoder.stats.dropped_bytes == 2 + 3 + len(good) - 2
    assert decoder.stats.crc_errors == 0
    long255 = H("03 00 FF") + encode_frame(bytes([6]) + bytes(254))[2:]  # LEN 255 in long form is accepted
    assert Decoder("to-motor").feed(long255) == [SetCurrent(0.0)]


# ---- regressions for pyvesc's failure modes ---------------------------------------------------------


def test_500_start_bytes_then_valid_frame() -> None:
    decoder = Decoder("to-motor")
    assert decoder.feed(b"\x02" * 500 + SetCurrent(2.5).encode()) == [SetCurrent(2.5)]
    assert decoder.stats.dropped_bytes == 500 and decoder.buffered == 0


def test_100_kb_of_random_junk_before_a_valid_frame() -> None:
    rng = random.Random(20240611)
    junk = rng.randbytes(100_000)
    decoder = Decoder("to-motor")
    out = []
    for i in range(0, len(junk), 4096):
        out += decoder.feed(junk[i : i + 4096])
        assert decoder.buffered < MAX_FRAME_LEN
    out += decoder.feed(SetCurrent(2.5).encode() + bytes(MAX_FRAME_LEN))
    assert out[-1] == SetCurrent(2.5)
    frame_bytes = sum(len(m.encode()) for m in out)
    assert decoder.stats.bytes_in == decoder.stats.dropped_bytes + frame_bytes + decoder.buffered


def test_false_long_header_before_valid_frames() -> None:
    frames = [SetCurrent(i / 10).encode() for i in range(30)]
    decoder = Decoder("to-motor")
    assert decoder.feed(H("03 FF FF") + b"".join(frames)) == [SetCurrent(i / 10) for i in range(30)]
    assert decoder.stats.dropped_bytes == 3
    plausible = Decoder("to-motor")  # 03 01 00 claims 256 bytes: frames come out once it is disproved
    assert plausible.feed(H("03 01 00") + b"".join(frames)) == [SetCurrent(i / 10) for i in range(30)]


@pytest.mark.parametrize("junk", [0x00, 0x02, 0x03, 0x55, 0xFF])
@pytest.mark.parametrize("split", [1, 2, 4, 9])
def test_one_junk_byte_before_a_frame_split_across_two_reads(junk: int, split: int) -> None:
    frame = bytes([junk]) + SetCurrent(2.5).encode()
    decoder = Decoder("to-motor")
    assert decoder.feed(frame[:split]) + decoder.feed(frame[split:]) == [SetCurrent(2.5)]
    assert decoder.stats.dropped_bytes == 1 and decoder.buffered == 0


def test_unknown_id_is_returned_and_counted() -> None:
    decoder = Decoder("to-motor")
    out = decoder.feed(encode_frame(H("C8 01 02")) + Alive().encode())
    assert out == [Unknown(200, H("01 02")), Alive()] and decoder.stats.unknown_ids == 1
    assert out[0].encode() == encode_frame(H("C8 01 02"))


def test_too_short_payload_is_counted_and_skipped() -> None:
    decoder = Decoder("to-motor")
    assert decoder.feed(encode_frame(H("06 00 00")) + SetRpm(5).encode()) == [SetRpm(5)]
    assert decoder.stats.short_payloads == 1 and decoder.stats.frames == 2
    assert decoder.stats.dropped_bytes == 0


def test_pathological_input_does_not_recurse() -> None:
    stream = (H("02 05 06 00") + H("03 02 00") + b"\x02\xff" + b"\x03") * 20_000
    stream += Alive().encode() + bytes(MAX_FRAME_LEN)
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(len(inspect.stack()) + 40)
    try:
        out = Decoder("to-motor").feed(stream)
    finally:
        sys.setrecursionlimit(old)
    assert out[-1] == Alive()


def test_reset_and_buffered() -> None:
    decoder = Decoder("to-motor")
    frame = SetCurrent(2.5).encode()
    assert decoder.feed(frame[:6]) == [] and decoder.buffered == 6
    decoder.reset()
    assert decoder.buffered == 0 and decoder.stats.dropped_bytes == 6
    assert decoder.feed(frame[6:] + frame) == [SetCurrent(2.5)]
    assert decoder.stats.as_dict()["bytes_in"] == 6 + 4 + 10


def test_message_fields_are_slots_without_class_level_defaults() -> None:
    for cls in [*MESSAGES_TO_MOTOR.values(), *MESSAGES_FROM_MOTOR.values(), Unknown]:
        for f in dataclasses.fields(cls):
            assert isinstance(vars(cls)[f.name], types.MemberDescriptorType), (cls.__name__, f.name)
    assert not hasattr(SetCurrent(1.0), "__dict__") and not hasattr(Values(), "__dict__")


def test_command_ids_match_the_table() -> None:
    assert {cls.COMMAND_ID for cls in MESSAGES_TO_MOTOR.values()} | {22} == {int(c) for c in CommandId}
    assert SetPosMulti().payload() == H("5C 00 00 00 00") and SetPosSingle().payload() == H("5D 00 00 00 00")

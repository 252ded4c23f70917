"""BNO08x UART-RVC frame codec: fixed vectors (PROTOCOLS.md D.3), exact round trips, range errors."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol import rvc
from protocol.rvc import RvcDecoder, RvcFrame, RvcRaw, pack_raw, unpack_raw

DATASHEET = bytes.fromhex("AA AA DE 01 00 92 FF 25 08 8D FE EC FF D1 03 00 00 00 E7")
CONSTRUCTED = bytes.fromhex("AA AA 2A D2 04 C9 FD E2 45 0C 00 DE FF EA 03 00 00 00 C3")
G = 9.80665 / 1000.0  # m/s^2 per milli-g, written independently of the module constant

int16 = st.integers(-32768, 32767)
uint8 = st.integers(0, 255)
raws = st.builds(RvcRaw, uint8, int16, int16, int16, int16, int16, int16, uint8, uint8)


def test_datasheet_vector_decodes_to_the_datasheet_values():
    f = RvcFrame.from_bytes(DATASHEET)
    assert f.index == 222
    assert math.degrees(f.yaw_rad) == pytest.approx(0.01, rel=1e-12)
    assert math.degrees(f.pitch_rad) == pytest.approx(-1.10, rel=1e-12)
    assert math.degrees(f.roll_rad) == pytest.approx(20.85, rel=1e-12)
    assert f.accel_x_mps2 == pytest.approx(-371 * G, rel=1e-12)
    assert f.accel_y_mps2 == pytest.approx(-20 * G, rel=1e-12)
    assert f.accel_z_mps2 == pytest.approx(977 * G, rel=1e-12)
    assert round(f.accel_x_mps2, 3) == -3.638 and round(f.accel_z_mps2, 3) == 9.581
    assert (f.motion_intent, f.motion_request) == (0, 0)


def test_constructed_vector_decodes_like_the_adafruit_parser():
    f = RvcFrame.from_bytes(CONSTRUCTED)
    assert f.index == 0x2A
    degs = [round(math.degrees(a), 2) for a in (f.yaw_rad, f.pitch_rad, f.roll_rad)]
    assert degs == [12.34, -5.67, 178.9]
    accel = [round(a, 4) for a in (f.accel_x_mps2, f.accel_y_mps2, f.accel_z_mps2)]
    assert accel == [0.1177, -0.3334, 9.8263]


@pytest.mark.parametrize("frame", [DATASHEET, CONSTRUCTED])
def test_vectors_reencode_byte_exact(frame):
    assert RvcFrame.from_bytes(frame).encode() == frame
    assert RvcDecoder().feed(frame) == [RvcFrame.from_bytes(frame)]  # the stream decoder's path agrees


def test_constructed_vector_encodes_from_values_given_in_degrees_and_mg():
    f = RvcFrame(
        index=0x2A,
        yaw_rad=math.radians(12.34),
        pitch_rad=math.radians(-5.67),
        roll_rad=math.radians(178.90),
        accel_x_mps2=12 * G,
        accel_y_mps2=-34 * G,
        accel_z_mps2=1002 * G,
    )
    assert f.encode() == CONSTRUCTED


def test_every_int16_value_survives_si_conversion_exactly():
    for v in range(-32768, 32768):
        raw = RvcRaw(v & 0xFF, v, v, v, v, v, v)
        assert RvcFrame.from_raw(raw).to_raw() == raw, v


@given(raws)
def test_raw_round_trip_over_full_field_ranges(raw):
    wire = pack_raw(raw)
    assert len(wire) == 19 and wire[:2] == b"\xaa\xaa" and wire[17] == 0
    assert wire[18] == sum(wire[2:18]) % 256
    assert unpack_raw(wire) == raw
    frame = RvcFrame.from_bytes(wire)
    assert frame.to_raw() == raw
    assert frame.encode() == wire


@given(
    st.floats(-32768.99, 32767.99, allow_nan=False),
    st.sampled_from([("yaw_rad", rvc.CENTIDEG_TO_RAD), ("accel_z_mps2", rvc.MG_TO_MPS2)]),
)
def test_encode_truncates_toward_zero(lsb_value, field_and_lsb):
    name, lsb = field_and_lsb
    si = lsb_value * lsb
    values = dict(index=0, yaw_rad=0.0, pitch_rad=0.0, roll_rad=0.0,
                  accel_x_mps2=0.0, accel_y_mps2=0.0, accel_z_mps2=0.0)
    values[name] = si
    decoded = getattr(RvcFrame.from_bytes(RvcFrame(**values).encode()), name)
    assert abs(decoded) <= abs(si) * (1 + 1e-12)  # never rounded away from zero
    assert abs(si - decoded) < lsb * (1 + 1e-9)  # by less than one LSB


def test_truncation_examples():
    f = RvcFrame(0, math.radians(12.349), math.radians(-12.349), 0.0, 12.9 * G, -12.9 * G, 0.0)
    raw = f.to_raw()
    assert (raw.yaw_cdeg, raw.pitch_cdeg, raw.accel_x_mg, raw.accel_y_mg) == (1234, -1234, 12, -12)


@pytest.mark.parametrize(
    "name, value, needle",
    [
        ("yaw_rad", 6.0, "yaw_rad=6.0"),
        ("roll_rad", -5.8, "roll_rad=-5.8"),
        ("accel_x_mps2", 400.0, "accel_x_mps2=400.0"),
        ("accel_z_mps2", math.nan, "accel_z_mps2=nan"),
        ("index", 256, "index=256"),
        ("motion_intent", -1, "motion_intent=-1"),
    ],
)
def test_out_of_range_values_raise_naming_value_and_range(name, value, needle):
    values = dict(index=0, yaw_rad=0.0, pitch_rad=0.0, roll_rad=0.0,
                  accel_x_mps2=0.0, accel_y_mps2=0.0, accel_z_mps2=0.0)
    values[name] = value
    with pytest.raises(ValueError) as exc:
        RvcFrame(**values).encode()
    msg = str(exc.value)
    assert needle in msg
    if name.endswith("_rad"):
        assert "-5.71" in msg and "5.71" in msg  # +-327.68 degrees in radians
    if name.startswith("accel"):
        assert "321.3" in msg  # 32767 mg in m/s^2


def test_largest_values_that_fit_encode():
    top = RvcFrame(255, 32767 * rvc.CENTIDEG_TO_RAD, -32768 * rvc.CENTIDEG_TO_RAD, 0.0,
                   32767 * G, -32768 * G, 0.0, 255, 255)
    assert top.to_raw() == RvcRaw(255, 32767, -32768, 0, 32767, -32768, 0, 255, 255)


@pytest.mark.parametrize(
    "frame, needle",
    [
        (DATASHEET[:-1], "length 18"),
        (b"\xab" + DATASHEET[1:], "header ab aa"),
        (DATASHEET[:-1] + b"\xe8", "checksum 0xe8"),
    ],
)
def test_from_bytes_rejects_bad_frames(frame, needle):
    with pytest.raises(ValueError, match=needle):
        RvcFrame.from_bytes(frame)


def test_reserved_byte_is_covered_by_checksum_but_ignored():
    body = bytearray(CONSTRUCTED)
    body[17] = 0x55
    body[18] = sum(body[2:18]) % 256
    assert RvcFrame.from_bytes(bytes(body)) == RvcFrame.from_bytes(CONSTRUCTED)


def test_motion_intent_and_request_sit_in_bytes_15_and_16():
    wire = RvcFrame(1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, motion_intent=3, motion_request=4).encode()
    assert (wire[15], wire[16], wire[17]) == (3, 4, 0)
    assert RvcFrame.from_bytes(wire).motion_intent == 3 and RvcFrame.from_bytes(wire).motion_request == 4

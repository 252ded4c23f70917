"""The AK-series CAN codecs: MIT mode and servo mode (round trips, saturation, the special frames)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol import can_mit as mit
from protocol import can_servo as servo

L = mit.AK60_6
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


def _in(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False)


@given(_in(-L.p_max, L.p_max), _in(-L.v_max, L.v_max), _in(0, L.kp_max), _in(0, L.kd_max), _in(-L.t_max, L.t_max))
def test_mit_command_round_trip_within_one_step(p, v, kp, kd, t):
    cmd = mit.MitCommand(p, v, kp, kd, t)
    back = mit.decode_command(mit.encode_command(cmd))
    for got, want, span, bits in ((back.p_des, p, 2 * L.p_max, 16), (back.v_des, v, 2 * L.v_max, 12),
                                  (back.kp, kp, L.kp_max, 12), (back.kd, kd, L.kd_max, 12),
                                  (back.t_ff, t, 2 * L.t_max, 12)):
        step = span / ((1 << bits) - 1)
        assert want - step * (1 + 1e-9) <= got <= want + 1e-9 * span  # truncation: never above, within a step


def _fields(d: bytes) -> tuple[int, ...]:
    return ((d[0] << 8) | d[1], (d[2] << 4) | (d[3] >> 4), ((d[3] & 0xF) << 8) | d[4], (d[5] << 4) | (d[6] >> 4),
            ((d[6] & 0xF) << 8) | d[7])


@given(st.binary(min_size=8, max_size=8))
def test_mit_command_bytes_round_trip_within_one_code(data):
    # the manual's truncating float_to_uint may land one code low on a decoded value (float rounding)
    if mit.special_frame(data):
        return
    again = _fields(mit.encode_command(mit.decode_command(data)))
    assert all(0 <= a - b <= 1 for a, b in zip(_fields(data), again, strict=True))


@given(finite, finite, finite, finite, finite)
def test_mit_command_saturates_at_the_limits(p, v, kp, kd, t):
    back = mit.decode_command(mit.encode_command(mit.MitCommand(p, v, kp, kd, t)))
    assert -L.p_max <= back.p_des <= L.p_max and -L.v_max <= back.v_des <= L.v_max
    assert 0 <= back.kp <= L.kp_max and 0 <= back.kd <= L.kd_max and -L.t_max <= back.t_ff <= L.t_max
    if p >= L.p_max:
        assert back.p_des == L.p_max
    if t <= -L.t_max:
        assert back.t_ff == -L.t_max
    if kp >= L.kp_max:
        assert back.kp == L.kp_max


def test_mit_layout_vector():
    # p = +12.5 (0xFFFF), v = 0 (2047 = 0x7FF), kp = 0, kd = 5 (0xFFF), t = -15 (0)
    data = mit.encode_command(mit.MitCommand(12.5, 0.0, 0.0, 5.0, -15.0))
    assert data == bytes([0xFF, 0xFF, 0x7F, 0xF0, 0x00, 0xFF, 0xF0, 0x00])


def test_mit_special_frames():
    assert mit.ENTER_MOTOR_MODE.hex() == "fffffffffffffffc"
    assert mit.EXIT_MOTOR_MODE.hex() == "fffffffffffffffd"
    assert mit.SET_ZERO.hex() == "fffffffffffffffe"
    assert [mit.special_frame(f) for f in (mit.ENTER_MOTOR_MODE, mit.EXIT_MOTOR_MODE, mit.SET_ZERO)] == [
        "enter", "exit", "zero"]
    assert mit.special_frame(b"\xff" * 8) == "" and mit.special_frame(mit.ENTER_MOTOR_MODE[:7]) == ""
    # no command within the ranges encodes to a special frame: kd = max and t = max give ..FF FF, not FC..FE
    assert not mit.special_frame(mit.encode_command(mit.MitCommand(99, 99, 999, 9, 99)))


@given(st.integers(0, 255), _in(-L.p_max, L.p_max), _in(-L.v_max, L.v_max), _in(-L.t_max, L.t_max),
       st.integers(-128, 127), st.integers(0, 255))
def test_mit_reply_round_trip(driver_id, p, v, t, temp, err):
    r = mit.decode_reply(mit.encode_reply(mit.MitReply(driver_id, p, v, t, temp, err)))
    assert (r.driver_id, r.temperature_c, r.error) == (driver_id, temp, err)
    assert abs(r.p - p) <= 2 * L.p_max / 65535 * 1.000001
    assert abs(r.v - v) <= 2 * L.v_max / 4095 * 1.000001 and abs(r.t - t) <= 2 * L.t_max / 4095 * 1.000001
    assert mit.decode_reply(mit.encode_reply(mit.MitReply(driver_id, p, v, t))[:6]).error == 0


def test_mit_rejects_wrong_lengths():
    with pytest.raises(ValueError, match="7 data bytes"):
        mit.decode_command(b"\x00" * 7)
    with pytest.raises(ValueError, match="5 data bytes"):
        mit.decode_reply(b"\x00" * 5)


# ------------------------------------------------------------------ servo mode
@given(st.sampled_from([servo.PacketId.SET_CURRENT, servo.PacketId.SET_CURRENT_BRAKE]), _in(-60.0, 60.0),
       st.integers(0, 255))
def test_servo_current_round_trip(packet, amps, driver_id):
    arb = servo.command_id(packet, driver_id)
    assert servo.split_id(arb) == (packet, driver_id)
    cmd = servo.decode_command(arb, servo.encode_command(packet, amps))
    assert cmd.packet == packet and abs(cmd.value - amps) <= 0.0005 + 1e-12


@given(_in(-1.0, 1.0), _in(-1e5, 1e5), _in(-2e5, 2e5), st.integers(-32768, 32767), st.integers(-32768, 32767))
def test_servo_other_packets_round_trip(duty, erpm, pos_deg, spd, acc):
    P = servo.PacketId
    assert abs(servo.decode_command(P.SET_DUTY << 8, servo.encode_command(P.SET_DUTY, duty)).value - duty) <= 5e-6
    assert abs(servo.decode_command(P.SET_RPM << 8, servo.encode_command(P.SET_RPM, erpm)).value - erpm) <= 0.5
    assert abs(servo.decode_command(P.SET_POS << 8, servo.encode_command(P.SET_POS, pos_deg)).value - pos_deg) <= 5e-5
    c = servo.decode_command(P.SET_POS_SPD << 8, servo.encode_command(P.SET_POS_SPD, pos_deg, spd * 10, acc * 10))
    assert abs(c.value - pos_deg) <= 5e-5 and (c.speed_erpm, c.accel_erpm_s) == (spd * 10, acc * 10)


def test_servo_scalings_as_the_manual_routines_pack_them():
    """Manual V1.0.8 5.1.5-5.1.7: SET_POS int32 deg x 10 000; SET_POS_SPD int32 deg x 10 000, int16 spd / 10,
    int16 RPA / 10 (180 deg at 5000 ERPM and 30 000 ERPM/s, the manual's own example values)."""
    P = servo.PacketId
    assert servo.encode_command(P.SET_POS, 180.0) == (1_800_000).to_bytes(4, "big")
    assert servo.encode_command(P.SET_POS_SPD, 180.0, 5000, 30_000) == bytes.fromhex("001b7740" "01f4" "0bb8")
    assert servo.encode_command(P.SET_ORIGIN_HERE, 2) == b"\x02"  # restore the default zero


def test_servo_special_frames_unknown_packets_and_error_codes():
    assert servo.special_frame(0x01, b"\xff" * 7 + b"\xfc") == "enter"  # power on, as opensourceleg sends it
    assert servo.special_frame(0x68, b"\xff" * 7 + b"\xfd") == "exit"
    assert servo.special_frame(0x101, b"\xff" * 7 + b"\xfc") == ""  # packet 1: a SET_CURRENT of -1 mA
    assert servo.special_frame(0x01, b"\x00\x00\x03\xe8") == ""  # a real SET_DUTY
    with pytest.raises(servo.UnknownPacket, match="packet id 7"):
        servo.decode_command(0x0701, b"\x01")
    assert [servo.error_code(f) for f in (0, 1, 2, 4, 5, 6, 11, 18)] == [0, 3, 4, 2, 1, 1, 5, 6]


@given(finite)
def test_servo_current_saturates_at_int32(amps):
    cmd = servo.decode_command(servo.PacketId.SET_CURRENT << 8, servo.encode_command(servo.PacketId.SET_CURRENT, amps))
    assert -(2**31) / 1000 <= cmd.value <= (2**31 - 1) / 1000
    if amps > 3e6:
        assert cmd.value == (2**31 - 1) / 1000


@given(_in(-3200, 3200), _in(-3e5, 3e5), _in(-300, 300), st.integers(-128, 127), st.integers(0, 255))
def test_servo_status_round_trip(pos, spd, cur, temp, err):
    s = servo.decode_status(servo.encode_status(servo.ServoStatus(pos, spd, cur, temp, err)))
    assert abs(s.position_deg - pos) <= 0.05 + 1e-9 and abs(s.speed_erpm - spd) <= 5 + 1e-6
    assert abs(s.current_a - cur) <= 0.005 + 1e-9 and (s.temperature_c, s.error) == (temp, err)


@given(finite, finite, finite)
def test_servo_status_saturates(pos, spd, cur):
    s = servo.decode_status(servo.encode_status(servo.ServoStatus(pos, spd, cur)))
    assert abs(s.position_deg) <= 3276.8 and abs(s.current_a) <= 327.68
    if cur > 400:
        assert s.current_a == 327.67


def test_servo_ids_and_bad_frames():
    assert servo.status_id(0x68) == 0x2968
    assert servo.command_id(servo.PacketId.SET_CURRENT, 0x68) == 0x168
    assert servo.encode_command(servo.PacketId.SET_CURRENT, 1.5).hex() == "000005dc"  # 1500 mA
    assert servo.encode_command(servo.PacketId.SET_ORIGIN_HERE, 1) == b"\x01"
    assert not math.isnan(servo.decode_command(0x0500, b"\x00").value)
    with pytest.raises(ValueError, match="packet id 9"):
        servo.decode_command(0x0901, b"\x00" * 4)
    with pytest.raises(ValueError, match="needs 4 data bytes"):
        servo.decode_command(0x0101, b"\x00" * 3)
    with pytest.raises(ValueError, match="driver_id 256"):
        servo.command_id(1, 256)

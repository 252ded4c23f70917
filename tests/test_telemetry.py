"""Telemetry record codec: layout, full-range round trips, range errors, compatibility, CSV rows."""

import binascii
import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.cobs import cobs_decode
from protocol.telemetry import (
    BASE_FIELD_COUNT,
    RECORD_COLUMNS,
    RECORD_FIELDS,
    RECORD_FRAME_LEN,
    RECORD_SPECS,
    CrcError,
    FaultReason,
    FieldSpec,
    FrameError,
    SupervisorState,
    TelemetryRecord,
    UnknownVersionError,
    crc16,
    decode_frame,
    decode_payload,
    encode_payload,
    encode_record,
    frame_payload,
    record_to_row,
)

f32 = st.floats(width=32)
records = st.builds(
    TelemetryRecord,
    seq=st.integers(0, 2**32 - 1),
    time_cycles=st.integers(0, 2**64 - 1),
    reference_rad=f32, encoder_angle_rad=f32, imu_pitch_rad=f32, fused_angle_rad=f32,
    velocity_rad_s=f32, current_cmd_a=f32, current_meas_a=f32, torque_est_nm=f32,
    supervisor_state=st.integers(0, 255), fault_reason=st.integers(0, 255),
    deadline_misses=st.integers(0, 2**32 - 1),
)


def same(a: TelemetryRecord, b: TelemetryRecord) -> bool:
    """Field-wise equality where NaN equals NaN."""
    for name in RECORD_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if not (x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))):
            return False
    return True


def test_field_list_matches_the_brief():
    assert RECORD_FIELDS == (
        "seq", "time_cycles", "reference_rad", "encoder_angle_rad", "imu_pitch_rad", "fused_angle_rad",
        "velocity_rad_s", "current_cmd_a", "current_meas_a", "torque_est_nm", "supervisor_state",
        "fault_reason", "deadline_misses",
    )
    assert "".join(s.fmt for s in RECORD_SPECS) == "IQffffffffBBI"


def test_enum_codes_are_fixed():
    assert [(m.name, m.value) for m in SupervisorState] == [("INIT", 0), ("RUN", 1), ("SAFE", 2)]
    assert [m.name for m in FaultReason] == [
        "NONE", "ANGLE_LIMIT", "CURRENT_LIMIT", "MOTOR_TIMEOUT", "IMU_TIMEOUT", "SENSOR_DISAGREEMENT",
        "MOTOR_FAULT", "DEADLINE_MISSES", "ESTOP", "WATCHDOG", "TASK_OVERRUN", "LINK_LOST", "COMMAND_STALE",
        "CONTROLLER_ERROR", "MOTOR_ENCODER_DISAGREEMENT", "OVER_TEMPERATURE", "IMU_FROZEN", "MOTOR_JAM",
    ]
    assert [m.value for m in FaultReason] == list(range(18))


def test_crc16_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1
    assert crc16(b"") == 0xFFFF
    # bitwise reference: poly 0x1021, init 0xFFFF, MSB first
    data, reg = b"\x01\x0d\xe8\x03", 0xFFFF
    for byte in data:
        reg ^= byte << 8
        for _ in range(8):
            reg = ((reg << 1) ^ 0x1021) & 0xFFFF if reg & 0x8000 else (reg << 1) & 0xFFFF
    assert crc16(data) == reg == binascii.crc_hqx(data, 0xFFFF)


def test_layout_of_one_record():
    rec = TelemetryRecord(seq=0x01020304, time_cycles=2**40 + 5, reference_rad=1.5,
                          supervisor_state=SupervisorState.SAFE, fault_reason=FaultReason.LINK_LOST,
                          deadline_misses=7)
    wire = encode_record(rec)
    assert len(wire) == RECORD_FRAME_LEN == 56 and wire[-1] == 0 and 0 not in wire[:-1]
    p = cobs_decode(wire[:-1])
    assert len(p) == 54
    assert p[0] == 1 and p[1] == BASE_FIELD_COUNT == 13
    assert struct.unpack_from("<IQf", p, 2) == (0x01020304, 2**40 + 5, 1.5)
    assert (p[46], p[47]) == (2, 11)
    assert struct.unpack_from("<I", p, 48) == (7,)
    assert struct.unpack_from("<H", p, 52) == (crc16(p[:52]),)


@given(records)
def test_round_trip_over_full_field_ranges(rec):
    wire = encode_record(rec)
    assert len(wire) == RECORD_FRAME_LEN
    back = decode_frame(wire)
    assert same(back, rec)
    assert encode_record(back) == wire
    assert encode_payload([getattr(rec, n) for n in RECORD_FIELDS]) == cobs_decode(wire[:-1])


def test_floats_travel_as_float32():
    back = decode_frame(encode_record(TelemetryRecord(seq=0, time_cycles=0, reference_rad=0.1)))
    assert back.reference_rad == struct.unpack("<f", struct.pack("<f", 0.1))[0] != 0.1


def test_decoded_enums_are_members_and_unknown_codes_stay_ints():
    back = decode_frame(encode_record(TelemetryRecord(0, 0, supervisor_state=1, fault_reason=4)))
    assert back.supervisor_state is SupervisorState.RUN and back.fault_reason is FaultReason.IMU_TIMEOUT
    back = decode_frame(encode_record(TelemetryRecord(0, 0, supervisor_state=9, fault_reason=200)))
    assert type(back.supervisor_state) is int and back.supervisor_state == 9 and back.fault_reason == 200


@pytest.mark.parametrize(
    "kwargs, needle",
    [
        (dict(seq=-1), "seq=-1 is out of range: uint32 allows integers 0..4294967295"),
        (dict(seq=2**32), "seq=4294967296"),
        (dict(time_cycles=2**64), "time_cycles=18446744073709551616 is out of range: uint64"),
        (dict(torque_est_nm=1e39), "torque_est_nm=1e+39 is out of range: float32"),
        (dict(supervisor_state=256), "supervisor_state=256 is out of range: uint8 allows integers 0..255"),
        (dict(deadline_misses=1.5), "deadline_misses=1.5"),
    ],
)
def test_out_of_range_values_raise_naming_value_and_range(kwargs, needle):
    base = dict(seq=0, time_cycles=0)
    base.update(kwargs)
    with pytest.raises(ValueError) as exc:
        encode_record(TelemetryRecord(**base))
    assert needle in str(exc.value)


def _payload(rec: TelemetryRecord, extra_specs=(), extra_values=()):
    specs = RECORD_SPECS + tuple(extra_specs)
    return encode_payload([getattr(rec, n) for n in RECORD_FIELDS] + list(extra_values), specs)


@given(records, st.lists(st.sampled_from(["B", "H", "I", "f", "d", "Q"]), min_size=1, max_size=8), st.data())
def test_new_writer_extra_trailing_fields_decode_with_old_field_list(rec, fmts, data):
    extra = [FieldSpec(f"new_{i}", fmt) for i, fmt in enumerate(fmts)]
    values = [0.5 if f in "fd" else data.draw(st.integers(0, 255)) for f in fmts]
    payload = _payload(rec, extra, values)
    assert payload[1] == 13 + len(fmts)
    assert same(decode_frame(frame_payload(payload)), rec)
    # a reader that knows the new fields sees them too
    out = decode_payload(payload, RECORD_SPECS + tuple(extra))
    assert [out[s.name] for s in extra] == values


def test_old_writer_record_fills_new_reader_fields_with_defaults():
    rec = TelemetryRecord(seq=5, time_cycles=10, current_cmd_a=1.0)
    newer = RECORD_SPECS + (FieldSpec("battery_v", "f", 24.0), FieldSpec("motor_temp_c", "h", -1))
    out = decode_payload(_payload(rec), newer)
    assert out["battery_v"] == 24.0 and out["motor_temp_c"] == -1
    assert out["seq"] == 5 and out["current_cmd_a"] == 1.0


def test_inconsistent_payloads_are_rejected_with_the_right_error():
    rec = TelemetryRecord(seq=1, time_cycles=2)
    good = _payload(rec)
    decode_payload(good)

    def recrc(body: bytes) -> bytes:
        return body + struct.pack("<H", crc16(body))

    with pytest.raises(CrcError):
        decode_payload(good[:-1] + bytes([good[-1] ^ 1]))
    with pytest.raises(UnknownVersionError):
        decode_payload(recrc(b"\x02" + good[1:-2]))
    with pytest.raises(FrameError, match="field count 12"):
        decode_payload(recrc(good[:1] + b"\x0c" + good[2:-2]))
    with pytest.raises(FrameError, match="do not fit"):
        decode_payload(recrc(good[:-3]))  # one byte short
    with pytest.raises(FrameError, match="do not fit"):
        decode_payload(recrc(good[:-2] + b"\x00"))  # one byte too many for 13 fields
    with pytest.raises(FrameError, match="do not fit"):
        decode_payload(recrc(good[:1] + b"\x0f" + good[2:-2] + b"\x00"))  # 15 fields but 1 extra byte
    with pytest.raises(FrameError, match="too short"):
        decode_payload(b"\x01\x0d\x00")


def test_record_to_row_has_degrees_and_names():
    rec = TelemetryRecord(seq=3, time_cycles=4, reference_rad=math.pi / 4, velocity_rad_s=-math.pi,
                          supervisor_state=SupervisorState.SAFE, fault_reason=FaultReason.ESTOP)
    row = record_to_row(rec)
    assert tuple(row) == RECORD_COLUMNS
    assert row["reference_deg"] == pytest.approx(45.0) and row["velocity_deg_s"] == pytest.approx(-180.0)
    assert row["reference_rad"] == math.pi / 4
    assert (row["supervisor_state"], row["supervisor_state_name"]) == (2, "SAFE")
    assert (row["fault_reason"], row["fault_reason_name"]) == (8, "ESTOP")
    assert record_to_row(TelemetryRecord(0, 0, fault_reason=99))["fault_reason_name"] == "UNKNOWN_99"
    assert all(c.endswith(("_deg", "_deg_s")) for c in RECORD_COLUMNS if "deg" in c)


def test_record_fits_the_line_budget_at_1khz():
    bits_per_ms = 921600 / 1000
    assert RECORD_FRAME_LEN * 10 < bits_per_ms * 0.65  # 56 bytes = 60.8 % of the link

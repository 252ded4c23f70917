"""docs/telemetry.md: the worked example on the wire decodes to the record the document describes."""

import re
from pathlib import Path

from protocol.cobs import cobs_decode
from protocol.telemetry import (
    RECORD_FRAME_LEN,
    FaultReason,
    SupervisorState,
    TelemetryDecoder,
    TelemetryRecord,
    encode_record,
)

DOC = Path(__file__).resolve().parents[1] / "docs" / "telemetry.md"
EXAMPLE = TelemetryRecord(
    seq=1000, time_cycles=168_000_000, reference_rad=0.25, encoder_angle_rad=0.2421875, imu_pitch_rad=0.25,
    fused_angle_rad=0.2470703125, velocity_rad_s=-1.5, current_cmd_a=2.5, current_meas_a=2.375,
    torque_est_nm=0.1875, supervisor_state=SupervisorState.RUN, fault_reason=FaultReason.NONE,
    deadline_misses=3,
)


def _wire_block() -> bytes:
    text = DOC.read_text(encoding="utf-8")
    m = re.search(r"<!-- telemetry-example-frame -->\s*```hex\n(.*?)```", text, re.S)
    assert m, "the example frame block is missing from docs/telemetry.md"
    return bytes.fromhex(m.group(1))


def _payload_block() -> bytes:
    text = DOC.read_text(encoding="utf-8")
    m = re.search(r"Payload \(54 bytes\):\n```\n(.*?)```", text, re.S)
    assert m, "the example payload block is missing from docs/telemetry.md"
    return bytes.fromhex("".join(line[:25] for line in m.group(1).splitlines()))


def test_documented_frame_decodes_to_the_documented_record():
    wire = _wire_block()
    assert len(wire) == RECORD_FRAME_LEN
    dec = TelemetryDecoder()
    assert dec.feed(wire) == [EXAMPLE]
    assert dec.stats.dropped_bytes == 0


def test_documented_frame_is_what_the_encoder_writes():
    assert encode_record(EXAMPLE) == _wire_block()


def test_documented_payload_is_the_cobs_decoded_frame():
    payload = _payload_block()
    assert len(payload) == 54
    assert cobs_decode(_wire_block()[:-1]) == payload

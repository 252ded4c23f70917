"""`pafp run --trace-wire`: a slice per UART and CAN frame on the bench's wires, read back from trace.pftrace."""

from __future__ import annotations

import collections

from firmware.config import load_firmware_config
from host_tools.reports.report import TRACE_FILE, write_outputs
from host_tools.runner import RunConfig, run_virtual
from tests.trace_reader import read_trace


def _traced(tmp_path, **kw):
    r = run_virtual(RunConfig(strides=1, seed=1, duration_s=1.2, trace_wire=True, **kw))
    s = write_outputs(r, tmp_path, plot=False)
    return r, s, read_trace(tmp_path / TRACE_FILE)


def test_every_uart_frame_is_a_slice_named_by_its_message_and_none_overlap(tmp_path):
    r, s, tr = _traced(tmp_path)
    names = {t.name: collections.Counter(x.name for x in tr.on(t.name)) for t in tr.tracks.values()
             if t.name.startswith("wire ")}
    assert set(names) == {"wire motor tx", "wire motor rx", "wire imu rx", "wire telemetry tx"}
    assert names["wire telemetry tx"] == {"telemetry record": s["telemetry"]["records_sent"]}
    # the motor driver writes the command and the feedback request as one transfer: one slice naming both
    assert sum(n for k, n in names["wire motor tx"].items() if k.startswith("SetCurrent")) > 500
    assert names["wire motor tx"]["SetCurrent, GetValuesSelective"] > 500 and names["wire imu rx"]["RVC frame"] > 50
    assert sum(names["wire motor rx"].values()) >= s["motor_link"]["replies"]
    byte_ns = 10 * 1e9 / 921600
    for track in names:  # one line: a frame ends before the next begins; 10 bits per byte at the baud rate
        frames = sorted(tr.on(track), key=lambda x: x.ts)
        assert all(a.ts + a.dur <= b.ts for a, b in zip(frames, frames[1:], strict=False))
        assert all(x.dur >= byte_ns - 1 for x in frames)
    plain = run_virtual(RunConfig(strides=1, seed=1, duration_s=1.2))
    assert (tmp_path / "telemetry.bin").read_bytes() == plain.telemetry  # the taps change nothing


def test_frames_to_a_can_motor_are_named_by_their_packet(tmp_path):
    fw = load_firmware_config().with_changes(motor_link="can-servo")
    r, s, tr = _traced(tmp_path, firmware=fw)
    frames = tr.on("wire motor can (to the motor)")
    assert collections.Counter(x.name for x in frames)["SET_CURRENT"] > 500
    frames.sort(key=lambda x: x.ts)
    assert all(a.ts + a.dur <= b.ts for a, b in zip(frames, frames[1:], strict=False))

"""Telemetry stream decoder: chunking, garbage, bit flips, sequence gaps, bounded memory, accounting."""

import dataclasses
import math
import random

from hypothesis import given
from hypothesis import strategies as st

from protocol.telemetry import (
    MAX_ENCODED_LEN,
    RECORD_FRAME_LEN,
    TelemetryDecoder,
    TelemetryRecord,
    encode_record,
    frame_payload,
)

f32 = st.floats(width=32, allow_nan=False)
records = st.builds(
    TelemetryRecord,
    seq=st.integers(0, 2**32 - 1),
    time_cycles=st.integers(0, 2**64 - 1),
    reference_rad=f32, current_cmd_a=f32, torque_est_nm=f32,
    supervisor_state=st.integers(0, 2), fault_reason=st.integers(0, 11),
    deadline_misses=st.integers(0, 2**32 - 1),
)
# garbage that holds no 0x00 cannot end a frame: it can only spoil the frame it is glued to
nonzero_garbage = st.binary(min_size=1, max_size=40).map(lambda b: b.replace(b"\x00", b"\x01"))


def feed_all(chunks):
    dec = TelemetryDecoder()
    out = []
    for c in chunks:
        out += dec.feed(c)
    return out, dec


def split(stream: bytes, cuts: list[int]) -> list[bytes]:
    cuts = sorted(cuts)
    return [stream[a:b] for a, b in zip([0, *cuts], [*cuts, len(stream)], strict=True)]


def test_sequence_of_records_and_stats():
    recs = [TelemetryRecord(seq=i, time_cycles=1000 * i, reference_rad=0.5) for i in range(10)]
    out, dec = feed_all([b"".join(encode_record(r) for r in recs)])
    assert out == recs
    s = dec.stats
    assert (s.records, s.dropped_bytes, s.crc_errors, s.bad_frames, s.lost_records) == (10, 0, 0, 0, 0)
    assert s.bytes_in == 10 * RECORD_FRAME_LEN


def test_lost_records_from_sequence_gaps_including_wrap():
    seqs = [2**32 - 3, 2**32 - 1, 0, 4, 5]  # missing 2**32-2, 1, 2, 3
    out, dec = feed_all([b"".join(encode_record(TelemetryRecord(s, 0)) for s in seqs)])
    assert [r.seq for r in out] == seqs
    assert dec.stats.lost_records == 4 and dec.stats.sequence_resets == 0


def test_sequence_going_back_is_a_reset_not_a_loss():
    seqs = [100, 101, 5, 6, 6]
    _, dec = feed_all([b"".join(encode_record(TelemetryRecord(s, 0)) for s in seqs)])
    assert dec.stats.lost_records == 0 and dec.stats.sequence_resets == 2


@given(st.lists(records, max_size=8), st.data())
def test_dropped_records_are_counted_as_lost(recs, data):
    recs = [dataclasses.replace(r, seq=i) for i, r in enumerate(recs)]
    keep = [r for r in recs if data.draw(st.booleans())]
    out, dec = feed_all([b"".join(encode_record(r) for r in keep)])
    assert out == keep
    expected_lost = (keep[-1].seq - keep[0].seq + 1 - len(keep)) if keep else 0
    assert dec.stats.lost_records == expected_lost


@given(st.lists(records, max_size=8), st.lists(st.integers(0, 8 * RECORD_FRAME_LEN), max_size=12))
def test_any_chunking_yields_the_same_records_and_stats(recs, cuts):
    stream = b"\x07\x08\x00" + b"".join(encode_record(r) for r in recs)  # starts mid-frame
    whole, d1 = feed_all([stream])
    parts, d2 = feed_all(split(stream, [c for c in cuts if c <= len(stream)]))
    assert parts == whole == recs
    assert d1.stats == d2.stats
    assert d2.stats.bad_frames == 1  # the truncated first frame


@given(st.lists(st.tuples(st.just(b"") | nonzero_garbage, records), max_size=8), st.binary(max_size=30))
def test_frames_not_overlapped_by_garbage_are_all_recovered(items, tail):
    """Garbage (no 0x00) glued in front of a frame destroys exactly that frame; all others decode.

    A frame is 'overlapped' when garbage sits between its preceding delimiter and its first byte.
    """
    stream = bytearray()
    expected, lost_bytes = [], 0
    for garbage, rec in items:
        stream += garbage + encode_record(rec)
        if garbage:
            lost_bytes += len(garbage) + RECORD_FRAME_LEN
        else:
            expected.append(rec)
    stream += tail
    out, dec = feed_all([bytes(stream)])
    assert out == expected
    hit = sum(1 for g, _ in items if g)
    s = dec.stats
    assert s.crc_errors + s.bad_frames + s.unknown_versions >= hit
    assert s.dropped_bytes + dec.pending_bytes == lost_bytes + len(tail)


@given(st.binary(max_size=600), st.lists(st.integers(0, 600), max_size=10))
def test_arbitrary_bytes_never_raise_and_every_byte_is_accounted(stream, cuts):
    out, dec = feed_all(split(stream, [c for c in cuts if c <= len(stream)]))
    good = sum(len(encode_record(r)) for r in out)
    assert good + dec.stats.dropped_bytes + dec.pending_bytes == dec.stats.bytes_in == len(stream)
    assert dec.pending_bytes <= MAX_ENCODED_LEN


@given(st.lists(records, min_size=1, max_size=4), st.data())
def test_single_bit_flip_never_yields_a_wrong_record(recs, data):
    """Flip any one bit of the stream (delimiters included): only the original records can come out,
    and the record(s) whose frame holds the flip are lost."""
    frames = [encode_record(r) for r in recs]
    stream = bytearray(b"".join(frames))
    bit = data.draw(st.integers(0, len(stream) * 8 - 1))
    stream[bit // 8] ^= 1 << (bit % 8)
    out, dec = feed_all([bytes(stream)])
    hit = (bit // 8) // RECORD_FRAME_LEN
    merged = (bit // 8) % RECORD_FRAME_LEN == RECORD_FRAME_LEN - 1  # delimiter flipped: next frame joins
    expected = [r for i, r in enumerate(recs) if i != hit and not (merged and i == hit + 1)]
    assert out == expected
    assert dec.stats.records == len(expected)


def test_every_single_bit_flip_of_one_record_is_rejected():
    rec = TelemetryRecord(seq=1000, time_cycles=168_000_000, reference_rad=0.25, velocity_rad_s=-1.5,
                          current_cmd_a=2.5, supervisor_state=1, deadline_misses=3)
    frame = encode_record(rec)
    for bit in range((len(frame) - 1) * 8):
        bad = bytearray(frame)
        bad[bit // 8] ^= 1 << (bit % 8)
        out, _ = feed_all([bytes(bad)])
        assert out == [], bit


def test_memory_stays_bounded_on_long_garbage_without_delimiters():
    rng = random.Random(7)
    dec = TelemetryDecoder()
    for _ in range(200):
        dec.feed(bytes(rng.randrange(1, 256) for _ in range(1000)))
        assert dec.pending_bytes <= MAX_ENCODED_LEN
    rec = TelemetryRecord(seq=1, time_cycles=1)
    out = dec.feed(b"\x00" + encode_record(rec))  # the overlong frame ends, the next decodes
    assert out == [rec]
    assert dec.stats.bad_frames == 1
    assert dec.stats.dropped_bytes == 200_001


def test_overlong_frame_counts_once_whatever_the_chunking():
    stream = b"\x01" * 1000 + b"\x00" + encode_record(TelemetryRecord(2, 3))
    for size in (1, 7, 300, len(stream)):
        out, dec = feed_all([stream[i : i + size] for i in range(0, len(stream), size)])
        assert len(out) == 1 and dec.stats.bad_frames == 1 and dec.stats.dropped_bytes == 1001


def test_unknown_version_is_counted_and_skipped():
    import struct

    from protocol.telemetry import crc16

    body = b"\x02\x01\x05"
    future = frame_payload(body + struct.pack("<H", crc16(body)))
    rec = TelemetryRecord(1, 1)
    out, dec = feed_all([future + encode_record(rec)])
    assert out == [rec] and dec.stats.unknown_versions == 1 and dec.stats.dropped_bytes == len(future)


def test_idle_delimiters_are_dropped_quietly():
    rec = TelemetryRecord(1, 1, torque_est_nm=math.inf)
    out, dec = feed_all([b"\x00\x00" + encode_record(rec) + b"\x00"])
    assert out == [rec]
    assert dec.stats.dropped_bytes == 3 and dec.stats.bad_frames == 0


def test_reset_drops_the_partial_frame():
    dec = TelemetryDecoder()
    frame = encode_record(TelemetryRecord(9, 9))
    dec.feed(frame + frame[:20])
    dec.reset()
    assert dec.pending_bytes == 0 and dec.stats.dropped_bytes == 20
    assert dec.feed(b"\x00" + frame) == [TelemetryRecord(9, 9)]
    assert dec.stats.sequence_resets == 0


def test_feed_values_counts_and_decodes_as_feed_does():
    """The CSV path (value tuples) and the record path see the same records and the same losses."""
    import random
    from dataclasses import astuple

    from protocol.telemetry import RECORD_FIELDS, TelemetryDecoder, TelemetryRecord, encode_record

    rng = random.Random(11)
    frames = [encode_record(TelemetryRecord(seq=k, time_cycles=1000 * k, reference_rad=rng.uniform(-1, 1),
                                            current_cmd_a=rng.uniform(-5, 5))) for k in range(400)]
    data = bytearray(b"".join(frames[k] for k in range(400) if k % 37))  # some records lost
    for _ in range(60):  # and some bytes corrupted
        data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    a, b = TelemetryDecoder(), TelemetryDecoder()
    records = [r for k in range(0, len(data), 333) for r in a.feed(data[k:k + 333])]
    values = [v for k in range(0, len(data), 333) for v in b.feed_values(data[k:k + 333])]
    assert a.stats == b.stats and a.stats.crc_errors + a.stats.bad_frames > 0 and a.stats.lost_records > 0
    assert [tuple(int(x) if k >= len(RECORD_FIELDS) - 3 else x for k, x in enumerate(astuple(r)))
            for r in records] == values

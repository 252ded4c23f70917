"""Throughput of the RVC and telemetry codecs (run with --benchmark-only)."""

from protocol.rvc import RvcDecoder, RvcFrame
from protocol.telemetry import TelemetryDecoder, TelemetryRecord, encode_record

CONSTRUCTED = bytes.fromhex("AA AA 2A D2 04 C9 FD E2 45 0C 00 DE FF EA 03 00 00 00 C3")
RECORD = TelemetryRecord(seq=1000, time_cycles=168_000_000, reference_rad=0.25, velocity_rad_s=-1.5,
                         current_cmd_a=2.5, supervisor_state=1, deadline_misses=3)


def test_bench_encode_record(benchmark):
    assert len(benchmark(encode_record, RECORD)) == 56


def test_bench_decode_1000_records(benchmark):
    stream = b"".join(encode_record(TelemetryRecord(i, i)) for i in range(1000))
    assert len(benchmark(lambda: TelemetryDecoder().feed(stream))) == 1000


def test_bench_rvc_encode(benchmark):
    frame = RvcFrame.from_bytes(CONSTRUCTED)
    assert benchmark(frame.encode) == CONSTRUCTED


def test_bench_rvc_decode_1000_frames(benchmark):
    stream = CONSTRUCTED * 1000
    assert len(benchmark(lambda: RvcDecoder().feed(stream))) == 1000

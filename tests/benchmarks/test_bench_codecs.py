"""VESC codec throughput: streaming decode of a ~1 MB capture against a bare baseline, SET_CURRENT encode.

Run with ``.venv/bin/python -m pytest tests/benchmarks/test_bench_codecs.py --benchmark-only``. Rates are in
messages per second (``extra_info["msgs_per_s"]``, from the median round).

The headline compares like with like: ``test_bench_vesc_stream_decode_reading_every_field`` decodes the
streams and reads every field of every message (multi-field messages such as GET_VALUES convert a field to
SI on first access, so reading them all is the full work), against the SI baseline, which gets the frames
already split, checks each CRC, unpacks the integers with ``struct`` and converts every one of them to SI
(no scanning, no objects): ``ratio_to_si_baseline``, goal >= 0.5. The lazy figure stays as a second line:
``test_bench_vesc_stream_decode`` only counts the messages (no field read), against the bare baseline that
only unpacks the integers (``ratio_to_baseline``).
"""

from __future__ import annotations

import binascii
import dataclasses
import math
import random
import statistics
import struct
import time
import warnings
from collections.abc import Callable
from typing import Any

import pytest

from protocol.vesc import (
    Alive,
    Decoder,
    GetValues,
    Message,
    RotorPosition,
    SetCurrent,
    SetPos,
    Values,
)
from protocol.vesc_values import VALUES_FIELDS

SEED = 20240611
CAPTURE_BYTES = 1_000_000
READ_SIZE = 4096
GOAL_RATIO = 0.5
_MEDIANS: dict[str, float] = {}


@dataclasses.dataclass(frozen=True)
class Capture:
    """Both wires of a recorded link, as streams and pre-split into frames."""

    to_motor: bytes
    from_motor: bytes
    to_motor_frames: list[bytes]
    from_motor_frames: list[bytes]

    @property
    def messages(self) -> int:
        """Number of frames (= messages) in the capture."""
        return len(self.to_motor_frames) + len(self.from_motor_frames)


def build_capture(seed: int = SEED, size_bytes: int = CAPTURE_BYTES) -> Capture:
    """A control loop's traffic: SET_CURRENT + GET_VALUES each cycle, some SET_POS/ALIVE, replies, positions."""
    rng = random.Random(seed)
    to_motor: list[bytes] = []
    from_motor: list[bytes] = []
    total = cycle = 0
    while total < size_bytes:
        sent = [SetCurrent(rng.uniform(-15.0, 15.0)).encode(), GetValues().encode()]
        if cycle % 10 == 0:
            sent.append(SetPos(rng.uniform(-math.pi, math.pi)).encode())
        if cycle % 25 == 0:
            sent.append(Alive().encode())
        received = [Values(temp_fet_c=rng.uniform(25.0, 70.0), temp_motor_c=rng.uniform(25.0, 90.0),
                           avg_motor_current_a=rng.uniform(-15.0, 15.0), avg_iq_a=rng.uniform(-15.0, 15.0),
                           duty=rng.uniform(-0.9, 0.9), erpm=rng.randint(-20000, 20000),
                           v_in_v=rng.uniform(22.0, 25.0), tachometer=rng.randint(-10**6, 10**6),
                           tachometer_abs=rng.randint(0, 10**7), pid_pos_rad=rng.uniform(-math.pi, math.pi),
                           controller_id=0x7E, avg_vq_v=rng.uniform(-20.0, 20.0)).encode()]
        if cycle % 4 == 0:
            received.append(RotorPosition(rng.uniform(-math.pi, math.pi)).encode())
        to_motor += sent
        from_motor += received
        total += sum(map(len, sent)) + sum(map(len, received))
        cycle += 1
    return Capture(b"".join(to_motor), b"".join(from_motor), to_motor, from_motor)


@pytest.fixture(scope="module")
def capture() -> Capture:
    """The deterministic ~1 MB capture shared by the benchmarks of this module."""
    return build_capture()


def decode_capture(capture: Capture, consume: Callable[[list[Message]], Any]) -> None:
    """Decode both wires as a streaming host would: fresh decoders, reads of READ_SIZE bytes, each read's
    messages handed to ``consume`` and then dropped."""
    for direction, stream in (("to-motor", capture.to_motor), ("from-motor", capture.from_motor)):
        decoder = Decoder(direction)  # type: ignore[arg-type]
        feed = decoder.feed
        for i in range(0, len(stream), READ_SIZE):
            consume(feed(stream[i : i + READ_SIZE]))


_BASE_STRUCTS = {
    "to-motor": {cls.COMMAND_ID: cls._ARGS for cls in (SetCurrent, GetValues, SetPos, Alive)},
    "from-motor": {4: Values._ARGS, 22: struct.Struct(">i")},
}


def bare_baseline(capture: Capture) -> int:
    """For each pre-split frame: check the CRC and unpack the fields with struct (nothing else); count them."""
    crc = binascii.crc_hqx
    count = 0
    for direction, frames in (("to-motor", capture.to_motor_frames), ("from-motor", capture.from_motor_frames)):
        unpackers = {cid: s.unpack_from for cid, s in _BASE_STRUCTS[direction].items()}
        for frame in frames:
            payload = frame[2:-3]
            if crc(payload, 0) == (frame[-3] << 8) | frame[-2]:
                unpackers[payload[0]](payload, 1)
                count += 1
    return count


def _divisors(wire: Any) -> tuple[float, ...]:
    """Raw -> SI divisor of each wire field (1 for plain integers: they stay ints, as in the messages)."""
    return tuple(f.scale * (180.0 / math.pi if f.angle else 1.0) for f in wire)


_SI_DIVISORS = {
    "to-motor": {cls.COMMAND_ID: _divisors(cls._WIRE) for cls in (SetCurrent, GetValues, SetPos, Alive)},
    "from-motor": {4: _divisors(VALUES_FIELDS), 22: (1e4 * 180.0 / math.pi,)},
}


def si_baseline(capture: Capture) -> int:
    """The bare baseline plus every field converted to SI (raw / scale, degrees to rad): the same fields."""
    crc = binascii.crc_hqx
    count = 0
    for direction, frames in (("to-motor", capture.to_motor_frames), ("from-motor", capture.from_motor_frames)):
        unpackers = {cid: s.unpack_from for cid, s in _BASE_STRUCTS[direction].items()}
        divisors = _SI_DIVISORS[direction]
        for frame in frames:
            payload = frame[2:-3]
            if crc(payload, 0) == (frame[-3] << 8) | frame[-2]:
                cid = payload[0]
                _ = [raw if d == 1 else raw / d for raw, d in zip(unpackers[cid](payload, 1), divisors[cid],
                                                                  strict=True)]
                count += 1
    return count


class Counter:
    """Streaming consumer that counts messages."""

    def __init__(self) -> None:
        """Start at zero."""
        self.count = 0

    def __call__(self, messages: list[Message]) -> None:
        """Count a batch."""
        self.count += len(messages)


class FieldReader(Counter):
    """Streaming consumer that counts messages and reads every field of each (forcing the SI conversion)."""

    def __init__(self) -> None:
        """Start at zero, with a per-class cache of field names."""
        super().__init__()
        self.fields = 0
        self._names: dict[type, tuple[str, ...]] = {}

    def __call__(self, messages: list[Message]) -> None:
        """Count a batch and read all its fields."""
        self.count += len(messages)
        for message in messages:
            names = self._names.get(type(message))
            if names is None:
                names = self._names[type(message)] = tuple(f.name for f in dataclasses.fields(message))
            for name in names:
                getattr(message, name)
            self.fields += len(names)


def median_rate(fn: Callable[[], Any], count: int, rounds: int = 7) -> float:
    """Messages per second of ``fn`` (median of ``rounds`` timed calls) for use outside the benchmark fixture."""
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return count / statistics.median(times)


def _record_rate(benchmark: Any, key: str, count: int) -> float:
    """Store msgs/s of the benchmark's median round in extra_info and in the module table; return it."""
    median_s = benchmark.stats.stats.median
    _MEDIANS[key] = median_s
    rate = count / median_s
    benchmark.extra_info["messages"] = count
    benchmark.extra_info["msgs_per_s"] = round(rate)
    return rate


def _baseline_rate(capture: Capture) -> float:
    """Baseline rate of this session: from its benchmark when it ran first, else measured here."""
    if "baseline" in _MEDIANS:
        return capture.messages / _MEDIANS["baseline"]
    return median_rate(lambda: bare_baseline(capture), capture.messages)


def test_bench_vesc_bare_baseline(benchmark: Any, capture: Capture) -> None:
    assert benchmark(bare_baseline, capture) == capture.messages
    _record_rate(benchmark, "baseline", capture.messages)


def test_bench_vesc_si_baseline(benchmark: Any, capture: Capture) -> None:
    assert benchmark(si_baseline, capture) == capture.messages
    _record_rate(benchmark, "si_baseline", capture.messages)


def test_bench_vesc_stream_decode(benchmark: Any, capture: Capture) -> None:
    def run() -> Counter:
        counter = Counter()
        decode_capture(capture, counter)
        return counter

    assert benchmark(run).count == capture.messages
    rate = _record_rate(benchmark, "decode", capture.messages)
    baseline = _baseline_rate(capture)
    ratio = rate / baseline
    benchmark.extra_info["baseline_msgs_per_s"] = round(baseline)
    benchmark.extra_info["ratio_to_baseline"] = round(ratio, 3)


def test_bench_vesc_stream_decode_reading_every_field(benchmark: Any, capture: Capture) -> None:
    def run() -> FieldReader:
        reader = FieldReader()
        decode_capture(capture, reader)
        return reader

    reader = benchmark(run)
    per_id = {"to-motor": {6: 1, 4: 0, 9: 1, 30: 0}, "from-motor": {4: 23, 22: 2}}
    expected_fields = sum(per_id["to-motor"][f[2]] for f in capture.to_motor_frames)
    expected_fields += sum(per_id["from-motor"][f[2]] for f in capture.from_motor_frames)
    assert reader.count == capture.messages and reader.fields == expected_fields
    rate = _record_rate(benchmark, "decode_read", capture.messages)
    benchmark.extra_info["ratio_to_baseline"] = round(rate / _baseline_rate(capture), 3)
    si = (capture.messages / _MEDIANS["si_baseline"] if "si_baseline" in _MEDIANS
          else median_rate(lambda: si_baseline(capture), capture.messages))
    ratio = rate / si
    benchmark.extra_info["si_baseline_msgs_per_s"] = round(si)
    benchmark.extra_info["ratio_to_si_baseline"] = round(ratio, 3)
    benchmark.extra_info["goal_met"] = ratio >= GOAL_RATIO
    if ratio < GOAL_RATIO:  # a timing on a shared machine: reported, not a correctness failure
        warnings.warn(f"full decode is {ratio:.2f} of the SI baseline rate (goal >= {GOAL_RATIO})", stacklevel=1)


def test_bench_vesc_encode_set_current(benchmark: Any) -> None:
    rng = random.Random(SEED)
    currents = [rng.uniform(-22.7, 22.7) for _ in range(1000)]

    def encode_all() -> list[bytes]:
        return [SetCurrent(c).encode() for c in currents]

    frames = benchmark(encode_all)
    assert len(frames) == 1000 and all(len(f) == 10 for f in frames)
    _record_rate(benchmark, "encode", len(currents))

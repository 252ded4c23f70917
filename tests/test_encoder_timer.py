"""Virtual encoder timer: 4000 counts/rev, floor rounding, wraps both ways, C-style wrap-safe deltas, DIR."""

from __future__ import annotations

import math

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from hal.virtual.timer import VirtualEncoderTimer

CPR = 4000
RAD_PER_COUNT = math.tau / CPR


class Shaft:
    """A clock and an angle that tests set directly (angle per cycle recorded as a table)."""

    def __init__(self) -> None:
        self.t = 0
        self.angle = 0.0

    def now(self) -> int:
        return self.t

    def angle_at(self, t_cycles: int) -> float:
        assert t_cycles == self.t
        return self.angle


def c_int(value: int, bits: int) -> int:
    """(intN_t) cast of an unsigned value, as C does it on a two's-complement MCU."""
    half = 1 << (bits - 1)
    return (value + half) % (1 << bits) - half


def make(bits: int = 16, **kw: int) -> tuple[Shaft, VirtualEncoderTimer]:
    shaft = Shaft()
    return shaft, VirtualEncoderTimer(shaft.now, shaft.angle_at, bits=bits, **kw)


def at_count(counts: int) -> float:
    """An angle safely inside count `counts` (half a count above its lower edge)."""
    return (counts + 0.5) * RAD_PER_COUNT


def test_4000_counts_per_revolution_and_floor_rounding() -> None:
    shaft, enc = make()
    assert enc.cnt() == 0
    shaft.angle = math.tau + 0.5 * RAD_PER_COUNT
    assert enc.cnt() == 4000
    shaft.angle = 0.999 * RAD_PER_COUNT
    assert enc.cnt() == 0
    shaft.angle = -1e-9
    assert enc.cnt() == 65535
    shaft.angle = -RAD_PER_COUNT * 1.5
    assert enc.cnt() == 65534


@given(theta=st.floats(-500.0, 500.0), revs=st.integers(-20, 20))
def test_one_revolution_is_exactly_4000_counts(theta: float, revs: int) -> None:
    frac = (theta / RAD_PER_COUNT) % 1.0
    assume(1e-6 < frac < 1 - 1e-6)
    shaft, enc = make(bits=32)
    shaft.angle = theta
    base = enc.counts_at(0)
    shaft.angle = theta + revs * math.tau
    assert enc.counts_at(0) - base == 4000 * revs


@pytest.mark.parametrize("bits", [16, 32])
@pytest.mark.parametrize("direction", [1, -1])
def test_high_speed_wraps_are_recovered_by_wrap_safe_deltas(bits: int, direction: int) -> None:
    shaft, enc = make(bits=bits)
    step = direction * 30_001  # counts per sample, under 32768
    true_total = 0
    recovered = 0
    prev = enc.cnt()
    for _ in range(400 if bits == 16 else 50):
        true_total += step
        shaft.angle = at_count(true_total)
        cnt = enc.cnt()
        assert 0 <= cnt <= (1 << bits) - 1
        recovered += c_int(cnt - prev, bits)
        prev = cnt
        assert enc.counting_down() is (direction < 0)
    assert recovered == true_total
    expected_wraps = abs(math.floor(true_total / (1 << bits)))
    assert enc.update_events == expected_wraps
    if bits == 16:
        assert expected_wraps > 100


def test_32_bit_counter_wraps_at_2_to_the_32() -> None:
    shaft, enc = make(bits=32)
    shaft.angle = at_count(-1)
    assert enc.cnt() == 2**32 - 1
    shaft.angle = at_count(2**32 + 5)
    assert enc.cnt() == 5
    assert enc.arr == 2**32 - 1 and enc.bits == 32


@given(deltas=st.lists(st.integers(-32767, 32767), min_size=1, max_size=60))
def test_int16_cast_recovers_any_sequence_of_moves_under_half_range(deltas: list[int]) -> None:
    shaft, enc = make()
    prev = enc.cnt()
    position = 0
    recovered = 0
    for d in deltas:
        position += d
        shaft.angle = at_count(position)
        cnt = enc.cnt()
        recovered += c_int(cnt - prev, 16)
        prev = cnt
        assert recovered == position


@given(deltas=st.lists(st.integers(-1999, 1999), min_size=1, max_size=60))
def test_arr_3999_wraps_once_per_revolution_and_modular_delta_works(deltas: list[int]) -> None:
    n = 4000
    shaft, enc = make(arr=n - 1)
    prev = enc.cnt()
    position = 0
    recovered = 0
    for d in deltas:
        position += d
        shaft.angle = at_count(position)
        cnt = enc.cnt()
        assert cnt == position % n
        recovered += (cnt - prev + n // 2) % n - n // 2
        prev = cnt
    assert recovered == position


def test_dir_bit_follows_the_last_change_and_holds_when_still() -> None:
    shaft, enc = make()
    assert enc.counting_down() is False
    shaft.angle = at_count(10)
    assert enc.counting_down() is False
    shaft.angle = at_count(3)
    assert enc.counting_down() is True
    assert enc.counting_down() is True  # no movement: DIR keeps its last value
    shaft.angle = at_count(4)
    enc.cnt()
    assert enc.counting_down() is False


def test_inverted_polarity_counts_the_other_way() -> None:
    shaft, enc = make(polarity=-1)
    shaft.angle = at_count(10)
    assert enc.cnt() == 65536 - 11
    assert enc.counting_down() is True


def test_set_cnt_supports_read_and_clear() -> None:
    shaft, enc = make()
    shaft.angle = at_count(1234)
    assert enc.cnt() == 1234
    enc.set_cnt(0)
    assert enc.cnt() == 0
    shaft.angle = at_count(1200)
    assert c_int(enc.cnt(), 16) == -34
    with pytest.raises(ValueError, match="65536"):
        enc.set_cnt(65536)


def test_update_interrupt_counts_wraps_in_windows() -> None:
    rate = 0.05  # counts per cycle, upwards
    enc = VirtualEncoderTimer(lambda: 0, lambda t: (t * rate + 0.25) * RAD_PER_COUNT)
    source = enc.update_interrupt(cost_cycles=60)
    period = int(65536 / rate)
    assert source.count_in(0, period - 10) == 0
    assert source.count_in(period - 10, 3 * period + 5) == 3
    assert source.count_in(3 * period + 5, 3 * period + 6) == 0


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"bits": 24}, "bits 24"),
        ({"arr": 0}, "arr 0"),
        ({"arr": 70000}, "arr 70000"),
        ({"counts_per_rev": 0}, "counts_per_rev 0"),
        ({"polarity": 2}, "polarity 2"),
    ],
)
def test_bad_configuration_is_named(kwargs: dict[str, int], needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        VirtualEncoderTimer(lambda: 0, lambda t: 0.0, **kwargs)


def test_non_finite_angle_is_refused() -> None:
    enc = VirtualEncoderTimer(lambda: 7, lambda t: math.nan)
    with pytest.raises(ValueError, match="not finite"):
        enc.cnt()

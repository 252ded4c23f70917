"""The UART RX interrupt source: one firing per byte arriving on the RX wire, counted in windows."""

from __future__ import annotations

from collections.abc import Sequence

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hal.virtual.uart import VirtualUart
from rtos.interrupts import is_interrupt_source

F_CPU = 72_000_000


class Clock:
    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


class PeriodicPeer:
    """Sends a frame every period_cycles, produced lazily when advanced (an IMU in UART-RVC mode)."""

    def __init__(self, uart: VirtualUart, frame: bytes, period_cycles: int) -> None:
        self.uart = uart
        self.frame = frame
        self.period = period_cycles
        self.next_start = period_cycles
        self.ends: list[int] = []
        self.advanced: list[int] = []

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        pass

    def advance_to(self, t_cycles: int) -> None:
        self.advanced.append(t_cycles)
        while self.next_start <= t_cycles:
            self.ends += self.uart.transmit_to_mcu(self.frame, self.next_start)
            self.next_start += self.period


@given(
    bursts=st.lists(
        st.tuples(st.integers(0, 300_000), st.integers(1, 30)), min_size=1, max_size=10
    ),
    cuts=st.lists(st.integers(0, 600_000), min_size=1, max_size=15),
)
def test_counts_in_consecutive_windows_equal_arrivals(bursts: list[tuple[int, int]], cuts: list[int]) -> None:
    clock = Clock()
    uart = VirtualUart(clock, F_CPU, 115_200, rx_buffer_size=8)
    source = uart.rx_interrupt(cost_cycles=120)
    assert is_interrupt_source(source)
    ends: list[int] = []
    for start, n in sorted(bursts):
        ends += uart.transmit_to_mcu(bytes(n), start)
    edges = [0, *sorted(cuts)]
    for t0, t1 in zip(edges, edges[1:], strict=False):
        expected = sum(1 for e in ends if t0 <= e < t1)
        assert source.count_in(t0, t1) == expected
    # overlapping windows with the same start (a response-time iteration) agree too
    t_last = edges[-1]
    assert source.count_in(t_last, t_last + 1_000) == sum(1 for e in ends if t_last <= e < t_last + 1_000)
    assert source.count_in(t_last, t_last + 10**9) == sum(1 for e in ends if e >= t_last)


@given(
    windows=st.lists(st.integers(1, 400_000), min_size=1, max_size=12),
    period=st.integers(50_000, 300_000),
)
def test_count_in_advances_a_lazy_peer(windows: list[int], period: int) -> None:
    clock = Clock()
    uart = VirtualUart(clock, F_CPU, 115_200)
    peer = PeriodicPeer(uart, bytes(19), period)
    uart.connect(peer)
    source = uart.rx_interrupt(cost_cycles=100, name="imu_rx")
    t0 = 0
    total = 0
    for width in windows:
        t1 = t0 + width
        n = source.count_in(t0, t1)
        assert peer.advanced[-1] == t1
        assert n == sum(1 for e in peer.ends if t0 <= e < t1)
        total += n
        t0 = t1
    assert total == sum(1 for e in peer.ends if e < t0)


def test_dropped_bytes_do_not_fire_but_framing_errors_do() -> None:
    clock = Clock()
    uart = VirtualUart(clock, F_CPU, 115_200)
    source = uart.rx_interrupt(cost_cycles=120)
    uart.drop_next(2)
    ends = uart.transmit_to_mcu(b"abcd", 0)
    fe = uart.inject_framing_error(ends[-1], count=3)
    assert source.count_in(0, fe[-1] + 1) == 2 + 3


def test_every_source_sees_every_byte_and_windows_must_not_go_back() -> None:
    clock = Clock()
    uart = VirtualUart(clock, F_CPU, 115_200)
    a = uart.rx_interrupt(cost_cycles=1)
    b = uart.rx_interrupt(cost_cycles=2, name="other")
    ends = uart.transmit_to_mcu(b"xyz", 0)
    assert a.count_in(0, ends[-1] + 1) == 3
    assert b.count_in(ends[0], ends[-1]) == 2
    assert (a.name, a.cost_cycles, b.name) == ("uart_rx", 1, "other")
    with pytest.raises(ValueError, match="must not decrease"):
        b.count_in(0, 10)
    with pytest.raises(ValueError, match="invalid"):
        a.count_in(50, 10)
    with pytest.raises(ValueError, match="cost_cycles -1"):
        uart.rx_interrupt(cost_cycles=-1)


def test_long_runs_stay_bounded_in_memory() -> None:
    clock = Clock()
    uart = VirtualUart(clock, F_CPU, 3_000_000, rx_buffer_size=64)
    source = uart.rx_interrupt(cost_cycles=1)
    t0 = 0
    total = 0
    for _ in range(50):
        ends = uart.transmit_to_mcu(bytes(500), t0)
        total += source.count_in(t0, ends[-1] + 1)
        t0 = ends[-1] + 1
        clock.t = t0
        uart.read()
    assert total == 50 * 500
    assert len(source._times) < 5_000

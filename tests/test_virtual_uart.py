"""Virtual UART: byte timing at the stop-bit end, back-to-back queuing, overrun, peers, fault injection."""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hal.errors import HalError
from hal.virtual.uart import VirtualUart

F_CPU = 168_000_000


class Clock:
    """A settable cycle clock."""

    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


class RecordingPeer:
    """Records what the MCU sent and when it was advanced."""

    def __init__(self) -> None:
        self.received: list[tuple[bytes, list[int]]] = []
        self.advanced: list[int] = []

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        self.received.append((data, list(end_times_cycles)))

    def advance_to(self, t_cycles: int) -> None:
        self.advanced.append(t_cycles)


class EchoPeer(RecordingPeer):
    """Replies with the same bytes latency_cycles after each received byte's end, produced lazily."""

    def __init__(self, uart: VirtualUart, latency_cycles: int) -> None:
        super().__init__()
        self.uart = uart
        self.latency = latency_cycles
        self.todo: list[tuple[int, int]] = []

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        super().on_bytes(data, end_times_cycles)
        self.todo += [(end + self.latency, b) for end, b in zip(end_times_cycles, data, strict=True)]

    def advance_to(self, t_cycles: int) -> None:
        super().advance_to(t_cycles)
        while self.todo and self.todo[0][0] <= t_cycles:
            start, byte = self.todo.pop(0)
            self.uart.transmit_to_mcu(bytes([byte]), start)


def byte_end(start: int, k: int, baud: int, f_cpu: int = F_CPU) -> int:
    """Reference: end of the k-th byte (1-based) of a burst starting at start, by exact fractions."""
    return start + math.ceil(Fraction(10 * k, baud) * f_cpu)


def make(baud: int = 921_600, **kw: int) -> tuple[Clock, VirtualUart]:
    clock = Clock()
    return clock, VirtualUart(clock, F_CPU, baud, **kw)


def test_78_byte_reply_at_921600_arrives_846_us_after_its_first_start_bit() -> None:
    clock, uart = make(rx_buffer_size=512)
    start = 10_000
    reply = bytes(range(78))
    ends = uart.transmit_to_mcu(reply, start)
    assert ends[-1] - start == math.ceil(Fraction(78 * 10, 921_600) * F_CPU)
    assert (ends[-1] - start) / F_CPU == pytest.approx(78 * 10 / 921_600, abs=1 / F_CPU)
    assert (ends[-1] - start) / F_CPU * 1e6 == pytest.approx(846.35, abs=0.01)
    clock.t = ends[-1] - 1
    assert uart.in_waiting() == 77
    clock.t = ends[-1]
    assert uart.in_waiting() == 78
    assert uart.read() == reply


def test_each_byte_readable_exactly_at_its_stop_bit_end() -> None:
    clock, uart = make(baud=115_200)
    start = 777
    uart.transmit_to_mcu(b"abcdefgh", start)
    got = b""
    for k in range(1, 9):
        clock.t = byte_end(start, k, 115_200) - 1
        got += uart.read()
        assert len(got) == k - 1
        clock.t += 1
        got += uart.read()
        assert got == b"abcdefgh"[:k]


def test_back_to_back_writes_continue_the_burst_without_drift() -> None:
    clock, uart = make()
    peer = RecordingPeer()
    uart.connect(peer)
    assert uart.write(b"123456") == 6
    clock.t = 500  # line still busy with the first burst
    assert uart.write(b"7890") == 4
    ends = peer.received[0][1] + peer.received[1][1]
    assert ends == [byte_end(0, k, 921_600) for k in range(1, 11)]
    assert uart.tx_line_busy_until == ends[-1]
    clock.t = ends[-1] + 50  # idle line: the next write starts at its own time
    uart.write(b"x")
    assert peer.received[2][1] == [byte_end(clock.t, 1, 921_600)]


def test_rx_bursts_queue_behind_a_busy_line() -> None:
    clock, uart = make(baud=460_800)
    first = uart.transmit_to_mcu(b"aaaa", 0)
    second = uart.transmit_to_mcu(b"bb", 10)  # asked to start while the line is busy
    assert second == [byte_end(0, k, 460_800) for k in (5, 6)]
    assert first[-1] < second[0]
    clock.t = second[-1]
    assert uart.read() == b"aaaabb"


def test_write_refuses_and_counts_what_the_tx_queue_cannot_hold() -> None:
    clock, uart = make(baud=115_200, tx_queue_size=16)
    assert uart.tx_free() == 16
    assert uart.write(bytes(20)) == 16
    assert uart.errors.tx_dropped == 4
    assert uart.tx_free() == 0
    assert uart.write(b"z") == 0
    assert uart.errors.tx_dropped == 5
    clock.t = byte_end(0, 3, 115_200)
    assert uart.tx_free() == 3
    clock.t -= 1
    assert uart.tx_free() == 2
    assert uart.tx_bytes == 16


def test_overrun_keeps_the_oldest_bytes_and_counts_events_and_lost_bytes() -> None:
    clock, uart = make(rx_buffer_size=8)
    ends = uart.transmit_to_mcu(bytes(range(20)), 0)
    clock.t = ends[-1]
    assert uart.read() == bytes(range(8))
    errors = uart.errors
    assert (errors.overrun, errors.rx_lost) == (1, 12)
    # partial read makes room for 4; the next 10 bytes: 4 kept, 6 lost, a second event
    ends = uart.transmit_to_mcu(bytes(range(100, 110)), clock.t)
    clock.t = ends[3]
    assert uart.in_waiting() == 4
    clock.t = ends[-1]
    assert uart.read(8) == bytes(range(100, 108))
    assert (uart.errors.overrun, uart.errors.rx_lost) == (2, 14)


def test_overrun_run_spanning_reads_that_free_no_room_is_one_event() -> None:
    clock, uart = make(rx_buffer_size=4)
    ends = uart.transmit_to_mcu(bytes(10), 0)
    clock.t = ends[6]
    assert uart.in_waiting() == 4
    clock.t = ends[-1]
    assert uart.in_waiting() == 4
    assert (uart.errors.overrun, uart.errors.rx_lost) == (1, 6)


def test_peer_is_advanced_before_reads_and_writes_and_replies_arrive_on_time() -> None:
    clock, uart = make(baud=115_200)
    peer = EchoPeer(uart, latency_cycles=5_000)
    uart.connect(peer)
    clock.t = 100
    uart.write(b"hi")
    assert peer.advanced == [100]
    request_ends = peer.received[0][1]
    assert request_ends == [byte_end(100, 1, 115_200), byte_end(100, 2, 115_200)]
    # 'h' starts 5000 cycles after its request byte ends; 'i' queues behind it on the busy line
    reply_start = request_ends[0] + 5_000
    clock.t = byte_end(reply_start, 1, 115_200) - 1
    assert uart.read() == b""
    clock.t += 1
    assert uart.read() == b"h"
    clock.t = byte_end(reply_start, 2, 115_200) - 1
    assert uart.read() == b""
    clock.t += 1
    assert uart.read() == b"i"
    assert peer.advanced[-1] == clock.t


def test_transmitting_into_the_already_read_past_is_refused() -> None:
    clock, uart = make()
    clock.t = 1_000
    uart.read()
    with pytest.raises(ValueError, match="999"):
        uart.transmit_to_mcu(b"x", 999)
    uart.transmit_to_mcu(b"x", 1_000)


def test_drop_next_rx_loses_bytes_but_keeps_their_line_time() -> None:
    clock, uart = make()
    uart.drop_next(3)
    ends = uart.transmit_to_mcu(b"abcdef", 0)
    assert ends == [byte_end(0, k, 921_600) for k in range(1, 7)]
    clock.t = ends[2]
    assert uart.in_waiting() == 0
    clock.t = ends[-1]
    assert uart.read() == b"def"
    assert uart.dropped_rx == 3
    assert uart.errors.total() == 0


def test_drop_next_tx_hides_bytes_from_the_peer() -> None:
    _, uart = make()
    peer = RecordingPeer()
    uart.connect(peer)
    uart.drop_next(2, direction="tx")
    assert uart.write(b"abcd") == 4
    assert peer.received[0][0] == b"cd"
    assert peer.received[0][1] == [byte_end(0, k, 921_600) for k in (3, 4)]
    assert uart.dropped_tx == 2
    with pytest.raises(ValueError, match="sideways"):
        uart.drop_next(1, direction="sideways")  # type: ignore[arg-type]


def test_framing_errors_count_at_their_end_and_delay_following_bytes() -> None:
    clock, uart = make()
    fe_ends = uart.inject_framing_error(0, count=2)
    ends = uart.transmit_to_mcu(b"ok", 0)
    assert ends[0] == byte_end(0, 3, 921_600)
    clock.t = fe_ends[0] - 1
    assert uart.errors.framing == 0
    clock.t = fe_ends[1]
    assert uart.errors.framing == 2
    assert uart.read() == b""
    clock.t = ends[-1]
    assert uart.read() == b"ok"


def test_noise_and_garbage_are_received_as_data() -> None:
    clock, uart = make()
    uart.inject_garbage(b"\xff\x00", 0)
    ends = uart.inject_noise(b"\x55", 0)
    clock.t = ends[-1]
    assert uart.read() == b"\xff\x00\x55"
    assert uart.errors.noise == 1


def test_read_limits_and_bad_arguments() -> None:
    clock, uart = make()
    ends = uart.transmit_to_mcu(b"abcdef", 0)
    clock.t = ends[-1]
    assert uart.read(0) == b""
    assert uart.read(2) == b"ab"
    assert uart.in_waiting() == 4
    with pytest.raises(ValueError, match="-2"):
        uart.read(-2)
    with pytest.raises(TypeError, match="str"):
        uart.write("text")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        uart.connect(object())  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [({"baud": 0}, "baud 0"), ({"rx_buffer_size": 0}, "rx_buffer_size 0"), ({"tx_queue_size": -1}, "-1")],
)
def test_constructor_names_bad_values(kwargs: dict[str, int], needle: str) -> None:
    args = {"baud": 115_200, **kwargs}
    with pytest.raises(ValueError, match=needle):
        VirtualUart(lambda: 0, F_CPU, **args)


def test_closed_uart_raises_hal_error() -> None:
    _, uart = make()
    uart.close()
    uart.close()
    for call in (lambda: uart.write(b"x"), uart.read, uart.in_waiting, uart.tx_free):
        with pytest.raises(HalError, match="closed"):
            call()


@given(
    bursts=st.lists(
        st.tuples(st.integers(0, 200_000), st.binary(min_size=1, max_size=40)), min_size=1, max_size=8
    ),
    read_times=st.lists(st.integers(0, 400_000), min_size=1, max_size=12),
    size=st.integers(1, 64),
)
def test_lazy_reads_match_an_eager_per_byte_reference(
    bursts: list[tuple[int, bytes]], read_times: list[int], size: int
) -> None:
    baud = 230_400
    clock, uart = make(baud=baud, rx_buffer_size=size)
    # reference timing: one line, bursts back to back in push order, exact fractions
    arrivals: list[tuple[Fraction, int]] = []
    busy = Fraction(0)
    byte_time = Fraction(10 * F_CPU, baud)
    for start, data in bursts:
        t = max(Fraction(start), busy)
        for b in data:
            t += byte_time
            arrivals.append((t, b))
        busy = t
        uart.transmit_to_mcu(data, start)
    # reference buffer, byte by byte in arrival order
    buf: list[int] = []
    lost = events = 0
    losing = False
    i = 0
    for t_read in sorted(read_times):
        while i < len(arrivals) and math.ceil(arrivals[i][0]) <= t_read:
            if len(buf) < size:
                buf.append(arrivals[i][1])
                losing = False
            else:
                lost += 1
                events += 0 if losing else 1
                losing = True
            i += 1
        clock.t = t_read
        assert uart.read(5) == bytes(buf[:5])
        del buf[:5]
    assert (uart.errors.rx_lost, uart.errors.overrun) == (lost, events)


def test_a_write_after_the_exact_line_end_starts_a_new_burst() -> None:
    # the first byte ends at 1822.92 cycles (stop bit seen at cycle 1823); a write at cycle 1823
    # finds the line idle and starts its own burst there, rather than continuing the old one
    clock, uart = make()
    peer = RecordingPeer()
    uart.connect(peer)
    uart.write(b"a")
    clock.t = uart.tx_line_busy_until
    assert clock.t == 1823
    uart.write(bytes(11))
    assert peer.received[1][1][-1] == byte_end(1823, 11, 921_600) == 21876
    # while a burst is still running (cycle 1822 < 1822.92), the bytes continue it exactly
    clock2, uart2 = make()
    ends_a = uart2.transmit_to_mcu(b"a", 0)
    ends_b = uart2.transmit_to_mcu(bytes(11), 1822)
    assert ends_a + ends_b == [byte_end(0, k, 921_600) for k in range(1, 13)]

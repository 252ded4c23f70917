"""The virtual CAN bus and bxCAN: frame times, arbitration, mailboxes, FIFO overrun, filters."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hal.can import CanFrame
from hal.errors import HalError
from hal.virtual.can import FIFO_DEPTH, TX_MAILBOXES, FilterBank, VirtualBxCan
from hal.virtual.can_bits import frame_bits, unstuffed_bits, worst_case_bits
from hal.virtual.can_bus import VirtualCanBus
from hal.virtual.devices.world import World
from hal.virtual.plant import Plant

F = 1_000_000  # ticks per second: 1 tick = 1 bit at 1 Mbit/s


class _Clock:
    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


class _Listener:
    def __init__(self) -> None:
        self.got: list[tuple[int, CanFrame]] = []
        self.sent: list[tuple[int, CanFrame]] = []

    def on_frame(self, frame: CanFrame, t: int) -> None:
        self.got.append((t, frame))

    def tx_done(self, frame: CanFrame, t: int) -> None:
        self.sent.append((t, frame))


def _bus() -> tuple[World, VirtualCanBus, _Clock]:
    world = World(Plant(), F)
    return world, VirtualCanBus(world, 1_000_000), _Clock()


def test_frame_lengths_match_the_published_bounds():
    assert (unstuffed_bits(8, False), worst_case_bits(8, False)) == (111, 135)
    assert (unstuffed_bits(8, True), worst_case_bits(8, True)) == (131, 160)


@given(st.booleans(), st.integers(0, (1 << 29) - 1), st.binary(max_size=8))
def test_exact_stuffing_lies_between_none_and_the_worst_case(extended, ident, data):
    ident = ident if extended else ident & 0x7FF
    bits = frame_bits(ident, data, extended)
    assert unstuffed_bits(len(data), extended) <= bits <= worst_case_bits(len(data), extended)


def test_stuffing_counts_runs_of_five():
    # ID 0 and zero data: long runs of dominant bits, far more stuff bits than an alternating pattern
    assert frame_bits(0, bytes(8), False) > frame_bits(0x555, b"\x55" * 8, False)
    assert frame_bits(0x555, b"\x55" * 8, False) - unstuffed_bits(8, False) <= 3  # only the CRC may stuff


def test_a_frame_takes_its_bit_times_and_reaches_the_other_nodes():
    world, bus, clock = _bus()
    port = VirtualBxCan(clock, bus)
    other = _Listener()
    bus.attach(other)
    frame = CanFrame(0x123, b"\x01\x02\x03\x04\x05\x06\x07\x08")
    clock.t = 100
    assert port.send(frame)
    assert port.tx_pending() == 1
    bits = frame_bits(0x123, frame.data, False)
    clock.t = 100 + bits - 1
    assert port.tx_pending() == 1 and other.got == []
    clock.t = 100 + bits
    assert port.tx_pending() == 0
    assert other.got == [(100 + bits, frame)]
    assert bus.load(100 + bits) == pytest.approx(bits / (100 + bits))


def test_lowest_id_wins_arbitration_and_the_loser_follows():
    world, bus, clock = _bus()
    a, b = VirtualBxCan(clock, bus, "a"), VirtualBxCan(clock, bus, "b")
    seen = _Listener()
    bus.attach(seen)
    clock.t = 10
    hi, lo, ext = CanFrame(0x200, b"\x00"), CanFrame(0x100, b"\x00"), CanFrame((0x100 << 18) | 5, b"\x00", True)
    assert a.send(hi) and b.send(ext) and b.send(lo)
    clock.t = 10_000
    a.tx_pending()
    assert [f for _, f in seen.got] == [lo, ext, hi]  # a standard frame beats an extended one of the same base
    assert bus.arbitration_losses == 2 + 1
    ends = [t for t, _ in seen.got]
    assert ends[0] == 10 + frame_bits(0x100, b"\x00", False)
    assert ends[1] == ends[0] + frame_bits(ext.arbitration_id, b"\x00", True)


def test_three_mailboxes_then_refused():
    world, bus, clock = _bus()
    port = VirtualBxCan(clock, bus)
    clock.t = 1
    assert all(port.send(CanFrame(0x10 + i, b"")) for i in range(TX_MAILBOXES))
    assert not port.send(CanFrame(0x20, b""))
    assert port.errors.tx_refused == 1
    assert not port.flush(0.1)
    clock.t = 1 + 3 * worst_case_bits(0, False)
    assert port.send(CanFrame(0x20, b"")) and port.errors.tx_refused == 1


@pytest.mark.parametrize("lock", [False, True])
def test_fifo_overrun_keeps_three_and_counts(lock):
    world, bus, clock = _bus()
    port = VirtualBxCan(clock, bus, fifo_lock=lock)
    sender = VirtualBxCan(clock, bus, "sender")
    frames = [CanFrame(0x100 + i, bytes([i])) for i in range(5)]
    clock.t = 1
    for f in frames[:3]:
        assert sender.send(f)
    clock.t = 2_000
    for f in frames[3:]:
        assert sender.send(f)
    clock.t = 4_000
    assert port.fifo_level(0) == FIFO_DEPTH
    assert port.errors.overruns == 2 and port.fifo_overruns == [2, 0]
    got = [port.receive() for _ in range(4)]
    last = frames[2] if lock else frames[4]  # locked: the new ones are discarded; else they overwrite the last
    assert got == [frames[0], frames[1], last, None]


def test_reading_in_time_avoids_the_overrun():
    world, bus, clock = _bus()
    port, sender = VirtualBxCan(clock, bus), VirtualBxCan(clock, bus, "sender")
    got = []
    for i in range(6):
        clock.t = 1 + 200 * i
        assert sender.send(CanFrame(0x100 + i, b""))
        clock.t += 150
        while (f := port.receive()) is not None:
            got.append(f.arbitration_id)
    assert got == [0x100 + i for i in range(6)] and port.errors.overruns == 0


def test_filters_route_to_fifos_and_drop_the_rest():
    world, bus, clock = _bus()
    port, sender = VirtualBxCan(clock, bus), VirtualBxCan(clock, bus, "sender")
    port.set_filters([FilterBank(0x2900, 0x1FFFFF00, True, fifo=1), FilterBank(0x000, 0x7FF, False, fifo=0)])
    clock.t = 1
    for f in (CanFrame(0x2901, b"\x01", True), CanFrame(0x000, b"\x02"), CanFrame(0x055, b"\x03")):
        assert sender.send(f)
    clock.t = 1000
    assert (port.fifo_level(0), port.fifo_level(1), port.filtered) == (1, 1, 1)
    assert port.receive() == CanFrame(0x000, b"\x02")  # FIFO 0 first
    assert port.receive() == CanFrame(0x2901, b"\x01", True)
    with pytest.raises(ValueError, match="15 filter banks"):
        port.set_filters([FilterBank(0, 0, False)] * 15)


def test_closed_port_raises_and_frames_are_checked():
    world, bus, clock = _bus()
    port = VirtualBxCan(clock, bus)
    port.close()
    with pytest.raises(HalError, match="closed"):
        port.send(CanFrame(1, b""))
    with pytest.raises(ValueError, match="out of range"):
        CanFrame(0x800, b"")
    with pytest.raises(ValueError, match="at most 8"):
        CanFrame(1, bytes(9))
    with pytest.raises(ValueError, match="bitrate"):
        VirtualCanBus(world, 2_000_000)

"""Virtual pins, watchdog forwarding, SysTick and the VirtualMcu bundle."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from hal.interfaces import Board
from hal.virtual.gpio import VirtualDigitalIn, VirtualDigitalOut, VirtualWatchdog
from hal.virtual.mcu import VirtualMcu
from hal.virtual.timer import SysTick


class Clock:
    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


def test_estop_follows_its_schedule_lazily() -> None:
    clock = Clock()
    pin = VirtualDigitalIn(clock)
    pin.set_at(2_000, False)
    pin.set_at(1_000, True)
    assert pin.read() is False
    clock.t = 999
    assert pin.read() is False
    clock.t = 1_000
    assert pin.read() is True
    clock.t = 5_000
    assert pin.read() is False
    with pytest.raises(ValueError, match="t_cycles 4999"):
        pin.set_at(4_999, True)
    pin.set(True)  # at the current cycle, after the read
    assert pin.read() is True


def test_same_cycle_changes_apply_in_call_order() -> None:
    clock = Clock()
    pin = VirtualDigitalIn(clock)
    pin.set_at(10, True)
    pin.set_at(10, False)
    clock.t = 10
    assert pin.read() is False


def test_led_records_changes_with_times() -> None:
    clock = Clock()
    led = VirtualDigitalOut(clock)
    clock.t = 5
    led.write(True)
    led.write(True)
    clock.t = 9
    led.toggle()
    assert led.level is False
    assert led.history == [(5, True), (9, False)]


def test_watchdog_forwards_kicks() -> None:
    kicked: list[int] = []
    dog = VirtualWatchdog(lambda: kicked.append(1))
    dog.kick()
    dog.kick()
    assert dog.kicks == 2 and len(kicked) == 2


@pytest.mark.parametrize(
    ("f_cpu", "load"), [(168_000_000, 167_999), (72_000_000, 71_999), (16_000_000, 15_999)]
)
def test_systick_load_matches_hal_init_tick(f_cpu: int, load: int) -> None:
    st_ = SysTick(f_cpu)
    assert st_.load == load
    assert st_.ticks(load) == 0 and st_.ticks(load + 1) == 1
    assert st_.val(0) == load and st_.val(load) == 0


def test_systick_24_bit_limit() -> None:
    SysTick(168_000_000, tick_hz=11)  # LOAD 15 272 726 fits
    with pytest.raises(ValueError, match="24 bits"):
        SysTick(168_000_000, tick_hz=10)  # LOAD 16 799 999 > 0xFFFFFF
    with pytest.raises(ValueError, match="tick_hz 0"):
        SysTick(168_000_000, tick_hz=0)


@given(cuts=st.lists(st.integers(0, 2_000_000), min_size=1, max_size=20))
def test_systick_interrupt_counts_ticks_in_windows(cuts: list[int]) -> None:
    tick = SysTick(168_000)  # period 168 cycles
    source = tick.interrupt(cost_cycles=80)
    edges = [0, *sorted(cuts)]
    for t0, t1 in zip(edges, edges[1:], strict=False):
        brute = sum(1 for k in range(1, t1 // 168 + 2) if t0 <= k * 168 < t1)
        assert source.count_in(t0, t1) == brute


def test_virtual_mcu_builds_a_board_and_lists_interrupt_sources() -> None:
    clock = Clock()
    mcu = VirtualMcu(clock, 168_000_000)
    motor = mcu.uart("motor", 921_600)
    imu = mcu.uart("imu", 115_200)
    tele = mcu.uart("telemetry", 921_600, tx_queue_size=1024)
    enc = mcu.encoder_timer(lambda t: 0.0)
    board = mcu.board(
        motor, imu, tele, enc, mcu.digital_in("estop"), mcu.digital_out("led"), mcu.watchdog(lambda: None)
    )
    assert isinstance(board, Board)
    assert board.uarts()["imu"] is imu
    clock.t = 168_000 * 7 + 5
    assert board.ticks_ms() == 7 == mcu.systick.ticks(clock.t)
    names = [s.name for s in mcu.interrupt_sources(120, 80, timer_update_cycles=60)]
    assert names == ["encoder_update", "motor_rx", "imu_rx", "telemetry_rx", "systick"]
    with pytest.raises(ValueError, match="'motor' already used"):
        mcu.uart("motor", 115_200)

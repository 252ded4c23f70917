"""The virtual bench: wiring, time order across devices, encoder, interrupts, handles, SimContext."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

from firmware.drivers.motor import FEEDBACK_MASK
from hal.binding import VIRTUAL_BENCH, bind_board
from hal.virtual.bench import FIXTURES, VirtualBench, fixture_by_name
from hal.virtual.plant import FixtureKind, Plant
from protocol.rvc import RvcDecoder
from protocol.vesc import Decoder, GetValuesSelective, SetCurrent, ValuesSelective
from rtos import Scheduler, Task, VirtualClock

F = 168_000_000
ISR = tomllib.loads((Path(__file__).resolve().parents[1] / "profiles" / "board_stm32f4.toml").read_text())[
    "isr_cycles"]


class Clock:
    """A settable cycle clock."""

    def __init__(self) -> None:
        self.t = 0

    def __call__(self) -> int:
        return self.t


def test_build_wires_the_board_without_reading_the_clock() -> None:
    def not_yet() -> int:
        raise AssertionError("the clock must not be read while the bench is built")

    bench = VirtualBench(not_yet, F, seed=3)
    board = bench.board
    assert board.motor_uart is bench.motor_uart and board.imu_uart is bench.imu_uart
    assert board.telemetry_uart is bench.telemetry_uart and board.encoder is bench.encoder
    assert board.estop is bench.estop and board.led is bench.led and board.watchdog is bench.watchdog
    assert (board.motor_uart.baud, board.imu_uart.baud, board.f_cpu_hz) == (921_600, 115_200, F)
    assert bench.motor_uart.peer is bench.motor and bench.imu_uart.peer is bench.imu


def test_a_thousand_hertz_motor_loop_gets_every_reply_and_imu_frames_at_100_hz() -> None:
    clock = Clock()
    bench = VirtualBench(clock, F, initial_angle_rad=0.2)
    motor_rx, imu_rx = Decoder("from-motor"), RvcDecoder()
    request = GetValuesSelective(FEEDBACK_MASK).encode()
    replies = []
    for k in range(300):
        clock.t = k * F // 1000
        replies += motor_rx.feed(bench.board.motor_uart.read())
        imu_rx.feed(bench.board.imu_uart.read())
        bench.board.motor_uart.write(SetCurrent(3.0).encode() + request)
    assert len(replies) == 299 and all(isinstance(r, ValuesSelective) for r in replies)
    assert imu_rx.stats.frames == 29 and imu_rx.stats.lost_frames == 0
    assert bench.motor.stats.commands == 299 and bench.motor_uart.errors.total() == 0  # last: on the wire
    # the motor lifts the foot: position and speed in the replies grow
    assert replies[-1].values["pid_pos_rad"] > replies[0].values["pid_pos_rad"]


def test_plant_view_runs_device_events_before_a_later_query() -> None:
    clock = Clock()
    bench = VirtualBench(clock, F)
    bench.board.motor_uart.write(SetCurrent(2.0).encode())
    end = bench.motor_uart.tx_line_busy_until
    later = (end + 1000) / F
    assert bench.plant.state_at(later).current_command_a == 2.0  # the command ran first, at its end time
    assert bench.plant.params.peak_current_a == 22.7  # attributes pass through
    raw = VirtualBench(clock, F)
    raw.board.motor_uart.write(SetCurrent(2.0).encode())
    raw.plant.raw.output_angle_rad(later)  # bypassing the world: the plant is now past the command
    with pytest.raises(ValueError, match="past"):
        raw.advance_to(end + 1000)


def test_encoder_counts_the_ankle_from_its_power_up_position() -> None:
    clock = Clock()
    bench = VirtualBench(clock, F, initial_angle_rad=0.5)  # the suspended foot falls
    assert bench.encoder.cnt() == 0
    twin = Plant(initial_angle_rad=0.5)
    for k in range(1, 30):
        clock.t = k * F // 100
        counts = math.floor((twin.output_angle_rad(clock.t / F) - 0.5) * 4000 / math.tau)
        assert bench.encoder.cnt() == counts % 65536
    assert bench.encoder.cnt() > 60000 and bench.encoder.counting_down()  # wrapped below zero


def test_interrupt_sources_drive_the_scheduler() -> None:
    bench = VirtualBench(lambda: sched.now, F)
    request = GetValuesSelective(FEEDBACK_MASK).encode()

    def motor_task(job: object) -> None:
        bench.board.motor_uart.read()
        bench.board.motor_uart.write(SetCurrent(0.5).encode() + request)

    sources = bench.interrupt_sources(ISR, encoder_wraps=True)
    assert [s.name for s in sources] == ["encoder_update", "motor_rx", "imu_rx", "telemetry_rx", "systick"]
    sched = Scheduler([Task("motor", 1, period=F // 1000, cost=20_000, body=motor_task)], VirtualClock(F),
                      interrupts=sources)
    sched.run_until(F // 10)
    fired = {s.name: s.in_jobs + s.while_idle for s in sched.interrupt_stats()}
    assert fired["systick"] == 99  # k * 1 ms for k >= 1, inside [0, 0.1 s)
    assert fired["motor_rx"] == 100 * 23  # every byte of the 100 replies (23 B each), the last by 99.6 ms
    assert fired["imu_rx"] == 81 + 9 * 19  # banner and nine frames by 0.1 s
    assert bench.encoder_mount.late_queries == 0
    assert [s.name for s in VirtualBench(Clock(), F).interrupt_sources(ISR)] == [
        "motor_rx", "imu_rx", "telemetry_rx", "systick"]
    with pytest.raises(ValueError, match="uart_rx_byte"):
        bench.interrupt_sources({"systick": 80})


def test_handles_estop_led_watchdog_telemetry() -> None:
    clock = Clock()
    bench = VirtualBench(clock, F)
    bench.estop.set_at(F // 2, True)
    clock.t = F // 2 - 1
    assert bench.board.estop.read() is False
    clock.t = F // 2
    assert bench.board.estop.read() is True
    bench.board.led.write(True)
    assert bench.led.history == [(F // 2, True)]

    class Dog:
        kicks = 0

        def kick(self) -> None:
            self.kicks += 1

    dog = Dog()
    bench.board.watchdog.kick()  # nothing attached yet: counted, not forwarded
    bench.attach_watchdog(dog)
    bench.board.watchdog.kick()
    assert dog.kicks == 1 and bench.watchdog.kicks == 2
    bench.board.telemetry_uart.write(b"hello")
    assert bench.telemetry_bytes() == b"hello"
    with pytest.raises(TypeError):
        bench.attach_watchdog(object())


def test_fault_injection_handles() -> None:
    clock = Clock()
    bench = VirtualBench(clock, F)
    bench.motor_uart.inject_garbage(b"\x00\x01", 100)
    bench.imu.silence(0.0, 1.0)
    bench.motor.inject_fault(3, 0.001)
    clock.t = F // 10
    assert bench.board.motor_uart.read() == b"\x00\x01"
    assert bench.board.imu_uart.read() == b"".join(line.encode() + b"\r\n" for line in bench.imu.config.banner)
    assert bench.motor.fault == 3


def test_sim_context_for_bind_board() -> None:
    clock = Clock()
    bench = VirtualBench(clock, F, motor_baud=460_800)
    board = bind_board(VIRTUAL_BENCH, bauds={"motor": 460_800, "imu": 115_200, "telemetry": 921_600},
                       watchdog=bench.watchdog, now_cycles=clock, f_cpu_hz=F, context=bench)
    assert board.motor_uart is bench.motor_uart and board.encoder is bench.encoder
    assert board.estop is bench.estop and board.led is bench.led
    with pytest.raises(ValueError, match="460800"):
        bench.virtual_uart("motor", "ak60-6", 921_600)
    with pytest.raises(ValueError, match="bno08x"):
        bench.virtual_uart("imu", "ak60-6", 115_200)


def test_fixtures_by_name() -> None:
    assert VirtualBench(Clock(), F, fixture="spring_bench").plant.fixture.kind is FixtureKind.SPRING_BENCH
    assert not fixture_by_name("unpowered").powered
    assert set(FIXTURES) >= {"suspended", "spring_bench", "unpowered"}
    with pytest.raises(ValueError, match="suspended"):
        fixture_by_name("trampoline")

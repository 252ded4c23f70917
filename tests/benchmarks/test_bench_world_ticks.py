"""Speed of the virtual bench: 1000 motor ticks at 1 kHz (run with --benchmark-only).

One tick = what a 1 kHz motor task does against the bench: read the motor and IMU UARTs, read the
encoder, write SET_CURRENT + GET_VALUES_SELECTIVE. Wall time per tick is the bench's cost per
millisecond of simulated time (the firmware's and the scheduler's own work come on top).
"""

from __future__ import annotations

import math

from firmware.drivers.motor import FEEDBACK_MASK
from hal.virtual.bench import VirtualBench
from protocol.rvc import RvcDecoder
from protocol.vesc import Decoder, GetValuesSelective, SetCurrent

F = 168_000_000
TICKS = 1000


def run_ticks() -> int:
    """Run TICKS ticks on a fresh bench; return the replies received."""
    clock = [0]
    bench = VirtualBench(lambda: clock[0], F, initial_angle_rad=0.2)
    board = bench.board
    motor_rx, imu_rx = Decoder("from-motor"), RvcDecoder()
    request = GetValuesSelective(FEEDBACK_MASK).encode()
    replies = 0
    for k in range(TICKS):
        clock[0] = k * F // 1000
        replies += len(motor_rx.feed(board.motor_uart.read()))
        imu_rx.feed(board.imu_uart.read())
        board.encoder.cnt()
        board.motor_uart.write(SetCurrent(1.0 + 0.5 * math.sin(k * 0.01)).encode() + request)
    return replies


def test_bench_1000_ticks(benchmark):
    assert benchmark.pedantic(run_ticks, rounds=5, iterations=1) == TICKS - 1

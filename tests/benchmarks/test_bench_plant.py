"""Plant integration speed (run with --benchmark-only): wall time per simulated second; see docs/plant.md."""

from __future__ import annotations

import math
from typing import Any

from hal.virtual.plant import Plant, load_plant_params, spring_bench

PARAMS = load_plant_params()
UART_LATENCY_S = 0.0000371  # commands land off the 0.1 ms integration grid, as packets do


def one_second_with_commands(query: bool) -> float:
    """1 s of simulated time, spring bench, a new current command every 1 ms (optionally an angle read)."""
    plant = Plant(PARAMS, spring_bench(0.68), initial_angle_rad=0.0)
    for k in range(1000):
        t = k * 1e-3 + UART_LATENCY_S
        plant.set_current_command(3.0 + 2.0 * math.sin(2 * math.pi * 1.0 * t), t)
        if query:
            plant.output_angle_rad(t + 0.0002)
    return plant.output_angle_rad(1.0)


def one_second_through_the_backlash() -> float:
    """1 s of simulated time, spring bench, the packaged backlash, a current command every 1 ms reversing at 5 Hz
    (9 reversals: the gap is crossed at each, and more often as the foot rests on its stop), an angle read and a
    motor sample (current, rotor speed and angle) every 1 ms."""
    plant = Plant(PARAMS, spring_bench(0.68), initial_angle_rad=0.0, backlash_rad=math.radians(PARAMS.backlash_deg))
    for k in range(1000):
        t = k * 1e-3 + UART_LATENCY_S
        plant.set_current_command(2.0 * math.sin(2 * math.pi * 5.0 * t), t)
        plant.output_angle_rad(t + 0.0002)
        plant.motor_sample(t + 0.0004)
    assert plant.gap_crossings >= 9
    return plant.output_angle_rad(1.0)


def one_second_free() -> float:
    """1 s of simulated time without inputs (pure integration)."""
    plant = Plant(PARAMS, spring_bench(0.68), initial_angle_rad=0.3)
    plant.advance_to(1.0)
    return plant.output_angle_rad(1.0)


def test_bench_plant_1s_commands_every_1ms(benchmark: Any) -> None:
    angle = benchmark.pedantic(one_second_with_commands, args=(False,), rounds=9, iterations=1)
    assert PARAMS.stop_min_rad - 0.05 < angle < PARAMS.stop_max_rad + 0.05


def test_bench_plant_1s_commands_and_reads_every_1ms(benchmark: Any) -> None:
    angle = benchmark.pedantic(one_second_with_commands, args=(True,), rounds=9, iterations=1)
    assert PARAMS.stop_min_rad - 0.05 < angle < PARAMS.stop_max_rad + 0.05


def test_bench_plant_1s_backlash_commands_and_motor_reads_every_1ms(benchmark: Any) -> None:
    angle = benchmark.pedantic(one_second_through_the_backlash, rounds=9, iterations=1)
    assert PARAMS.stop_min_rad - 0.05 < angle < PARAMS.stop_max_rad + 0.05


def test_bench_plant_1s_free(benchmark: Any) -> None:
    angle = benchmark.pedantic(one_second_free, rounds=9, iterations=1)
    assert PARAMS.stop_min_rad - 0.05 < angle < PARAMS.stop_max_rad + 0.05

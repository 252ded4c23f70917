"""Cost of the per-sample control numerics (run with --benchmark-only); figures go in docs/control.md."""

from __future__ import annotations

from typing import Any

from firmware.control.estimation import AngleEstimator, VelocityEstimator
from firmware.control.filters import ButterworthLowPass
from firmware.control.pid import CascadeController, FeedforwardParams, PidGains, feedforward_current_a
from firmware.control.reference import GaitReference


def test_bench_cascade_update(benchmark: Any) -> None:
    c = CascadeController(PidGains(2.0, 0.2, 0.05, 0.005), PidGains(0.2, 1.0), 0.001, 10.0, 8.0)
    result = benchmark(c.update, 0.1, 0.5, 0.09, 0.4)
    assert abs(result) <= 10.0


def test_bench_butterworth_step(benchmark: Any) -> None:
    f = ButterworthLowPass(2, 10.0, 100.0)
    benchmark(f.step, 0.3)


def test_bench_full_control_tick(benchmark: Any) -> None:
    """Reference + encoder velocity + fusion (+ IMU filter every 10th tick) + feed-forward + cascade."""
    c = CascadeController(PidGains(2.0, 0.2, 0.05, 0.005), PidGains(0.2, 1.0), 0.001, 10.0, 8.0)
    imu_filter = ButterworthLowPass(2, 10.0, 100.0)
    vel = VelocityEstimator(0.001)
    fusion = AngleEstimator(0.001)
    ref = GaitReference.normative()
    ff = FeedforwardParams(0.049, 1.176, 0.15, 0.078, 27.6, 0.9)
    counter = [0]

    def tick() -> float:
        k = counter[0]
        counter[0] = k + 1
        a, v, acc = ref.sample(k * 0.001)
        angle, velocity = vel.update((k * 3) & 0xFFFF)
        imu = imu_filter.step(0.1) if k % 10 == 0 else None
        theta = fusion.update(angle, imu)
        return c.update(a, v, theta, velocity, feedforward_current_a(a, acc, ff))

    result = benchmark(tick)
    assert abs(result) <= 10.0

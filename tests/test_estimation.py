"""Tests of the encoder arithmetic (wrap-safe deltas, velocity) and the encoder + IMU angle fusion."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware.control.estimation import AngleEstimator, VelocityEstimator, wrap_delta_counts

RAD_PER_COUNT = 2 * math.pi / 4000


@given(st.integers(0, 0xFFFF), st.integers(-32768, 32767))
def test_wrap_delta_16_bit(prev: int, delta: int) -> None:
    cnt = (prev + delta) % 0x10000
    assert wrap_delta_counts(cnt, prev) == delta
    assert wrap_delta_counts(cnt, prev) == ctypes.c_int16(cnt - prev).value   # the C cast


@given(st.integers(0, 3999), st.integers(-2000, 1999))
def test_wrap_delta_arr_3999(prev: int, delta: int) -> None:
    assert wrap_delta_counts((prev + delta) % 4000, prev, modulus=4000) == delta


def test_wrap_delta_both_directions_across_zero() -> None:
    assert wrap_delta_counts(5, 65530) == 11
    assert wrap_delta_counts(65530, 5) == -11
    assert wrap_delta_counts(0, 0xFFFF) == 1 and wrap_delta_counts(0xFFFF, 0) == -1


def encoder_count(angle_rad: float, zero_counts: int = 0) -> int:
    """CNT register of a 4000 count/rev encoder on a 16-bit timer."""
    return (math.floor(angle_rad / RAD_PER_COUNT) + zero_counts) % 0x10000


@pytest.mark.parametrize("speed", [12.0, -12.0])
def test_velocity_estimator_tracks_across_many_wraps(speed: float) -> None:
    ts = 0.001
    est = VelocityEstimator(ts_s=ts, velocity_cutoff_hz=20.0)
    zero = 65000   # arbitrary power-up count, close to the wrap
    theta0 = 0.0
    wraps = 0
    prev_cnt = None
    velocities = []
    for k in range(10000):   # 10 s at 12 rad/s = 19 rev = 76 000 counts: crosses the 16-bit wrap
        theta = speed * k * ts
        cnt = encoder_count(theta, zero)
        if prev_cnt is not None and abs(cnt - prev_cnt) > 30000:
            wraps += 1
        prev_cnt = cnt
        angle, vel = est.update(cnt)
        velocities.append(vel)
        if k == 0:
            theta0 = theta - angle
        assert abs(angle - (theta - theta0)) <= RAD_PER_COUNT + 1e-12
    assert wraps >= 1
    # 12 rad/s is 7.64 counts per 1 ms sample: the 20 Hz filter leaves a quantisation ripple.
    assert max(abs(v - speed) for v in velocities[-1000:]) < 0.1
    assert sum(velocities[-1000:]) / 1000 == pytest.approx(speed, abs=0.005)
    assert est.total_counts == pytest.approx(speed * 9.999 / RAD_PER_COUNT, abs=1.0)


def test_velocity_estimator_direction_and_reset() -> None:
    est = VelocityEstimator(ts_s=0.001, direction=-1)
    est.update(100)
    angle, _ = est.update(110)
    assert angle == pytest.approx(-10 * RAD_PER_COUNT)
    assert est.raw_velocity_rad_s == pytest.approx(-10 * RAD_PER_COUNT / 0.001)
    est.reset()
    assert est.update(5000 % 0x10000) == (0.0, 0.0)


@pytest.mark.parametrize(("kwargs", "name"), [({"ts_s": 0.0}, "ts_s"),
                                              ({"counts_per_rev": 0}, "counts_per_rev"),
                                              ({"direction": 2}, "direction"),
                                              ({"velocity_cutoff_hz": 600.0}, "cutoff_hz")])
def test_velocity_estimator_validation(kwargs: dict[str, float], name: str) -> None:
    args = {"ts_s": 0.001, **kwargs}
    with pytest.raises(ValueError, match=name):
        VelocityEstimator(**args)  # type: ignore[arg-type]


def run_fusion(est: AngleEstimator, seconds: float, true_offset: float, noise_rad: float, seed: int,
               imu_lag_s: float = 0.0195, imu_fault_after_s: float | None = None
               ) -> tuple[list[float], list[float], list[float]]:
    """Gait-like motion; encoder = truth - offset (quantised) at 1 kHz; IMU = lagged truth + noise, 100 Hz."""
    rng = np.random.default_rng(seed)
    ts = est.ts_s
    imu_state = None
    lag_beta = 1.0 - math.exp(-ts / imu_lag_s) if imu_lag_s > 0 else 1.0
    truth, fused, disagreement = [], [], []
    for k in range(round(seconds / ts)):
        t = k * ts
        theta = 0.2 + 0.25 * math.sin(2 * math.pi * t / 1.1) + 0.08 * math.sin(2 * math.pi * 3 * t / 1.1)
        imu_state = theta if imu_state is None else imu_state + lag_beta * (theta - imu_state)
        enc = math.floor((theta - true_offset) / RAD_PER_COUNT) * RAD_PER_COUNT
        imu = None
        if k % 10 == 0:
            imu = imu_state + float(rng.normal(0.0, noise_rad))
            if imu_fault_after_s is not None and t >= imu_fault_after_s:
                imu += 0.3
        truth.append(theta)
        fused.append(est.update(enc, imu))
        disagreement.append(est.disagreement_rad)
    return truth, fused, disagreement


def test_fusion_converges_to_true_offset_with_noisy_imu() -> None:
    est = AngleEstimator(ts_s=0.001, offset_tau_s=1.0)
    truth, fused, dis = run_fusion(est, 8.0, true_offset=0.7, noise_rad=0.01, seed=42)
    assert est.seeded and est.imu_samples == 800
    assert est.offset_rad == pytest.approx(0.7, abs=0.005)
    err = np.abs(np.array(fused[-3000:]) - np.array(truth[-3000:]))
    assert err.max() < 0.005 + RAD_PER_COUNT          # fast motion tracked by the encoder
    assert max(dis[-3000:]) < 5 * 0.01                  # innovations stay at the noise level


def test_fusion_first_imu_sample_seeds_offset() -> None:
    est = AngleEstimator(ts_s=0.001)
    assert est.update(1.0, None) == 1.0 and not est.seeded
    assert est.update(1.0, 1.3) == pytest.approx(1.3)
    assert est.offset_rad == pytest.approx(0.3) and est.disagreement_rad == 0.0


def test_fusion_lag_model_keeps_disagreement_small_during_motion() -> None:
    with_lag = AngleEstimator(ts_s=0.001, offset_tau_s=1.0, imu_lag_s=0.0195)
    without = AngleEstimator(ts_s=0.001, offset_tau_s=1.0, imu_lag_s=0.0)
    _, _, dis_lag = run_fusion(with_lag, 5.0, 0.4, 0.0, seed=1)
    _, _, dis_raw = run_fusion(without, 5.0, 0.4, 0.0, seed=1)
    assert max(dis_lag[-2000:]) < 0.003
    assert max(dis_raw[-2000:]) > 3 * max(dis_lag[-2000:])


def test_fusion_disagreement_flags_imu_fault() -> None:
    est = AngleEstimator(ts_s=0.001, offset_tau_s=2.0)
    _, _, dis = run_fusion(est, 4.0, 0.7, 0.005, seed=3, imu_fault_after_s=3.0)
    assert max(dis[2000:2990]) < 0.03
    assert dis[3005] > 0.25


@pytest.mark.parametrize(("kwargs", "name"), [({"offset_tau_s": 0.0}, "offset_tau_s"),
                                              ({"imu_lag_s": -0.1}, "imu_lag_s"), ({"ts_s": 5.0}, "ts_s")])
def test_fusion_validation(kwargs: dict[str, float], name: str) -> None:
    args = {"ts_s": 0.001, **kwargs}
    with pytest.raises(ValueError, match=name):
        AngleEstimator(**args)

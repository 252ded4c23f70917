"""Tests of the per-sample Butterworth and first-order low-pass filters against scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from firmware.config import FirmwareConfig
from firmware.control.filters import ButterworthLowPass, FirstOrderLowPass


@pytest.mark.parametrize(("order", "cutoff", "fs"), [(1, 5.0, 100.0), (2, 10.0, 100.0), (4, 20.0, 1000.0),
                                                     (5, 200.0, 1000.0), (8, 3.0, 100.0)])
def test_butterworth_matches_sosfilt(order: int, cutoff: float, fs: float) -> None:
    rng = np.random.default_rng(20240501 + order)
    x = rng.normal(0.0, 1.0, 3000)
    f = ButterworthLowPass(order, cutoff, fs)
    got = np.array([f.step(float(v)) for v in x])
    ref = signal.sosfilt(signal.butter(order, cutoff, fs=fs, output="sos"), x)
    assert np.max(np.abs(got - ref)) < 1e-12


def test_butterworth_initial_value_matches_sosfilt_zi() -> None:
    rng = np.random.default_rng(7)
    x = 2.5 + rng.normal(0.0, 0.1, 500)
    sos = signal.butter(2, 8.0, fs=100.0, output="sos")
    ref, _ = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * 2.5)
    f = ButterworthLowPass(2, 8.0, 100.0, initial_value=2.5)
    assert np.max(np.abs(np.array([f.step(float(v)) for v in x]) - ref)) < 1e-12
    f.reset(-1.0)
    assert all(f.step(-1.0) == pytest.approx(-1.0, abs=1e-12) for _ in range(50))
    assert np.array_equal(np.array(f.sos), sos)


def test_butterworth_attenuates_above_cutoff() -> None:
    fs, fc = 100.0, 10.0
    f = ButterworthLowPass(2, fc, fs)
    t = np.arange(2000) / fs
    y = np.array([f.step(math.sin(2 * math.pi * 40.0 * tk)) for tk in t])
    assert np.max(np.abs(y[500:])) < 0.1   # 40 Hz, two octaves above a 2nd-order 10 Hz cutoff


@pytest.mark.parametrize(("cutoff", "fs"), [(50.0, 100.0), (60.0, 100.0), (0.0, 100.0), (-1.0, 100.0),
                                            (math.nan, 100.0)])
def test_cutoff_must_be_below_nyquist(cutoff: float, fs: float) -> None:
    with pytest.raises(ValueError, match=r"cutoff_hz = .* sample_rate_hz = 100.0.*\(0, 50\) Hz"):
        ButterworthLowPass(2, cutoff, fs)
    with pytest.raises(ValueError, match="cutoff_hz"):
        FirstOrderLowPass(cutoff, fs)


def test_order_and_rate_validation() -> None:
    with pytest.raises(ValueError, match=r"order = 0 .*\[1, 8\]"):
        ButterworthLowPass(0, 10.0, 100.0)
    with pytest.raises(ValueError, match=r"imu_lowpass_order = 2\.0 is not allowed: must be an integer in \[1, 8\]"):
        FirmwareConfig(imu_lowpass_order=2.0)  # type: ignore[arg-type]  # where users set it: the profile
    with pytest.raises(ValueError, match="sample_rate_hz"):
        ButterworthLowPass(2, 10.0, 0.0)


def test_first_order_matches_lfilter() -> None:
    rng = np.random.default_rng(99)
    x = rng.normal(0.0, 1.0, 3000)
    f = FirstOrderLowPass(30.0, 1000.0)
    a = f.alpha
    ref = signal.lfilter([a], [1.0, -(1.0 - a)], x)
    got = np.array([f.step(float(v)) for v in x])
    assert np.max(np.abs(got - ref)) < 1e-12


def test_first_order_step_response_time_constant() -> None:
    fs, fc = 1000.0, 5.0
    f = FirstOrderLowPass(fc, fs)
    tau_samples = round(f.time_constant_s * fs)
    y = [f.step(1.0) for _ in range(tau_samples)]
    assert y[-1] == pytest.approx(1.0 - math.exp(-tau_samples / (f.time_constant_s * fs)), abs=1e-12)
    assert y[-1] == pytest.approx(1.0 - math.exp(-1.0), abs=0.01)
    f.reset(3.0)
    assert f.value == 3.0 and f.step(3.0) == 3.0

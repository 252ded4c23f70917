"""TrackingStream: the figures of host_tools.reports.metrics from samples fed in chunks, whatever the chunking."""

from __future__ import annotations

import numpy as np
import pytest

from host_tools.reports.metrics import cut_strides, run_window, signal_figures, tracking_metrics
from host_tools.reports.tracking_stream import TrackingStream


def _samples(seed: int = 1, seconds: float = 30.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.sort(np.arange(0.0, seconds, 0.002) + rng.normal(0.0, 1e-5, int(seconds / 0.002)))
    ref = 0.3 * np.sin(2 * np.pi * t / 1.1)
    ang = 0.3 * np.sin(2 * np.pi * (t - 0.013) / 1.1) + rng.normal(0.0, 0.002, len(t))
    return t, ref, ang


@pytest.mark.parametrize("chunk", [15_000, 500, 37, 3])  # 3: every add a few samples; 1 took 6 s
def test_chunked_figures_are_those_of_the_whole_arrays(chunk: int) -> None:
    t, ref, ang = _samples()
    m = tracking_metrics(t, ref, ang, start_s=1.5, stride_s=1.1, strides=20)
    strides = cut_strides(t, ref, ang, start_s=1.5, stride_s=1.1, strides=20)
    s = TrackingStream(("a",), stride_s=1.1, strides=20, dt_s=float(np.median(np.diff(t))),
                       expected_samples=len(t), plot_points=1000)
    run = np.ones(len(t), dtype=bool)
    for k in range(0, len(t), chunk):
        end = min(k + chunk, len(t))
        s.set_start(1.5 if t[end - 1] > 1.0 else None)  # as the firmware: known ahead of the gait's start
        s.add(t[k:end], ref[k:end], {"a": ang[k:end]}, run[k:end], ref[k:end], ang[k:end])
    r = s.finish()
    assert r.metrics["a"].samples == m.samples
    assert r.metrics["a"].rms_error_deg == pytest.approx(m.rms_error_deg, rel=1e-12)
    assert r.metrics["a"].max_error_deg == m.max_error_deg
    assert r.metrics["a"].lag_ms == pytest.approx(m.lag_ms, rel=1e-9)
    assert np.array_equal(r.strides["a"].angles_deg, strides.angles_deg)
    assert np.array_equal(r.strides["a"].reference_deg, strides.reference_deg)
    assert len(s._t) <= 2 * s.n_lag + 1 + chunk  # what is held: the lag's window and the last chunk


def test_plot_series_is_bounded_and_keeps_the_extremes() -> None:
    t, ref, ang = _samples(seconds=60.0)
    s = TrackingStream(("a",), stride_s=1.1, strides=40, dt_s=0.002, expected_samples=len(t), plot_points=1000)
    s.set_start(1.5)
    run = np.ones(len(t), dtype=bool)
    for k in range(0, len(t), 700):
        s.add(t[k:k + 700], ref[k:k + 700], {"a": ang[k:k + 700]}, run[k:k + 700], ref[k:k + 700], ang[k:k + 700])
    p = s.finish().plot
    assert p.group == 30 and len(p.t_s) == 2 * 1000
    assert p.current_cmd_a.max() == ref.max() and p.current_cmd_a.min() == ref.min()
    err = np.degrees(ref - ang)  # reference minus the signal
    assert p.errors_deg["a"].max() == err.max() and p.errors_deg["a"].min() == err.min()


def test_no_start_means_no_figures() -> None:
    t, ref, ang = _samples(seconds=5.0)
    s = TrackingStream(("a",), stride_s=1.1, strides=2, dt_s=0.002)
    s.add(t, ref, {"a": ang}, np.ones(len(t), dtype=bool), ref, ang)
    r = s.finish()
    assert r.metrics["a"].samples == 0 and np.isnan(r.metrics["a"].rms_error_deg)
    assert r.strides["a"].angles_deg.shape == (0, 101) and not r.enough and r.time_in_run_s == 0.0


@pytest.mark.parametrize("chunk", [4000, 333])
def test_run_mask_and_missing_samples_give_the_figures_of_signal_figures(chunk: int) -> None:
    """Samples outside RUN (SAFE latched at 9 s) and NaN ones (an IMU before its first frame) count nowhere."""
    t, ref, ang = _samples(seconds=12.0)
    state = np.where(t < 9.0, 1, 2)
    imu = np.where(t < 2.0, np.nan, ang)
    w = run_window(t, state, gait_start_s=1.5, stride_s=1.1, strides=9)
    s = TrackingStream(("enc", "imu"), stride_s=1.1, strides=9, dt_s=float(np.median(np.diff(t))))
    s.set_start(1.5)
    for k in range(0, len(t), chunk):
        sl = slice(k, k + chunk)
        s.add(t[sl], ref[sl], {"enc": ang[sl], "imu": imu[sl]}, state[sl] == 1, ref[sl], ang[sl])
    r = s.finish()
    assert r.enough == w.enough and r.time_in_run_s == pytest.approx(w.time_in_run_s, abs=0.003)
    for name, angle in (("enc", ang), ("imu", imu)):
        want = signal_figures(t, ref, angle, w)
        got = r.metrics[name]
        assert got.rms_error_deg == pytest.approx(want["rms_deg"], abs=1e-4)
        assert got.max_error_deg == pytest.approx(want["max_deg"], abs=1e-4)
        assert got.lag_ms == pytest.approx(want["lag_ms"], abs=0.01)
    assert r.metrics["imu"].samples < r.metrics["enc"].samples  # the NaN IMU samples are left out

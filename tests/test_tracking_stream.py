"""TrackingStream: the figures of host_tools.metrics from samples fed in chunks, whatever the chunking."""

from __future__ import annotations

import numpy as np
import pytest

from host_tools.metrics import cut_strides, tracking_metrics
from host_tools.tracking_stream import TrackingStream


def _samples(seed: int = 1, seconds: float = 30.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.sort(np.arange(0.0, seconds, 0.002) + rng.normal(0.0, 1e-5, int(seconds / 0.002)))
    ref = 0.3 * np.sin(2 * np.pi * t / 1.1)
    ang = 0.3 * np.sin(2 * np.pi * (t - 0.013) / 1.1) + rng.normal(0.0, 0.002, len(t))
    return t, ref, ang


@pytest.mark.parametrize("chunk", [15_000, 500, 37, 1])
def test_chunked_figures_are_those_of_the_whole_arrays(chunk: int) -> None:
    t, ref, ang = _samples()
    m = tracking_metrics(t, ref, ang, start_s=1.5, stride_s=1.1, strides=20)
    strides = cut_strides(t, ref, ang, start_s=1.5, stride_s=1.1, strides=20)
    s = TrackingStream(stride_s=1.1, strides=20, dt_s=float(np.median(np.diff(t))), expected_samples=len(t),
                       plot_points=1000)
    for k in range(0, len(t), chunk):
        end = min(k + chunk, len(t))
        s.set_start(1.5 if t[end - 1] > 1.0 else None)  # as the firmware: known ahead of the gait's start
        s.add(t[k:end], ref[k:end], ang[k:end], ref[k:end], ang[k:end])
    r = s.finish()
    assert r.metrics.samples == m.samples
    assert r.metrics.rms_error_deg == pytest.approx(m.rms_error_deg, rel=1e-12)
    assert r.metrics.max_error_deg == m.max_error_deg
    assert r.metrics.lag_ms == pytest.approx(m.lag_ms, rel=1e-9)
    assert np.array_equal(r.strides.angles_deg, strides.angles_deg)
    assert np.array_equal(r.strides.reference_deg, strides.reference_deg)
    assert len(s._t) <= 2 * s.n_lag + 1 + chunk  # what is held: the lag's window and the last chunk


def test_plot_series_is_bounded_and_keeps_the_extremes() -> None:
    t, ref, ang = _samples(seconds=60.0)
    s = TrackingStream(stride_s=1.1, strides=40, dt_s=0.002, expected_samples=len(t), plot_points=1000)
    s.set_start(1.5)
    for k in range(0, len(t), 700):
        s.add(t[k:k + 700], ref[k:k + 700], ang[k:k + 700], ref[k:k + 700], ang[k:k + 700])
    p = s.finish().plot
    assert p.group == 30 and len(p.t_s) == 2 * 1000
    assert p.current_cmd_a.max() == ref.max() and p.current_cmd_a.min() == ref.min()
    err = np.degrees(ang - ref)
    assert p.error_deg.max() == err.max() and p.error_deg.min() == err.min()


def test_no_start_means_no_figures() -> None:
    t, ref, ang = _samples(seconds=5.0)
    s = TrackingStream(stride_s=1.1, strides=2, dt_s=0.002)
    s.add(t, ref, ang, ref, ang)
    r = s.finish()
    assert r.metrics.samples == 0 and np.isnan(r.metrics.rms_error_deg) and r.strides.angles_deg.shape == (0, 101)

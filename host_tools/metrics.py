"""Tracking metrics of a run: RMS and max error, lag, and the strides cut out on a % gait grid."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["StrideSet", "TrackingMetrics", "cut_strides", "tracking_metrics"]


@dataclass(frozen=True)
class TrackingMetrics:
    """Error of the foot angle against the reference over whole strides (degrees, milliseconds)."""

    rms_error_deg: float
    max_error_deg: float
    lag_ms: float
    samples: int


@dataclass(frozen=True)
class StrideSet:
    """Whole strides resampled on a common % gait grid: `angles_deg[k]` is stride k."""

    percent: np.ndarray
    angles_deg: np.ndarray
    reference_deg: np.ndarray


def _window(t_s: np.ndarray, start_s: float, stride_s: float, strides: int) -> np.ndarray:
    return (t_s >= start_s) & (t_s < start_s + stride_s * strides)


def tracking_metrics(t_s: np.ndarray, reference_rad: np.ndarray, angle_rad: np.ndarray, *,
                     start_s: float, stride_s: float, strides: int, max_lag_s: float = 0.2) -> TrackingMetrics:
    """Metrics over `strides` whole strides from `start_s`; lag = the delay that best aligns the two.

    >>> t = np.arange(0, 2, 0.001); ref = np.sin(2 * np.pi * t); ang = np.sin(2 * np.pi * (t - 0.01))
    >>> m = tracking_metrics(t, ref, ang, start_s=0.5, stride_s=1.0, strides=1)
    >>> round(m.lag_ms), m.samples
    (10, 1000)
    """
    t_s, ref, ang = (np.asarray(a, dtype=float) for a in (t_s, reference_rad, angle_rad))
    sel = _window(t_s, start_s, stride_s, strides)
    if not sel.any():
        nan = float("nan")
        return TrackingMetrics(nan, nan, nan, 0)
    err = np.degrees(ang[sel] - ref[sel])
    dt = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 1.0
    best_lag, best = 0, np.inf
    idx = np.flatnonzero(sel)
    for k in range(0, int(max_lag_s / dt) + 1):
        lo = idx[idx - k >= 0]
        cost = float(np.mean((ang[lo] - ref[lo - k]) ** 2)) if len(lo) else np.inf
        if cost < best:
            best_lag, best = k, cost
    return TrackingMetrics(
        rms_error_deg=float(np.sqrt(np.mean(err**2))),
        max_error_deg=float(np.max(np.abs(err))),
        lag_ms=best_lag * dt * 1e3,
        samples=int(sel.sum()),
    )


def cut_strides(t_s: np.ndarray, reference_rad: np.ndarray, angle_rad: np.ndarray, *, start_s: float,
                stride_s: float, strides: int, points: int = 101) -> StrideSet:
    """Resample each whole stride on 0..100 % gait (degrees), for the per-stride plot."""
    percent = np.linspace(0.0, 100.0, points)
    angles, refs = [], []
    for k in range(strides):
        t0 = start_s + k * stride_s
        if t0 + stride_s > t_s[-1]:
            break
        tt = t0 + percent / 100.0 * stride_s
        angles.append(np.degrees(np.interp(tt, t_s, angle_rad)))
        refs.append(np.degrees(np.interp(tt, t_s, reference_rad)))
    shape = (0, points)
    return StrideSet(percent, np.array(angles).reshape(-1, points) if angles else np.empty(shape),
                     np.array(refs).reshape(-1, points) if refs else np.empty(shape))

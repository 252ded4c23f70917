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

    The lag is the shift (whole samples, refined by a parabola through the neighbouring costs) that
    minimises the mean square difference; negative means the angle leads the reference.

    >>> t = np.arange(0, 2, 0.001); ref = np.sin(2 * np.pi * t); ang = np.sin(2 * np.pi * (t - 0.01))
    >>> m = tracking_metrics(t, ref, ang, start_s=0.5, stride_s=1.0, strides=1)
    >>> round(m.lag_ms), m.samples
    (10, 1000)
    >>> m = tracking_metrics(t, ref, np.sin(2 * np.pi * (t - 0.0004)), start_s=0.5, stride_s=1.0, strides=1)
    >>> round(m.lag_ms, 2)
    0.4
    """
    t_s, ref, ang = (np.asarray(a, dtype=float) for a in (t_s, reference_rad, angle_rad))
    sel = _window(t_s, start_s, stride_s, strides)
    if not sel.any():
        nan = float("nan")
        return TrackingMetrics(nan, nan, nan, 0)
    err = np.degrees(ang[sel] - ref[sel])
    dt = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 1.0
    idx = np.flatnonzero(sel)
    n_lag = int(max_lag_s / dt)

    def cost(k: int) -> float:  # mean square of angle(t) - reference(t - k dt) over the window
        ok = idx[(idx - k >= 0) & (idx - k < len(ref))]
        return float(np.mean((ang[ok] - ref[ok - k]) ** 2)) if len(ok) else np.inf

    costs = {k: cost(k) for k in range(-n_lag, n_lag + 1)}
    best = min(costs, key=costs.__getitem__)
    lag = float(best)
    c_m, c_0, c_p = costs.get(best - 1), costs[best], costs.get(best + 1)
    if c_m is not None and c_p is not None and np.isfinite(c_m + c_p) and c_m + c_p - 2 * c_0 > 0:
        lag += 0.5 * (c_m - c_p) / (c_m + c_p - 2 * c_0)  # parabola through the three: sub-sample lag
    return TrackingMetrics(
        rms_error_deg=float(np.sqrt(np.mean(err**2))),
        max_error_deg=float(np.max(np.abs(err))),
        lag_ms=lag * dt * 1e3,
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

"""Tracking metrics of a run: RMS and max error, lag, and the strides cut out on a % gait grid.

The figures are computed only where the firmware was actually walking: the supervisor in RUN and the
gait (not the start-up ramp) running, within the whole strides asked for (:func:`run_window`). A run
with less than ``MIN_RUN_STRIDES`` stride of such time gets no figure (None), only the time it had.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MIN_RUN_STRIDES", "RUN_STATE", "RunWindow", "StrideSet", "TrackingMetrics", "cut_strides",
           "run_window", "signal_figures", "tracking_metrics"]

#: Value of SupervisorState.RUN as the probe records it (protocol.telemetry).
RUN_STATE = 1
#: Least time in RUN with the gait running, in strides, for a tracking figure: one whole stride, so that
#: every phase of the gait (swing and stance) is in the figure at least once.
MIN_RUN_STRIDES = 1.0


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


@dataclass(frozen=True)
class RunWindow:
    """The samples a tracking figure may use: in the stride window, supervisor in RUN, gait running."""

    mask: np.ndarray
    time_in_run_s: float
    min_run_s: float
    sample_s: float = 0.0

    @property
    def enough(self) -> bool:
        """Whether the run walked MIN_RUN_STRIDES strides (less one sample: the probe's phase) for a figure."""
        return self.time_in_run_s > 0.0 and self.time_in_run_s >= self.min_run_s - 1.5 * self.sample_s


def run_window(t_s: np.ndarray, supervisor_state: np.ndarray, *, gait_start_s: float | None, stride_s: float,
               strides: int) -> RunWindow:
    """Samples of `strides` whole strides from the gait start at which the supervisor was in RUN.

    time_in_run_s counts each such sample as one sampling period (the median spacing). A figure needs
    MIN_RUN_STRIDES strides of it, less one sample (a one-stride run may hold one sample fewer).

    >>> t = np.arange(0, 3, 0.01); state = np.where(t < 1.5, 1, 2)  # SAFE latched at 1.5 s
    >>> w = run_window(t, state, gait_start_s=0.5, stride_s=1.1, strides=2)
    >>> round(w.time_in_run_s, 2), w.enough
    (1.0, False)
    """
    t_s = np.asarray(t_s, dtype=float)
    min_run_s = MIN_RUN_STRIDES * stride_s
    if gait_start_s is None or not len(t_s):
        return RunWindow(np.zeros(len(t_s), dtype=bool), 0.0, min_run_s)
    mask = _window(t_s, gait_start_s, stride_s, strides) & (np.asarray(supervisor_state) == RUN_STATE)
    dt = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 0.0
    return RunWindow(mask, round(int(mask.sum()) * dt, 9), min_run_s, dt)


def signal_figures(t_s: np.ndarray, reference_rad: np.ndarray, angle_rad: np.ndarray | None,
                   window: RunWindow) -> dict[str, float | None]:
    """{"rms_deg", "max_deg", "lag_ms"} of reference minus angle over the window; None where not enough.

    NaN samples of the angle (an IMU before its first frame) are left out.
    """
    none: dict[str, float | None] = {"rms_deg": None, "max_deg": None, "lag_ms": None}
    if angle_rad is None or not window.enough:
        return none
    ang = np.asarray(angle_rad, dtype=float)
    mask = window.mask & np.isfinite(ang)
    if not mask.any():
        return none
    t = np.asarray(t_s, dtype=float)
    m = tracking_metrics(t, reference_rad, np.nan_to_num(ang), start_s=float(t[0]),
                         stride_s=float(t[-1] - t[0]) + 1.0, strides=1, mask=mask)
    return {"rms_deg": round(m.rms_error_deg, 4), "max_deg": round(m.max_error_deg, 4),
            "lag_ms": round(m.lag_ms, 2)}


def tracking_metrics(t_s: np.ndarray, reference_rad: np.ndarray, angle_rad: np.ndarray, *,
                     start_s: float, stride_s: float, strides: int, max_lag_s: float = 0.2,
                     mask: np.ndarray | None = None) -> TrackingMetrics:
    """Metrics over `strides` whole strides from `start_s` (and where `mask`); lag = the best-aligning delay.

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
    if mask is not None:
        sel &= np.asarray(mask, dtype=bool)
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

"""Tracking metrics, per-stride curves and a bounded plot series from probe samples fed in chunks.

A long run's samples never sit in memory together: :class:`TrackingStream` keeps running sums for the
RMS, maximum and lag of :func:`host_tools.metrics.tracking_metrics` (the lag's cost for each shift is
summed chunk by chunk, holding back the last ``max_lag_s`` of samples until the reference after them is
known), cuts each whole stride on the % gait grid of :func:`~host_tools.metrics.cut_strides` as soon as it
is complete, and keeps at most about ``plot_points`` samples of the time series for the plot (beyond that,
the minimum and maximum of each group of samples). Fed everything in one chunk, it gives the figures of
those two functions (to rounding); fed in chunks, the same figures whatever the chunking.

>>> t = np.arange(0, 2, 0.001); ref = np.sin(2 * np.pi * t); ang = np.sin(2 * np.pi * (t - 0.01))
>>> s = TrackingStream(stride_s=1.0, strides=1, dt_s=0.001)
>>> s.set_start(0.5)
>>> for k in range(0, len(t), 300): s.add(t[k:k + 300], ref[k:k + 300], ang[k:k + 300], ref[k:k + 300], ang[k:k + 300])
>>> r = s.finish()
>>> round(r.metrics.lag_ms), r.metrics.samples, r.strides.angles_deg.shape
(10, 1000, (1, 101))
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from host_tools.metrics import StrideSet, TrackingMetrics

__all__ = ["PlotSeries", "TrackingResult", "TrackingStream"]

_BLOCK = 4096  # samples per block of the lag sums (4096 x 201 shifts x 8 bytes = 6.6 MB)


@dataclass(frozen=True)
class PlotSeries:
    """Time series for the plot: every sample, or each group's minimum and maximum (``group`` samples)."""

    t_s: np.ndarray
    current_cmd_a: np.ndarray
    current_meas_a: np.ndarray
    error_deg: np.ndarray
    group: int


@dataclass(frozen=True)
class TrackingResult:
    """What a report needs from the probe: the metrics, the strides on the % gait grid, the plot series."""

    metrics: TrackingMetrics
    strides: StrideSet
    plot: PlotSeries


class TrackingStream:
    """Accumulates the tracking figures of a run from chunks of probe samples (see the module docstring)."""

    def __init__(self, *, stride_s: float, strides: int, dt_s: float, max_lag_s: float = 0.2,
                 expected_samples: int = 0, plot_points: int = 20_000, points: int = 101) -> None:
        """Strides of stride_s from the start (set_start), samples every dt_s; plot_points bounds the plot."""
        self.stride_s, self.strides, self.dt_s = stride_s, strides, dt_s
        self.n_lag = int(max_lag_s / dt_s)
        self.start_s: float | None = None
        self._received = 0  # samples added so far
        self._done = 0  # samples whose lag terms are summed (all of the reference they need is known)
        self._first = 0  # global index of the first held sample
        self._t = self._ref = self._ang = np.empty(0)
        n = 2 * self.n_lag + 1
        self._cost_sum, self._cost_n = np.zeros(n), np.zeros(n, dtype=np.int64)
        self._sq_sum, self._count, self._max = 0.0, 0, 0.0
        self.percent = np.linspace(0.0, 100.0, points)
        self._stride_angles: list[np.ndarray] = []
        self._stride_refs: list[np.ndarray] = []
        self._group = max(1, math.ceil(expected_samples / plot_points))
        self._plot: list[list[np.ndarray]] = [[], [], [], []]
        self._pending: list[np.ndarray] = [np.empty(0)] * 4  # plot samples of a group not yet complete

    def set_start(self, start_s: float | None) -> None:
        """The gait's start (None while unknown: the firmware sets it ahead of time, so no sample is lost)."""
        if start_s is not None:
            self.start_s = float(start_s)

    # -------------------------------------------------------------------- feeding
    def add(self, t_s: np.ndarray, reference_rad: np.ndarray, angle_rad: np.ndarray, current_cmd_a: np.ndarray,
            current_meas_a: np.ndarray) -> None:
        """Add the next samples (in time order)."""
        t_s, ref, ang = (np.asarray(a, dtype=float) for a in (t_s, reference_rad, angle_rad))
        if not len(t_s):
            return
        self._t = np.concatenate((self._t, t_s))
        self._ref = np.concatenate((self._ref, ref))
        self._ang = np.concatenate((self._ang, ang))
        self._received += len(t_s)
        err = np.degrees(ang - ref)
        self._add_plot([t_s, np.asarray(current_cmd_a, dtype=float), np.asarray(current_meas_a, dtype=float), err])
        self._process(final=False)

    def finish(self) -> TrackingResult:
        """Sum what is held back and return the result."""
        self._process(final=True)
        self._flush_plot()
        nan = float("nan")
        if self._count:
            costs = {k: self._cost_sum[i] / self._cost_n[i] if self._cost_n[i] else np.inf
                     for i, k in enumerate(range(-self.n_lag, self.n_lag + 1))}
            best = min(costs, key=costs.__getitem__)
            lag = float(best)
            c_m, c_0, c_p = costs.get(best - 1), costs[best], costs.get(best + 1)
            if c_m is not None and c_p is not None and np.isfinite(c_m + c_p) and c_m + c_p - 2 * c_0 > 0:
                lag += 0.5 * (c_m - c_p) / (c_m + c_p - 2 * c_0)  # parabola through the three: sub-sample lag
            metrics = TrackingMetrics(float(np.sqrt(self._sq_sum / self._count)), float(self._max),
                                      float(lag * self.dt_s * 1e3), self._count)
        else:
            metrics = TrackingMetrics(nan, nan, nan, 0)
        shape = (0, len(self.percent))
        strides = StrideSet(self.percent,
                            np.array(self._stride_angles) if self._stride_angles else np.empty(shape),
                            np.array(self._stride_refs) if self._stride_refs else np.empty(shape))
        plot = PlotSeries(*(np.concatenate(p) if p else np.empty(0) for p in self._plot), group=self._group)
        return TrackingResult(metrics, strides, plot)

    # -------------------------------------------------------------------- internals
    def _window(self) -> tuple[float, float]:
        if self.start_s is None:  # not started yet: every sample so far lies before the window
            return math.inf, math.inf
        return self.start_s, self.start_s + self.stride_s * self.strides

    def _process(self, final: bool) -> None:
        """Sum the lag terms of the samples whose shifted references are all known; cut complete strides."""
        n_lag, first = self.n_lag, self._first
        stop = self._received if final else max(self._done, self._received - n_lag)
        lo, hi = self._window()
        t, ref, ang = self._t, self._ref, self._ang
        idx = np.arange(self._done, stop)  # global indices
        loc = idx - first
        sel = (t[loc] >= lo) & (t[loc] < hi)
        idx, loc = idx[sel], loc[sel]
        if len(idx):
            err = np.degrees(ang[loc] - ref[loc])
            self._sq_sum += float(np.sum(err**2))
            self._count += len(idx)
            self._max = max(self._max, float(np.max(np.abs(err))))
            inner = (idx - n_lag >= 0) & (idx + n_lag < self._received)  # every shift's reference is known
            for b in range(0, int(inner.sum()), _BLOCK):  # in blocks: a (samples x shifts) matrix stays small
                self._sum_all_shifts(loc[inner][b:b + _BLOCK])
            edge, edge_idx = loc[~inner], idx[~inner]  # the run's first and last n_lag samples
            for i, k in enumerate(range(-n_lag, n_lag + 1) if len(edge) else ()):
                ok = (edge_idx - k >= 0) & (edge_idx - k < self._received)
                if ok.any():
                    d = ang[edge[ok]] - ref[edge[ok] - k]
                    self._cost_sum[i] += float(np.sum(d * d))
                    self._cost_n[i] += int(ok.sum())
        self._done = stop
        self._cut_strides(final)
        keep = self._done - n_lag  # the lag needs n_lag samples before the next one to sum
        if self.start_s is not None and len(self._stride_angles) < self.strides:  # and the stride being cut
            t0 = self.start_s + len(self._stride_angles) * self.stride_s
            keep = min(keep, first + max(0, int(np.searchsorted(t, t0, side="right")) - 1))
        keep = max(first, keep)
        if keep > first:
            cut = keep - first
            self._t, self._ref, self._ang = t[cut:], ref[cut:], ang[cut:]
            self._first = keep

    def _sum_all_shifts(self, loc: np.ndarray) -> None:
        """Add (angle(t) - reference(t - k dt))^2 for every shift k to the costs, for held samples loc."""
        n = self.n_lag
        windows = np.lib.stride_tricks.sliding_window_view(self._ref, 2 * n + 1)  # windows[w] = ref[w : w + 2n + 1]
        shifted = windows[loc - n][:, ::-1]  # column i: ref[l - k] for k = i - n
        d = self._ang[loc][:, None] - shifted
        self._cost_sum += np.einsum("ij,ij->j", d, d)
        self._cost_n += len(loc)

    def _cut_strides(self, final: bool) -> None:
        t = self._t
        if self.start_s is None or not len(t):
            return
        while len(self._stride_angles) < self.strides:
            t0 = self.start_s + len(self._stride_angles) * self.stride_s
            if t0 + self.stride_s > t[-1]:  # not complete (yet)
                break
            tt = t0 + self.percent / 100.0 * self.stride_s
            self._stride_angles.append(np.degrees(np.interp(tt, t, self._ang)))
            self._stride_refs.append(np.degrees(np.interp(tt, t, self._ref)))

    def _add_plot(self, series: list[np.ndarray]) -> None:
        if self._group == 1:
            for store, s in zip(self._plot, series, strict=True):
                store.append(s)
            return
        series = [np.concatenate((p, s)) for p, s in zip(self._pending, series, strict=True)]
        whole = len(series[0]) // self._group * self._group
        self._pending = [s[whole:] for s in series]
        if whole:
            self._add_groups([s[:whole] for s in series])

    def _add_groups(self, series: list[np.ndarray]) -> None:
        """Each group of samples as two points: (first t, minimum) and (last t, maximum) of every series."""
        g = self._group
        t = series[0].reshape(-1, g)
        out_t = np.column_stack((t[:, 0], t[:, -1])).ravel()
        self._plot[0].append(out_t)
        for store, s in zip(self._plot[1:], series[1:], strict=True):
            v = s.reshape(-1, g)
            store.append(np.column_stack((v.min(axis=1), v.max(axis=1))).ravel())

    def _flush_plot(self) -> None:
        if self._group > 1 and len(self._pending[0]):
            rest, self._pending = self._pending, [np.empty(0)] * 4
            n = len(rest[0])
            t = np.array([rest[0][0], rest[0][-1]])
            self._plot[0].append(t)
            for store, s in zip(self._plot[1:], rest[1:], strict=True):
                store.append(np.array([s.min(), s.max()]) if n else np.empty(0))

"""Tracking figures of several angle signals, per-stride curves and a bounded plot series, from chunks of samples.

A long run's samples never sit in memory together: :class:`TrackingStream` keeps, for each signal (the IMU
pitch, the encoder angle, the fused estimate, the probe's true angle), running sums for the RMS, maximum
and lag of :func:`host_tools.reports.metrics.signal_figures` (the lag's cost for each shift is summed chunk by chunk,
holding back the last ``max_lag_s`` of samples until the reference after them is known). Only samples of
the run window count: the whole strides from the gait's start with the supervisor in RUN
(:func:`host_tools.reports.metrics.run_window`), and for each signal only its finite samples (an IMU before its
first frame is NaN). It cuts each whole stride of the chosen signals on the % gait grid as soon as it is
complete, and keeps at most about ``plot_points`` samples of the time series for the plot (beyond that,
the minimum and maximum of each group of samples). Fed everything in one chunk it gives the figures of
those functions (to rounding); fed in chunks, the same figures whatever the chunking.

>>> t = np.arange(0, 2, 0.001); ref = np.sin(2 * np.pi * t); ang = np.sin(2 * np.pi * (t - 0.01))
>>> s = TrackingStream(("a",), stride_s=1.0, strides=1, dt_s=0.001)
>>> s.set_start(0.5)
>>> run = np.ones(len(t), dtype=bool)
>>> for k in range(0, len(t), 300): s.add(t[k:k + 300], ref[k:k + 300], {"a": ang[k:k + 300]}, run[k:k + 300],
...                                        ref[k:k + 300], ang[k:k + 300])
>>> r = s.finish()
>>> round(r.metrics["a"].lag_ms), r.metrics["a"].samples, r.strides["a"].angles_deg.shape, r.enough
(10, 1000, (1, 101), True)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from host_tools.reports.metrics import MIN_RUN_STRIDES, StrideSet, TrackingMetrics

__all__ = ["PLOT_STRIDES", "TRACKING_SIGNALS", "PlotSeries", "TrackingResult", "TrackingStream", "feed_probe",
           "probe_stream"]

#: The bench probe's tracking signals in the order they are shown: what a bench measures first, the truth
#: last. (name, probe field, description)
TRACKING_SIGNALS: tuple[tuple[str, str, str], ...] = (
    ("imu", "imu_pitch_rad", "IMU pitch as the firmware received it (the report's Figs 4.8-4.10)"),
    ("encoder", "encoder_angle_rad", "angle from the encoder count (zero at power-up)"),
    ("fused", "fused_angle_rad", "the firmware's fused estimate (encoder + IMU), what it controls"),
    ("truth", "true_angle_rad", "the plant's true output angle: emulation only, no bench has it"),
)
#: Whose strides tracking.png draws: what the report plotted (the IMU), the encoder (the bench-measurable
#: stand-in for the foot) and the truth (emulation only).
PLOT_STRIDES = ("imu", "encoder", "truth")
#: Value of SupervisorState.RUN as the probe records it (protocol.telemetry).
_RUN_STATE = 1

_BLOCK = 4096  # samples per block of the lag sums (4096 x 201 shifts x 8 bytes = 6.6 MB)


@dataclass(frozen=True)
class PlotSeries:
    """Time series for the plot: every sample, or each group's minimum and maximum (``group`` samples).

    ``errors_deg[name]`` is reference minus that signal, NaN outside RUN.
    """

    t_s: np.ndarray
    current_cmd_a: np.ndarray
    current_meas_a: np.ndarray
    errors_deg: dict[str, np.ndarray]
    group: int


@dataclass(frozen=True)
class TrackingResult:
    """What a report needs from the probe: figures per signal, the time they cover, strides, the plot series."""

    metrics: dict[str, TrackingMetrics]
    time_in_run_s: float
    min_run_s: float
    enough: bool
    strides: dict[str, StrideSet]
    plot: PlotSeries


class _Sums:
    """One signal's running sums: squared error, count, maximum, and the lag cost of every shift."""

    def __init__(self, shifts: int) -> None:
        self.sq_sum, self.count, self.max = 0.0, 0, 0.0
        self.cost_sum, self.cost_n = np.zeros(shifts), np.zeros(shifts, dtype=np.int64)

    def metrics(self, n_lag: int, dt_s: float) -> TrackingMetrics:
        """The figures of what was summed (NaN when nothing was)."""
        if not self.count:
            nan = float("nan")
            return TrackingMetrics(nan, nan, nan, 0)
        costs = {k: self.cost_sum[i] / self.cost_n[i] if self.cost_n[i] else np.inf
                 for i, k in enumerate(range(-n_lag, n_lag + 1))}
        best = min(costs, key=costs.__getitem__)
        lag = float(best)
        c_m, c_0, c_p = costs.get(best - 1), costs[best], costs.get(best + 1)
        if c_m is not None and c_p is not None and np.isfinite(c_m + c_p) and c_m + c_p - 2 * c_0 > 0:
            lag += 0.5 * (c_m - c_p) / (c_m + c_p - 2 * c_0)  # parabola through the three: sub-sample lag
        return TrackingMetrics(float(np.sqrt(self.sq_sum / self.count)), float(self.max), float(lag * dt_s * 1e3),
                               self.count)


class TrackingStream:
    """Accumulates the tracking figures of a run from chunks of probe samples (see the module docstring)."""

    def __init__(self, signals: tuple[str, ...], *, stride_s: float, strides: int, dt_s: float,
                 max_lag_s: float = 0.2, expected_samples: int = 0, plot_points: int = 20_000, points: int = 101,
                 stride_signals: tuple[str, ...] | None = None) -> None:
        """Figures of each named signal over strides of stride_s from the start (set_start), samples every dt_s.

        stride_signals: the signals whose strides are cut for the plot (default: all); plot_points bounds
        the plot series.
        """
        self.signals = signals
        self.stride_signals = signals if stride_signals is None else stride_signals
        self.stride_s, self.strides, self.dt_s = stride_s, strides, dt_s
        self.n_lag = int(max_lag_s / dt_s)
        self.start_s: float | None = None
        self._received = 0  # samples added so far
        self._done = 0  # samples whose lag terms are summed (all of the reference they need is known)
        self._first = 0  # global index of the first held sample
        self._t = self._ref = np.empty(0)
        self._run = np.empty(0, dtype=bool)
        self._ang = {name: np.empty(0) for name in signals}
        self._sums = {name: _Sums(2 * self.n_lag + 1) for name in signals}
        self._in_run = 0  # samples of the window with the supervisor in RUN
        self.percent = np.linspace(0.0, 100.0, points)
        self._stride_angles: dict[str, list[np.ndarray]] = {name: [] for name in self.stride_signals}
        self._stride_refs: list[np.ndarray] = []
        self._group = max(1, math.ceil(expected_samples / plot_points))
        n_series = 3 + len(signals)  # t, two currents, one error per signal
        self._plot: list[list[np.ndarray]] = [[] for _ in range(n_series)]
        self._pending: list[np.ndarray] = [np.empty(0)] * n_series  # plot samples of a group not yet complete

    def set_start(self, start_s: float | None) -> None:
        """The gait's start (None while unknown: the firmware sets it ahead of time, so no sample is lost)."""
        if start_s is not None:
            self.start_s = float(start_s)

    # -------------------------------------------------------------------- feeding
    def add(self, t_s: np.ndarray, reference_rad: np.ndarray, angles_rad: Mapping[str, np.ndarray],
            run: np.ndarray, current_cmd_a: np.ndarray, current_meas_a: np.ndarray) -> None:
        """Add the next samples (in time order); `run` is True where the supervisor was in RUN."""
        t_s, ref = np.asarray(t_s, dtype=float), np.asarray(reference_rad, dtype=float)
        if not len(t_s):
            return
        run = np.asarray(run, dtype=bool)
        angles = {name: np.asarray(angles_rad[name], dtype=float) for name in self.signals}
        self._t = np.concatenate((self._t, t_s))
        self._ref = np.concatenate((self._ref, ref))
        self._run = np.concatenate((self._run, run))
        for name, a in angles.items():
            self._ang[name] = np.concatenate((self._ang[name], a))
        self._received += len(t_s)
        errors = [np.where(run, np.degrees(ref - a), np.nan) for a in angles.values()]
        self._add_plot([t_s, np.asarray(current_cmd_a, dtype=float), np.asarray(current_meas_a, dtype=float),
                        *errors])
        self._process(final=False)

    def finish(self) -> TrackingResult:
        """Sum what is held back and return the result."""
        self._process(final=True)
        self._flush_plot()
        time_in_run = round(self._in_run * self.dt_s, 9)
        min_run = MIN_RUN_STRIDES * self.stride_s
        enough = time_in_run > 0.0 and time_in_run >= min_run - 1.5 * self.dt_s  # as metrics.RunWindow.enough
        metrics = {name: sums.metrics(self.n_lag, self.dt_s) for name, sums in self._sums.items()}
        shape = (0, len(self.percent))
        refs = np.array(self._stride_refs) if self._stride_refs else np.empty(shape)
        strides = {name: StrideSet(self.percent, np.array(a) if a else np.empty(shape), refs)
                   for name, a in self._stride_angles.items()}
        series = [np.concatenate(p) if p else np.empty(0) for p in self._plot]
        plot = PlotSeries(series[0], series[1], series[2], dict(zip(self.signals, series[3:], strict=True)),
                          group=self._group)
        return TrackingResult(metrics, time_in_run, min_run, enough, strides, plot)

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
        t, ref = self._t, self._ref
        idx_all = np.arange(self._done, stop)  # global indices
        loc_all = idx_all - first
        window = (t[loc_all] >= lo) & (t[loc_all] < hi) & self._run[loc_all]
        self._in_run += int(window.sum())
        for name, sums in self._sums.items():
            ang = self._ang[name]
            sel = window & np.isfinite(ang[loc_all])
            idx, loc = idx_all[sel], loc_all[sel]
            if not len(idx):
                continue
            err = np.degrees(ang[loc] - ref[loc])
            sums.sq_sum += float(np.sum(err**2))
            sums.count += len(idx)
            sums.max = max(sums.max, float(np.max(np.abs(err))))
            inner = (idx - n_lag >= 0) & (idx + n_lag < self._received)  # every shift's reference is known
            for b in range(0, int(inner.sum()), _BLOCK):  # in blocks: a (samples x shifts) matrix stays small
                self._sum_all_shifts(sums, ang, loc[inner][b:b + _BLOCK])
            edge_idx, edge = idx[~inner], loc[~inner]  # the run's first and last n_lag samples
            for i, k in enumerate(range(-n_lag, n_lag + 1) if len(edge) else ()):
                ok = (edge_idx - k >= 0) & (edge_idx - k < self._received)
                if ok.any():
                    d = ang[edge[ok]] - ref[edge[ok] - k]
                    sums.cost_sum[i] += float(np.sum(d * d))
                    sums.cost_n[i] += int(ok.sum())
        self._done = stop
        self._cut_strides()
        keep = self._done - n_lag  # the lag needs n_lag samples before the next one to sum
        if self.start_s is not None and len(self._stride_refs) < self.strides:  # and the stride being cut
            t0 = self.start_s + len(self._stride_refs) * self.stride_s
            keep = min(keep, first + max(0, int(np.searchsorted(t, t0, side="right")) - 1))
        keep = max(first, keep)
        if keep > first:
            cut = keep - first
            self._t, self._ref, self._run = t[cut:], ref[cut:], self._run[cut:]
            self._ang = {name: a[cut:] for name, a in self._ang.items()}
            self._first = keep

    def _sum_all_shifts(self, sums: _Sums, ang: np.ndarray, loc: np.ndarray) -> None:
        """Add (angle(t) - reference(t - k dt))^2 for every shift k to the costs, for held samples loc."""
        n = self.n_lag
        windows = np.lib.stride_tricks.sliding_window_view(self._ref, 2 * n + 1)  # windows[w] = ref[w : w + 2n + 1]
        shifted = windows[loc - n][:, ::-1]  # column i: ref[l - k] for k = i - n
        d = ang[loc][:, None] - shifted
        sums.cost_sum += np.einsum("ij,ij->j", d, d)
        sums.cost_n += len(loc)

    def _cut_strides(self) -> None:
        t = self._t
        if self.start_s is None or not len(t):
            return
        while len(self._stride_refs) < self.strides:
            t0 = self.start_s + len(self._stride_refs) * self.stride_s
            if t0 + self.stride_s > t[-1]:  # not complete (yet)
                break
            tt = t0 + self.percent / 100.0 * self.stride_s
            for name, store in self._stride_angles.items():
                store.append(np.degrees(np.interp(tt, t, np.nan_to_num(self._ang[name]))))
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
        self._plot[0].append(np.column_stack((t[:, 0], t[:, -1])).ravel())
        for store, s in zip(self._plot[1:], series[1:], strict=True):
            v = s.reshape(-1, g)  # fmin/fmax skip NaN (outside RUN) and give NaN only for an all-NaN group
            store.append(np.column_stack((np.fmin.reduce(v, axis=1), np.fmax.reduce(v, axis=1))).ravel())

    def _flush_plot(self) -> None:
        if self._group > 1 and len(self._pending[0]):
            rest, self._pending = self._pending, [np.empty(0)] * len(self._pending)
            self._plot[0].append(np.array([rest[0][0], rest[0][-1]]))
            for store, s in zip(self._plot[1:], rest[1:], strict=True):
                store.append(np.array([np.fmin.reduce(s), np.fmax.reduce(s)]))


def probe_stream(*, stride_s: float, strides: int, dt_s: float, expected_samples: int = 0) -> TrackingStream:
    """A stream of the bench probe's TRACKING_SIGNALS, cutting the PLOT_STRIDES signals' strides."""
    return TrackingStream(tuple(name for name, _, _ in TRACKING_SIGNALS), stride_s=stride_s, strides=strides,
                          dt_s=dt_s, expected_samples=expected_samples, stride_signals=PLOT_STRIDES)


def feed_probe(stream: TrackingStream, samples: Mapping[str, np.ndarray]) -> None:
    """Add a chunk of the probe's samples (arrays by Probe field name) to a probe_stream."""
    stream.add(samples["t_s"], samples["reference_rad"], {name: samples[key] for name, key, _ in TRACKING_SIGNALS},
               np.asarray(samples["supervisor_state"]) == _RUN_STATE, samples["current_cmd_a"],
               samples["current_meas_a"])

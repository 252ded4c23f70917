"""Plots of a run (matplotlib, Agg backend: works without a display)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from host_tools.outdir import save_figure  # noqa: E402
from host_tools.reports.metrics import StrideSet  # noqa: E402

__all__ = ["plot_per_stride", "plot_tracking"]

MARGINS_IN = {"left": 0.8, "right": 0.15, "top": 0.35, "bottom": 0.5}
"""The figures' margins in inches, set once: matplotlib's constrained layout measured every tick label again on each
figure: drawing a 2-stride run's two figures took 1.11 s of CPU with it, 0.69 s with these (best of 8 each)."""


def _framed(fig: plt.Figure, gap_in: float = 0.7) -> None:
    """Place the figure's axes inside :data:`MARGINS_IN`, ``gap_in`` inches apart (room for an x label)."""
    w, h = fig.get_size_inches()
    m = MARGINS_IN
    rows = len(fig.axes)
    axes_h = (h - m["top"] - m["bottom"] - gap_in * (rows - 1)) / rows
    fig.subplots_adjust(left=m["left"] / w, right=1 - m["right"] / w, top=1 - m["top"] / h, bottom=m["bottom"] / h,
                        hspace=gap_in / axes_h)


def plot_tracking(path: Path, strides: dict[str, StrideSet], band: tuple[np.ndarray, np.ndarray, np.ndarray],
                  t_s: np.ndarray, current_cmd_a: np.ndarray, current_meas_a: np.ndarray,
                  errors_deg: dict[str, np.ndarray], title: str) -> None:
    """Angle vs % gait (each stride and their mean per signal, the normative mean +- 1 SD); current and the
    tracking errors (reference minus each signal, NaN outside RUN) vs time.

    The time series of a long run come as each group's minimum and maximum (host_tools/reports/tracking_stream.py):
    a line zigzagging over the whole height, which Agg rasterises with a cell per pixel crossed unless the
    path is drawn in chunks (1000 vertices: 40,000 points took 140 MB and 2.8 s in one piece, 16 MB and 0.7 s).
    """
    with matplotlib.rc_context({"agg.path.chunksize": 1000}):
        _plot_tracking(path, strides, band, t_s, current_cmd_a, current_meas_a, errors_deg, title)


def _plot_tracking(path: Path, strides: dict[str, StrideSet], band: tuple[np.ndarray, np.ndarray, np.ndarray],
                   t_s: np.ndarray, current_cmd_a: np.ndarray, current_meas_a: np.ndarray,
                   errors_deg: dict[str, np.ndarray], title: str) -> None:
    fig, (ax1, ax2, ax4) = plt.subplots(3, 1, figsize=(9, 11))
    _framed(fig)
    pct, mean, sd = band
    ax1.fill_between(pct, mean - sd, mean + sd, color="0.85", label="normative mean ± 1 SD")
    ax1.plot(pct, mean, color="0.4", lw=1.2, ls="--", label="normative mean")
    colours = ("tab:blue", "tab:orange", "tab:purple", "tab:green")
    reference_drawn = False
    for (label, st), colour in zip(strides.items(), colours, strict=False):
        if not len(st.angles_deg):
            continue
        # one collection, not one line per stride: 1000 strides draw as fast as 10
        lines = [np.column_stack((st.percent, a)) for a in st.angles_deg]
        ax1.add_collection(LineCollection(lines, colors=colour, linewidths=0.5, alpha=0.4,
                                          label=f"{label}: each stride"))
        ax1.plot(st.percent, st.angles_deg.mean(axis=0), color=colour, lw=2.0, label=f"{label}: mean of strides")
        if not reference_drawn:
            ax1.plot(st.percent, st.reference_deg[0], color="tab:red", lw=1.2, label="reference")
            reference_drawn = True
    ax1.set(xlabel="gait cycle (%)", ylabel="ankle angle (deg, dorsiflexion +)", title=title, xlim=(0, 100))
    ax1.grid(alpha=0.3)
    ax1.legend(loc="lower left", fontsize=7)
    ax2.plot(t_s, current_cmd_a, lw=0.8, label="commanded current (A)")
    ax2.plot(t_s, current_meas_a, lw=0.8, label="measured current (A)")
    ax2.set(xlabel="time (s)", ylabel="motor current (A)")
    ax2.grid(alpha=0.3)
    ax2.legend(loc="upper right", fontsize=8)
    for (label, err), colour in zip(errors_deg.items(), (*colours, "k"), strict=False):
        ax4.plot(t_s, err, lw=0.7, color=colour, label=f"reference − {label}")
    ax4.set(xlabel="time (s)", ylabel="tracking error (deg), supervisor in RUN")
    ax4.grid(alpha=0.3)
    ax4.legend(loc="upper right", fontsize=8)
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def plot_per_stride(path: Path, upper: dict[str, list], upper_label: str, lower: dict[str, list], lower_label: str,
                    title: str) -> None:
    """Series with one value per stride (None: not known) against the stride number; a second panel if lower."""
    fig, axes = plt.subplots(2 if lower else 1, 1, figsize=(9, 7 if lower else 4.5), squeeze=False)
    _framed(fig)
    for ax, panel, label in zip(axes[:, 0], (upper, lower), (upper_label, lower_label), strict=False):
        for name, values in panel.items():
            y = np.array([np.nan if v is None else v for v in values], dtype=float)
            ax.plot(np.arange(1, len(y) + 1), y, lw=1.2, label=name)
        ax.set_ylabel(label)
        ax.set_xlabel("stride")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    axes[0, 0].set_title(title)
    save_figure(fig, path)
    plt.close(fig)

"""The run's figures (host_tools/reports/plots.py) keep every label, tick label and legend inside the image with their
fixed margins, also with values as wide as a run gives (tens of amps, hundreds of degrees of error, many strides)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from host_tools.reports import plots
from host_tools.reports.metrics import StrideSet


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> list:
    """The figures the plot functions draw, kept open (and drawn) for the test to measure."""
    figures: list = []

    def keep(fig, path, **savefig) -> None:
        fig.canvas.draw()
        figures.append(fig)

    monkeypatch.setattr(plots, "save_figure", keep)
    monkeypatch.setattr(plots.plt, "close", lambda fig: None)
    yield figures
    for fig in figures:
        plt.close(fig)


def _inside(fig) -> None:
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    for ax in fig.axes:
        tight = ax.get_tightbbox(renderer)
        assert tight.x0 >= box.x0 - 1 and tight.y0 >= box.y0 - 1, (ax.get_ylabel(), tight, box)
        assert tight.x1 <= box.x1 + 1 and tight.y1 <= box.y1 + 1, (ax.get_ylabel(), tight, box)
    for upper, lower in zip(fig.axes, fig.axes[1:], strict=False):  # an x label does not run into the next title
        assert upper.get_tightbbox(renderer).y0 > lower.get_tightbbox(renderer).y1


def test_the_tracking_figure_keeps_its_labels_inside(drawn: list) -> None:
    pct = np.linspace(0, 100, 101)
    angles = 150.0 * np.sin(np.linspace(0, 2 * np.pi, 101))[None, :].repeat(3, axis=0)
    st = StrideSet(percent=pct, angles_deg=angles, reference_deg=angles)
    t = np.linspace(0, 300, 3000)
    plots.plot_tracking(Path("unused.png"), {"imu": st, "encoder": st}, (pct, pct - 50, np.full(101, 10.0)), t,
                        -25.0 * np.sin(t), 25.0 * np.sin(t), {"imu": -123.4 * np.sin(t)}, "a title " * 8)
    _inside(drawn[0])


@pytest.mark.parametrize("lower", [{}, {"bus": [48.123, None, -12.5]}])
def test_the_per_stride_figure_keeps_its_labels_inside(drawn: list, lower: dict) -> None:
    plots.plot_per_stride(Path("unused.png"), {"winding (emulation only)": [25.0, 1234.5, None]}, "temperature (°C)",
                          lower, "bus voltage (V)", "Winding temperature")
    _inside(drawn[0])

"""`pafp fit`'s plots and `--validate` use what the fit uses: a stall's windows (`Experiment.stalled`) left out.

A synthetic recording (commands every millisecond, samples between them) whose writes' arrival windows are wide in
three simulation windows (a stall) and whose measurements there are spoiled: the validation's fit percentages must be
those of the recording built without those windows, the stall counted; fit.png's panels leave the stall out and shade
it, labelled with the samples left out.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from hal.virtual.plant import load_plant_params
from host_tools.calibration.fit_data import COMMAND_DELAY_S, STALL_BOUND_S, WINDOW_S, Experiment
from host_tools.calibration.fit_model import base_values, fit_percentages, simulate
from host_tools.calibration.fit_report import fit_figure, validate, write_fit_outputs
from host_tools.calibration.plant_fit import FitResult
from profiles import profile_path

T0 = 0.0005  # the first sample (the windows are cut from it)
DURATION_S = 4.5  # the held-out stretch (the fourth second) is in it
STALLED_WINDOWS = (4, 5, 13)  # two in a fitting stretch ([1, 1.5) s), one in the held-out one ([3.25, 3.5) s)


def _recording(keep: np.ndarray | None = None, spoil: bool = True) -> Experiment:
    """The synthetic recording (with only the samples `keep` marks, when given). Its measurements are the base
    plant's own response to the commands (simulated in one window from rest), spoiled in the stall's windows (when
    `spoil`) by noise of 10 deg and 2 A (seeded)."""
    t_cmd = np.arange(0.0, DURATION_S, 1e-3)
    i_cmd = 2.0 * np.sin(2 * np.pi * 0.7 * t_cmd)
    t = T0 + np.arange(0.0, DURATION_S - T0, 1e-3)
    window = ((t - T0) // WINDOW_S).astype(int)
    t_req = t_cmd + COMMAND_DELAY_S
    req_of = np.searchsorted(t_req, t - 1e-3, side="right") - 1  # the reply read a period after its request
    # each write's arrival window: 0.5 ms, and 4 ms (well over the stall's bound) for the stalled windows' writes
    cmd_window = ((t_cmd - T0) // WINDOW_S).astype(int)
    width = np.where(np.isin(cmd_window, STALLED_WINDOWS), 4e-3, 5e-4)
    bounds = np.column_stack([-0.5 * width, 0.5 * width])
    zeros = np.zeros(len(t))
    rest = Experiment(t_cmd, i_cmd, t, zeros, zeros, zeros, "synthetic", zeros, t_req, req_of, bounds=bounds,
                      req_cmd=np.arange(len(t_cmd)))
    base = load_plant_params()
    angle, current, _, _ = simulate(base, base_values(base), rest, window_s=2 * DURATION_S)
    vel = np.gradient(angle, t)
    if spoil:
        rng = np.random.default_rng(5)
        stall = np.isin(window, STALLED_WINDOWS)
        angle = angle + stall * np.radians(10.0) * rng.standard_normal(len(t))
        current = current + stall * 2.0 * rng.standard_normal(len(t))
    k = np.ones(len(t), dtype=bool) if keep is None else keep
    return replace(rest, t=t[k], angle=angle[k], imu=angle[k].copy(), current=current[k], vel=vel[k],
                   req_of=req_of[k])


def _stall_mask() -> np.ndarray:
    t = _recording().t
    return np.isin(((t - T0) // WINDOW_S).astype(int), STALLED_WINDOWS)


@pytest.fixture(scope="module")
def plant():
    base = load_plant_params()
    v = base_values(base)
    names = tuple(v)
    pct = {part: {"angle": 90.0, "current": 80.0, "imu": 70.0} for part in ("fit", "held_out")}
    r = FitResult(names, v, v, dict.fromkeys(names, 0.0), dict.fromkeys(names, 1.0), dict.fromkeys(names, True),
                  np.eye(len(names)), pct, 0, 0.0, 0.0, (0.0, DURATION_S), "synthetic", {})
    return base, r


def test_the_synthetic_stall_is_one():
    """The recording's stall is what `Experiment.stalled` finds: the three windows, nothing else."""
    exp = _recording()
    assert np.array_equal(exp.stalled(), _stall_mask())
    assert exp.stalled(bound_s=5e-3).sum() == 0  # over every window's width: no stall
    assert 5e-4 < STALL_BOUND_S < 4e-3


def test_validation_leaves_the_stall_out_and_counts_it(plant):
    base, r = plant
    exp = _recording()
    stall = _stall_mask()
    v = validate(base, r, exp)
    expected, unheard = fit_percentages(base, r.values, _recording(keep=~stall))
    assert v["stalled_samples_left_out"] == int(stall.sum()) == 750
    assert v["samples"] == len(exp.t) - 750
    assert v["current_samples_without_simulation"] == unheard
    for signal, value in expected.items():
        assert v["fit_percent"][signal] == pytest.approx(value, abs=1e-8), signal
    # the spoiled stall would have shown: with it, the angle's and the current's percentages fall far
    whole, _ = fit_percentages(base, r.values, exp)
    assert whole["angle"] < expected["angle"] - 10 and whole["current"] < expected["current"] - 10, (whole, expected)


def test_validation_of_a_recording_stalled_throughout_has_no_percentages(plant):
    base, r = plant
    exp = _recording()
    stalled = replace(exp, bounds=np.column_stack([np.zeros(len(exp.t_cmd)), np.full(len(exp.t_cmd), 4e-3)]))
    v = validate(base, r, stalled)
    assert v["samples"] == 0 and v["stalled_samples_left_out"] == len(exp.t)
    assert v["fit_percent"] == {"angle": None, "current": None, "imu": None}


def test_fit_md_and_json_count_the_validations_stall(plant, tmp_path):
    base, r = plant
    exp = _recording()
    v = validate(base, r, exp)
    base_text = profile_path("plant_ak60_6.toml").read_text(encoding="utf-8")
    s = write_fit_outputs(tmp_path, base, base_text, r, _recording(spoil=False), {"validation": v}, plot=False)
    assert json.loads((tmp_path / "fit.json").read_text())["validation"] == s["validation"] == v
    md = (tmp_path / "fit.md").read_text()
    assert f"On another recording, `synthetic` ({len(exp.t) - 750} samples used)" in md
    assert "750 samples in windows of a stall" in md


def test_the_plots_leave_the_stall_out_and_shade_it(plant):
    """fit.png: no measured or simulated point of a stall's window in either column; each column shades its part
    of the stall and says how many samples were left out."""
    import matplotlib.pyplot as plt

    base, r = plant
    exp = _recording()
    stall_t = exp.t[_stall_mask()]
    fig = fit_figure(base, r, exp)
    try:
        axes = np.array(fig.axes).reshape(3, 2)
        for col, (lo, hi, n) in enumerate(((1.0, 1.5, 500), (3.25, 3.5, 250))):
            inside = stall_t[(stall_t >= lo) & (stall_t < hi)]
            assert len(inside) == n
            for ax in axes[:, col]:
                xs = np.concatenate([line.get_xdata() for line in ax.get_lines()])
                assert len(xs) > 1000
                assert not np.any((xs >= lo) & (xs < hi)), (col, ax.get_ylabel())
                spans = [p for p in ax.patches if p.get_label() == f"stall: left out ({n} samples)"]
                assert len(spans) == 1, [p.get_label() for p in ax.patches]
                x0, x1 = spans[0].get_x(), spans[0].get_x() + spans[0].get_width()  # a Rectangle (matplotlib >= 3.9)
                assert x0 == pytest.approx(inside[0]) and x1 == pytest.approx(inside[-1])
                assert f"stall: left out ({n} samples)" in [t.get_text() for t in ax.get_legend().get_texts()]
    finally:
        plt.close(fig)

"""`pafp fit` on a recording a stall spoiled throughout: one line and exit 2 before any simulation, not a traceback."""

from __future__ import annotations

import numpy as np

from host_tools.calibration.fit_data import STALL_BOUND_S, Experiment
from host_tools.cli import main


def test_pafp_fit_refuses_a_run_stalled_throughout_in_one_line(tmp_path, monkeypatch, capsys):
    import host_tools.calibration.fit_data as fit_data
    import host_tools.calibration.plant_fit as plant_fit

    t = np.arange(4000) * 1e-3
    zeros = np.zeros_like(t)
    exp = Experiment(t, zeros, t, zeros, zeros, zeros, "runs/stalled", zeros, t, np.arange(4000) - 1,
                     bounds=np.column_stack([zeros, np.full(4000, 2 * STALL_BOUND_S)]), req_cmd=np.arange(4000))
    monkeypatch.setattr(fit_data, "load_experiment", lambda path: exp)

    def no_fit(*args, **kwargs):
        raise AssertionError("the fit ran")

    monkeypatch.setattr(plant_fit, "fit_plant", no_fit)
    assert main(["fit", str(tmp_path), "--no-plot", "--out", str(tmp_path / "fit")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "runs/stalled: the link stalled through too much of the run" in err[0], err
    assert not (tmp_path / "fit").exists()

"""pafp fit's memo of simulations (host_tools/calibration/fit_memo.py): within one fit a simulation or a window's plant
run asked for again is taken from it, and what it gives is the very simulation run afresh."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hal.virtual.plant import load_plant_params
from host_tools.calibration import fit_model
from host_tools.calibration.fit_data import Experiment
from host_tools.calibration.fit_memo import one_fit
from host_tools.calibration.fit_model import base_values, simulate


def _experiment() -> Experiment:
    """1 s at 1 kHz: 0.5 s of one current (its two windows never reverse), then a square wave (they do); a request at
    each sample, each sample carrying the previous one's."""
    t = np.arange(1000) * 1e-3
    i_cmd = np.where(t < 0.5, 0.4, np.where((t // 0.05) % 2 == 0, 1.5, -1.5))
    zeros = np.zeros_like(t)
    return Experiment(t, i_cmd, t, zeros, zeros, zeros, "hand-built", zeros, t, np.arange(len(t)) - 1)


def test_the_memo_gives_the_simulation_run_afresh(monkeypatch):
    """Within one fit: a repeat, a move of the IMU's lag or bias, of the backlash (where no command reverses the run
    is the same; where one does it is not), of the encoder offset, and another start of a window each give arrays
    equal bit for bit to the simulation outside a fit; the plant runs fewer windows than it would without the memo."""
    base = load_plant_params()
    exp = _experiment()
    shifted = np.zeros(len(exp.t))
    shifted[250] = 1e-3  # the second window starts a little higher
    v = base_values(base)
    asks = [(v, exp), (v, exp), ({**v, "imu_lag_s": 0.03}, exp), ({**v, "imu_bias_deg": 0.4}, exp),
            ({**v, "backlash_deg": 1.1}, exp), ({**v, "backlash_deg": 0.0}, exp),
            ({**v, "encoder_offset_deg": 0.3}, exp), (v, replace(exp, start_shift=shifted))]
    runs = []
    run_plant = fit_model.run_plant
    monkeypatch.setattr(fit_model, "run_plant", lambda *a: runs.append(a[3]) or run_plant(*a))  # a[3]: its start
    fresh = [simulate(base, w, e) for w, e in asks]
    without = len(runs)
    runs.clear()
    with one_fit():
        remembered = [simulate(base, w, e) for w, e in asks]
    for (w, _), a, b in zip(asks, fresh, remembered, strict=True):
        assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True)), w
    assert without == 4 * len(asks)
    # not run again: the repeat's, the IMU's lag's and bias's windows (four each), the backlash's windows without a
    # reversal (two each) and the other starts' unshifted windows (three)
    assert len(runs) == without - 3 * 4 - 2 * 2 - 3
    assert not np.array_equal(fresh[0][0], fresh[4][0])  # the backlash acts where the command reverses

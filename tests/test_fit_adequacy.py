"""The model-adequacy check's test (host_tools/calibration/fit_adequacy.py) on residuals made here, seeded: a residual
independent of a colored command passes although both are colored; one that carries a friction-like function of the
command fails, at the lags it carries it. Its verdict on `pafp fit`'s recordings: tests/test_plant_fit.py; its rates
over plants with and without unmodelled effects: tests/benchmarks/test_bench_fit_coverage.py."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from host_tools.calibration.fit_adequacy import LAGS, Z_BOUND, cross_test

DT = 0.002  # telemetry at 500 Hz, commands at 1 kHz, windows of 0.25 s


def _bench(seed: int = 4):  # type: ignore[no-untyped-def]
    """(command record, sample times, window of each sample, colored noise at the samples) of a 12 s run."""
    rng = np.random.default_rng(seed)
    t_cmd = np.arange(0.0, 12.0, 0.001)
    bits = np.repeat(rng.choice([-1.0, 1.0], len(t_cmd) // 30 + 1), 30)[: len(t_cmd)]  # a 30 ms PRBS
    i_cmd = np.convolve(bits, np.ones(8) / 8, mode="same")  # and smoothed: a colored command
    t = np.arange(0.01, 12.0, DT)
    noise = np.zeros(len(t))
    for k in range(1, len(t)):  # AR(1), pole 0.9: a colored residual
        noise[k] = 0.9 * noise[k - 1] + rng.normal()
    return SimpleNamespace(t_cmd=t_cmd, i_cmd=i_cmd), t, (t // 0.25).astype(int), noise


def test_a_residual_independent_of_a_colored_command_passes():
    """Both colored: the naive bound for white residuals (1.96 / sqrt(N)) is exceeded, the corrected one is not."""
    exp, t, win, noise = _bench()
    d = cross_test(noise, t, win, exp, DT)
    assert d["ok"] and d["max_abs_z"] <= Z_BOUND and not d["lags_ms_beyond"], d
    assert len(d["correlation"]) == LAGS
    white = 1.96 / math.sqrt(len(t))
    assert max(abs(c) for c in d["correlation"]) > white  # the white bound would have called it dependent
    assert min(d["bound95"]) > 2.0 * white


def test_a_residual_that_follows_the_command_fails_at_its_lags():
    """A friction-like error, 0.3 of the noise's size times the sign of the command 10 ms earlier: flagged, with the
    lags about 10 ms among those beyond the bound."""
    exp, t, win, noise = _bench()
    sign = np.sign(np.interp(t - 0.010, exp.t_cmd, exp.i_cmd))
    d = cross_test(noise + 0.3 * float(np.std(noise)) * sign, t, win, exp, DT)
    assert not d["ok"] and d["max_abs_z"] > Z_BOUND, d
    assert 10.0 in d["lags_ms_beyond"], d["lags_ms_beyond"]


def test_the_check_is_deterministic():
    exp, t, win, noise = _bench()
    assert cross_test(noise, t, win, exp, DT) == cross_test(noise.copy(), t, win, exp, DT)

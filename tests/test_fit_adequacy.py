"""The model-adequacy check's test (host_tools/calibration/fit_adequacy.py) on residuals made here, seeded: a residual
independent of a colored input passes although both are colored; one that carries a friction-like function of the
input fails, at the lags it carries it; in closed loop the command follows the measurement noise, the experiment's own
excitation does not. Its verdict on `pafp fit`'s recordings: tests/test_plant_fit.py; its rates over plants with and
without unmodelled effects: tests/benchmarks/test_bench_fit_coverage.py."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from host_tools.calibration.fit_adequacy import BEYOND_COUNT_LIMIT, LAGS, beyond_count, cross_test, inputs, z_bound

DT = 0.002  # telemetry at 500 Hz, commands at 1 kHz, windows of 0.25 s
BOUND = z_bound(6 * LAGS)


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
    d = cross_test(noise, t, win, (exp.t_cmd, exp.i_cmd), DT, BOUND)
    assert d["ok"] and d["max_abs_z"] <= BOUND and not d["lags_ms_beyond"], d
    assert len(d["correlation"]) == LAGS
    white = 1.96 / math.sqrt(len(t))
    assert max(abs(c) for c in d["correlation"]) > white  # the white bound would have called it dependent
    assert min(d["bound95"]) > 2.0 * white


def test_a_residual_that_follows_the_command_fails_at_its_lags():
    """A friction-like error, 0.3 of the noise's size times the sign of the command 10 ms earlier: flagged, with the
    lags about 10 ms among those beyond the bound."""
    exp, t, win, noise = _bench()
    sign = np.sign(np.interp(t - 0.010, exp.t_cmd, exp.i_cmd))
    d = cross_test(noise + 0.3 * float(np.std(noise)) * sign, t, win, (exp.t_cmd, exp.i_cmd), DT, BOUND)
    assert not d["ok"] and d["max_abs_z"] > BOUND, d
    assert 10.0 in d["lags_ms_beyond"], d["lags_ms_beyond"]


def test_in_closed_loop_the_command_follows_the_noise_and_the_excitation_does_not():
    """The angle's residual of a correct model is its measurement noise; a PD hold feeds that noise into the command
    (here 0.5 of the excitation's size through the gain). Against the command the check fails at lag 0 although
    nothing is missing from the model; against the excitation, which is a function of time only, it passes."""
    exp, t, win, noise = _bench()
    excitation = np.interp(t, exp.t_cmd, exp.i_cmd)
    command = excitation - 0.5 * float(np.std(excitation)) * noise / float(np.std(noise))
    closed = cross_test(noise, t, win, (t, command), DT, BOUND)
    assert not closed["ok"] and 0.0 in closed["lags_ms_beyond"], closed
    assert cross_test(noise, t, win, (t, excitation), DT, BOUND)["ok"]


def test_the_inputs_are_the_experiments_own_when_recorded():
    t = np.arange(0.0, 1.0, 0.002)
    cmd = SimpleNamespace(t_cmd=t, i_cmd=np.sin(t), t_exo=None, exogenous=None)
    assert list(inputs(cmd)) == ["command"]
    exo = SimpleNamespace(t_cmd=t, i_cmd=np.sin(t), t_exo=t, exogenous={"sysid_target_deg": t,
                                                                      "sysid_excitation_a": np.cos(t)})
    assert list(inputs(exo)) == ["sysid_target_deg", "sysid_excitation_a"]
    assert z_bound(312) > z_bound(156) > 3.9  # the family's bound grows with its size


def test_the_check_is_deterministic():
    exp, t, win, noise = _bench()
    sig = (exp.t_cmd, exp.i_cmd)
    assert cross_test(noise, t, win, sig, DT, BOUND) == cross_test(noise.copy(), t, win, sig, DT, BOUND)


def _encoder(seed: int = 4):  # type: ignore[no-untyped-def]
    """(true angle, its reading by an encoder of count Q: rounded to whole counts) of a 12 s motion with holds."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 12.0, DT)
    true = np.radians(10.0) * np.sin(2 * np.pi * 0.3 * t) * (np.sin(2 * np.pi * 0.1 * t) > -0.5)
    true = true + np.radians(0.2) * np.cumsum(rng.normal(size=len(t))) * math.sqrt(DT)
    return true, Q * np.round(true / Q)


Q = math.radians(0.09)


def test_a_model_that_follows_the_truth_stays_within_a_count_of_the_reading():
    """The reading is the truth rounded to whole counts: a model that follows the truth to within half a count of it
    is never more than one count from the reading (quantization is within half a count)."""
    true, reading = _encoder()
    model = true + 0.49 * Q * np.sin(np.arange(len(true)) * 0.37)
    d = beyond_count(reading - model, Q)
    assert d["ok"] and d["share_beyond_one_count"] == 0.0 and d["max_counts"] < 1.0, d
    assert d["samples"] == len(true) and d["count_deg"] == round(math.degrees(Q), 5)


def test_a_model_that_misses_a_torque_leaves_the_reading_by_more_than_a_count():
    """A model that drifts from the truth by one and a half counts through 2 % of the run (a friction the model lacks
    at each start of motion): beyond the limit; the same drift through 0.2 % of it: within."""
    true, reading = _encoder()
    drift = np.zeros(len(true))
    drift[:: 50] = 1.5 * Q  # every 50th sample: 2 %
    assert not beyond_count(reading - true - drift, Q)["ok"]
    few = np.zeros(len(true))
    few[:: 500] = 1.5 * Q  # 0.2 %
    d = beyond_count(reading - true - few, Q)
    assert d["ok"] and 0.0 < d["share_beyond_one_count"] <= BEYOND_COUNT_LIMIT and d["max_counts"] > 1.0, d

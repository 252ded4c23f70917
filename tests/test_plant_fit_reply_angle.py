"""pafp fit's timing models: the encoder angle a serial run takes from the motor's reply (the position when its
request reached the motor) and the command delay (`command_delay_s`), on a hand-built experiment."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hal.virtual.plant import load_plant_params
from host_tools.calibration.fit_data import COMMAND_DELAY_S, Experiment, _encoder_source
from host_tools.calibration.fit_model import base_values, simulate


def _experiment(from_reply: bool) -> Experiment:
    """0.5 s at 1 kHz: a current square wave, a request at each sample, each sample carrying the previous one's."""
    t = np.arange(500) * 1e-3
    i_cmd = np.where((t // 0.05) % 2 == 0, 1.5, -1.5)
    zeros = np.zeros_like(t)
    req_of = np.arange(len(t)) - 1
    return Experiment(t, i_cmd, t, zeros, zeros, zeros, "hand-built", zeros, t, req_of,
                      from_reply)


def test_a_reply_angle_is_the_plant_angle_when_its_request_arrived():
    base = load_plant_params()
    v = base_values(base)
    plain, _, _, mask = simulate(base, v, _experiment(False), free_v0=False)
    reply, _, _, _ = simulate(base, v, _experiment(True), free_v0=False)
    # requests arrive at the samples' times (the default command delay): a sample's reply angle is the previous
    # sample's plant angle, within each window (the first sample of a window has no request in it: masked)
    used = np.flatnonzero(mask)[1:]
    assert np.ptp(plain) > 0.01  # the foot moves: the comparison can fail
    assert np.allclose(reply[used], plain[used - 1], atol=1e-12)
    assert not np.allclose(reply[used], plain[used], atol=1e-6)


def test_the_command_delay_moves_the_simulated_response():
    base = load_plant_params()
    v = base_values(base)
    exp = _experiment(False)
    early, current_early, _, mask = simulate(base, v, exp, free_v0=False)
    late, current_late, _, _ = simulate(base, {**v, "command_delay_s": 0.002}, exp, free_v0=False)
    assert v["command_delay_s"] == COMMAND_DELAY_S
    # a later command: the reversals come later, so the response differs, most right after each reversal
    assert np.max(np.abs(early - late)[mask]) > 1e-4
    assert np.max(np.abs(current_early - current_late)[mask]) > 0.1


def test_the_encoder_source_comes_from_the_run_summary(tmp_path):
    assert _encoder_source(tmp_path) == ""  # no summary: the virtual bench's encoder
    (tmp_path / "summary.json").write_text(json.dumps({"encoder_source": "motor"}))
    assert _encoder_source(tmp_path) == "motor"
    (tmp_path / "summary.json").write_text("[1, 2")
    with pytest.raises(ValueError, match="summary.json"):
        _encoder_source(tmp_path)


def test_the_command_delay_is_bounded_below_the_reply_round_trip():
    """A delay longer than a period would leave samples whose reply's request has not arrived in the simulation:
    they carry the measured current and cost nothing (the artefact the bound keeps out: docs/calibration.md)."""
    from host_tools.calibration.fit_model import PARAMS

    base = load_plant_params()
    v = base_values(base)
    exp = _experiment(False)  # the measured current is 0 throughout; each sample carries the previous request's
    hi = PARAMS["command_delay_s"].hi
    assert hi < 1e-3
    _, at_bound, _, mask = simulate(base, {**v, "command_delay_s": hi}, exp, free_v0=False)
    _, too_late, _, _ = simulate(base, {**v, "command_delay_s": 1.5e-3}, exp, free_v0=False)
    assert np.all(at_bound[mask] != 0.0)  # every used sample's current is simulated
    assert np.all(too_late[mask] == 0.0)  # past a period every one is the measured current

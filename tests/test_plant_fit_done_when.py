"""Issue 21's done-when, end to end on the virtual bench: on a plant that is not the nominal one (--plant-seed 7, and
the hand-made plant file), `pafp run --experiment sysid` then `pafp fit` recovers every identified parameter within
its 95 % interval and inertia, damping, Coulomb friction and the gravity moment within 10 %; the fitted twin
predicts a different run (10 strides of gait tracking on the same plant, `pafp fit --validate`) with at least 90 %
fit on the encoder angle and 75 % on the current. A 10 s experiment keeps the test short (the default 29 s one's
figures are in docs/calibration.md, from the command it names)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from host_tools.calibration.plant_truth import truth_of
from host_tools.cli import main

ROOT = Path(__file__).resolve().parents[1]
HANDMADE = ROOT / "tests" / "data" / "plant_handmade.toml"
SHORT = ('\n[controller]\nname = "sysid"\nhold_s = 0.5\nsweep_deg = 12.0\nsweep_deg_s = 16.0\nchirp_s = 4.0\n'
         'prbs_s = 2.0\n')
QUIET = ["--quiet", "--no-plot", "--no-trace"]


@pytest.fixture(scope="module", params=[["--plant-seed", "7"], ["--plant", str(HANDMADE)]], ids=["seed7", "handmade"])
def fitted(request, tmp_path_factory):
    d = tmp_path_factory.mktemp("done")
    (d / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + SHORT)
    plant = request.param
    assert main(["run", "--experiment", "sysid", "--profile", str(d / "fw.toml"), *plant, *QUIET,
                 "--capture", str(d / "capture"), "--out", str(d / "sysid")]) == 0
    # a different run: 10 strides of gait tracking on the same plant (another seed: other noise, other offsets)
    assert main(["run", "--strides", "10", "--seed", "5", "--record", *plant, *QUIET, "--out", str(d / "gait")]) == 0
    assert main(["fit", str(d / "sysid"), "--validate", str(d / "gait"), "--no-plot", "--out", str(d / "fit")]) == 0
    return json.loads((d / "fit" / "fit.json").read_text()), truth_of(plant)


def _errors_in_half_widths(s: dict, truth: dict[str, float]) -> dict[str, float]:
    """|fitted - true| / 95 % half-width of every identified parameter with a known truth."""
    return {n: abs(p["value"] - truth[n]) / p["ci95_half_width"] for n, p in s["params"].items()
            if p["identifiable"] and n in truth and p["ci95_half_width"]}


def test_identified_parameters_are_within_their_intervals(fitted):
    """Each identified parameter within its own 95 % interval, on both plants, the rotor side's Kt/J_m among them
    (seed 7's static friction since the intervals carry the stuck starts' encoder count: docs/calibration.md,
    Limits, with the intervals' coverage over six plants)."""
    s, truth = fitted
    errors = _errors_in_half_widths(s, truth)
    assert len(errors) >= 5
    assert all(e <= 1.0 for e in errors.values()), errors


def test_residual_bias_is_within_three_half_widths(fitted):
    """A looser bound kept beside the strict one: every identified parameter within 3 half-widths."""
    s, truth = fitted
    errors = _errors_in_half_widths(s, truth)
    assert len(errors) >= 5 and "backlash_deg" in errors
    assert all(e <= 3.0 for e in errors.values()), errors


@pytest.mark.parametrize("name", ["output_inertia_kg_m2", "foot_damping_nm_s_per_rad", "gravity_moment_nm",
                                  "coulomb_friction_nm"])
def test_dynamics_within_ten_percent(fitted, name):
    s, truth = fitted
    p = s["params"][name]
    assert p["identifiable"], name
    assert abs(p["value"] / truth[name] - 1) < 0.10, (name, p["value"], truth[name])


def test_the_twin_predicts_a_gait_run(fitted):
    s, _ = fitted
    v = s["validation"]["fit_percent"]
    assert v["angle"] >= 90, v
    assert v["current"] >= 75, v

"""`pafp tune` and host_tools.studies.tuning: determinism, constraints, the written profile."""

import json
import math
import pickle

import pytest

from firmware.config import DEFAULT_PROFILE, load_firmware_config
from firmware.control.pid import PidGains
from host_tools.cli import main
from host_tools.studies import tuning
from host_tools.studies.sweep_engine import dask_client
from tests.study_clusters import threads_cluster  # noqa: F401 - a fixture


@pytest.fixture(scope="module")
def search_seed_5() -> tuning.TuneResult:
    """An in-process search of 5 candidates, seed 5 (two tests read it)."""
    return tuning.search(load_firmware_config(), budget=5, strides=1, seed=5)


def test_search_is_deterministic_whatever_the_worker_count(search_seed_5):
    base = load_firmware_config()
    a = search_seed_5  # in-process
    with dask_client(workers=2, processes=False) as client:  # two Dask worker threads
        b = tuning.search(base, budget=5, strides=1, seed=5, client=client)
    assert [e.as_dict() for e in a.evaluations] == [e.as_dict() for e in b.evaluations]
    assert [e.index for e in a.evaluations] == [0, 1, 2, 3, 4]
    assert a.start.gains == tuning.gains_of(base)  # candidate 0 is the starting profile
    assert a.best.score <= a.start.score
    assert a.best.score == min(e.score for e in a.evaluations)


def test_seed_changes_the_candidates(search_seed_5):
    rng_a = search_seed_5.evaluations[1].gains
    rng_b = tuning.search(load_firmware_config(), budget=5, strides=1, seed=2).evaluations[1].gains
    assert rng_a != rng_b
    for k, (lo, hi) in tuning.BOUNDS.items():
        assert lo <= rng_a[k] <= hi


def test_saturation_storm_is_infeasible():
    # hot gains drive the current command into its limit for much of the gait
    base = load_firmware_config()
    hot = tuning.gains_of(base.with_changes(position_gains=PidGains(30.0, 10.0, 0.1, 0.004),
                                            velocity_gains=PidGains(5.0, 100.0)))
    e = tuning.evaluate(0, base, hot, strides=1, seed=0)
    assert not e.feasible and math.isinf(e.score)
    assert e.saturation_fraction > tuning.SATURATION_MAX_FRACTION
    assert "saturation storm" in e.reason


@pytest.fixture(scope="module")
def nominal() -> tuning.Evaluation:
    """The profile's own gains on the default plant, one stride, seed 0 (two tests read it)."""
    base = load_firmware_config()
    return tuning.evaluate(0, base, tuning.gains_of(base), strides=1, seed=0)


def test_profile_gains_are_feasible_with_a_finite_score(nominal):
    e = nominal
    assert e.feasible, e.reason
    assert e.score == pytest.approx(e.rms_error_deg + tuning.EFFORT_WEIGHT * (e.rms_current_a + e.rms_current_step_a))


def test_differential_evolution_evolves_within_the_budget():
    # 16 runs = 2 generations of 8: the second is built by DE from the first
    base = load_firmware_config()
    r = tuning.search(base, budget=16, strides=1, seed=0)
    assert [e.index for e in r.evaluations] == list(range(16))
    first = [e.gains for e in r.evaluations[:8]]
    assert all(e.gains not in first for e in r.evaluations[8:])
    assert r.best.score == min(e.score for e in r.evaluations)


def test_write_profile_round_trips(tmp_path):
    gains = {"position_kp": 7.5, "position_ki": 1.25, "position_kd": 0.03, "velocity_kp": 0.5, "velocity_ki": 4.0}
    out = tuning.write_profile(DEFAULT_PROFILE, gains, tmp_path / "p.toml")
    src, text = DEFAULT_PROFILE.read_text().splitlines(), out.read_text().splitlines()
    comments = [line for line in src if line.lstrip().startswith("#") or " # " in line and "=" not in line]
    assert comments and all(c in text for c in comments)  # every comment line kept
    assert len(text) == len(src)  # line for line: only the five values differ
    assert sum(a != b for a, b in zip(src, text, strict=True)) == 5
    cfg = load_firmware_config(out)
    assert tuning.gains_of(cfg) == gains
    base = load_firmware_config()
    assert cfg.with_changes(position_gains=base.position_gains, velocity_gains=base.velocity_gains) == base


def test_write_profile_refuses_a_profile_without_gain_lines(tmp_path):
    src = tmp_path / "empty.toml"
    src.write_text("[rates_hz]\ncontrol = 1000\n")
    with pytest.raises(ValueError, match="position_kp"):
        tuning.write_profile(src, tuning.gains_of(load_firmware_config()), tmp_path / "out.toml")


@pytest.mark.parametrize("budget", [1, 4, 100_001, True])
def test_search_rejects_bad_budgets(budget):
    with pytest.raises(ValueError, match=f"budget {budget!r} out of range: an int in 5..100000"):
        tuning.search(load_firmware_config(), strides=1, budget=budget)


@pytest.mark.parametrize(("old", "new", "needle"), [
    ("control = 1000", "contrl = 1000", "[rates_hz] has no key 'contrl'"),
    ("angle_min_deg = -33.0", "angle_mni_deg = -33.0", "[safety] has no key 'angle_mni_deg'"),
])
def test_profile_with_a_misspelled_key_is_refused_naming_the_key(tmp_path, old, new, needle):
    text = DEFAULT_PROFILE.read_text(encoding="utf-8")
    assert text.count(old) == 1
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(old, new), encoding="utf-8")
    with pytest.raises(ValueError) as info:
        load_firmware_config(bad)
    assert needle in str(info.value) and str(bad) in str(info.value)


def test_firmware_config_pickles_for_the_tuning_workers() -> None:
    cfg = load_firmware_config()
    back = pickle.loads(pickle.dumps(cfg))
    assert back == cfg and back.position_gains == cfg.position_gains and back.safety == cfg.safety


PLANT = DEFAULT_PROFILE.parent / "plant_ak60_6.toml"


def _heavier_plant(tmp_path):
    """The packaged plant with the foot's damping x4 and Coulomb friction x2.5 (a plant `pafp fit` could write)."""
    text = PLANT.read_text(encoding="utf-8")
    assert text.count("foot_damping_nm_s_per_rad = 0.5") == 1 and text.count("coulomb_friction_nm = 0.1") == 1
    path = tmp_path / "plant_fitted.toml"
    path.write_text(text.replace("foot_damping_nm_s_per_rad = 0.5", "foot_damping_nm_s_per_rad = 2.0")
                    .replace("coulomb_friction_nm = 0.1", "coulomb_friction_nm = 0.25"), encoding="utf-8")
    return path


def test_candidates_run_the_plant_they_are_given(tmp_path, nominal):
    base = load_firmware_config()
    gains = tuning.gains_of(base)
    packaged = tuning.evaluate(0, base, gains, strides=1, seed=0, plant=tuning.TunePlant(PLANT))
    heavier = tuning.evaluate(0, base, gains, strides=1, seed=0, plant=tuning.TunePlant(_heavier_plant(tmp_path)))
    drawn = tuning.evaluate(0, base, gains, strides=1, seed=0, plant=tuning.TunePlant(seed=7))
    assert packaged.as_dict() == nominal.as_dict()  # the packaged file is the default plant
    assert heavier.rms_current_a != nominal.rms_current_a and heavier.rms_error_deg != nominal.rms_error_deg
    assert drawn.rms_error_deg != nominal.rms_error_deg


@pytest.mark.usefixtures("threads_cluster")
def test_pafp_tune_on_a_plant_file_writes_profile_json_and_plot(tmp_path, capsys):
    """One `pafp tune`: the outputs, and the plant it was given (pickled to the worker with each candidate, as to a
    worker process; `pafp tune` on its cluster of processes: the stop-signal tests in tests/test_output_failures.py)."""
    plant = _heavier_plant(tmp_path)
    out = tmp_path / "tune"
    assert main(["tune", "--budget", "5", "--strides", "1", "--workers", "1", "--seed", "3", "--quiet",
                 "--plant", str(plant), "--plant-seed", "7", "--out", str(out)]) == 0
    doc = json.loads((out / "tune.json").read_text())
    assert len(doc["evaluations"]) == 5 and doc["seed"] == 3
    assert doc["best"]["score"] <= doc["before"]["score"]
    assert doc["plant"] == {"file": str(plant), "seed": 7}
    base = load_firmware_config()
    again = tuning.evaluate(0, base, tuning.gains_of(base), strides=1, seed=3,
                            plant=tuning.TunePlant(plant, 7))
    assert doc["before"] == json.loads(json.dumps(again.as_dict()))  # candidate 0 ran that plant, that draw
    cfg = load_firmware_config(out / "firmware_tuned.toml")
    assert tuning.gains_of(cfg) == pytest.approx(doc["best"]["gains"])
    assert (out / "tune.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert "before: RMS" in printed and "after:  RMS" in printed
    assert f"on plant {plant} drawn with seed 7" in printed
    assert main(["run", "--profile", str(out / "firmware_tuned.toml"), "--strides", "1", "--quiet", "--no-plot",
                 "--no-trace", "--out", str(tmp_path / "run")]) == 0


def test_pafp_tune_refuses_a_missing_plant_file_before_any_run(tmp_path, capsys):
    out = tmp_path / "tune"
    assert main(["tune", "--budget", "5", "--strides", "1", "--quiet", "--plant", str(tmp_path / "missing.toml"),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"cannot read plant profile {tmp_path / 'missing.toml'}" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_bad_plant_seed_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"plant seed -1 out of range"):
        tuning.search(load_firmware_config(), budget=5, strides=1, plant=tuning.TunePlant(seed=-1))

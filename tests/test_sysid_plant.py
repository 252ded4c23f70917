"""The identification experiment controller, `--plant FILE` on run and emulate, and the emulator's imperfections."""

from __future__ import annotations

import argparse
import json
import math
import re
from pathlib import Path

import pytest

from firmware.config import load_firmware_config
from firmware.control.observation import Observation
from firmware.control.registry import build_controller
from firmware.control.sysid import SysidExperiment
from hal.virtual.plant import load_plant_params
from host_tools.cli import main
from host_tools.runner import RunConfig
from host_tools.serial_mode.served_plant import served_plant

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "profiles" / "plant_ak60_6.toml"


def _plant_file(tmp_path: Path, **values: float) -> Path:
    text = PLANT.read_text()
    for key, value in values.items():
        text, n = re.subn(rf"^{key}\s*=\s*[^#\n]*", f"{key} = {value!r}", text, count=1, flags=re.M)
        assert n == 1, key
    path = tmp_path / "plant.toml"
    path.write_text(text)
    return path


def test_sysid_is_a_shipped_controller_within_its_limits():
    cfg = load_firmware_config()
    c = build_controller("sysid", cfg, {})
    assert isinstance(c, SysidExperiment)
    assert 20.0 < c.duration_s < 40.0
    names = [n for n, _ in c.bounds]
    assert names == ["hold", "sweep", "chirp", "prbs", "hold_end"]
    obs = Observation()
    seen_current, targets = [], []
    for k in range(int(c.duration_s * 1000)):
        obs.t_s = k * 1e-3
        target, _ = c.target_and_excitation(obs.t_s)
        targets.append(target)
        obs.encoder_angle_rad = target  # a perfect hold: the command is the excitation
        seen_current.append(c.update(obs))
    limit = 0.6 * cfg.current_limit_a
    assert max(abs(i) for i in seen_current) <= limit
    assert min(targets) >= cfg.safety.angle_min_rad + math.radians(5) - 1e-9
    assert max(targets) <= cfg.safety.angle_max_rad - math.radians(5) + 1e-9
    assert max(targets) - min(targets) > math.radians(30)  # the sweep covers the range
    # the guard: beyond the margin the command pushes back towards the centre, whatever the excitation
    obs.encoder_angle_rad = cfg.safety.angle_max_rad
    assert c.update(obs) < 0.0


def test_sysid_parameters_are_checked():
    cfg = load_firmware_config()
    with pytest.raises(ValueError, match="sweep_deg"):
        build_controller("sysid", cfg, {"sweep_deg": 100.0})
    with pytest.raises(ValueError, match="unknown parameter 'bogus'"):
        build_controller("sysid", cfg, {"bogus": 1})
    with pytest.raises(ValueError, match="leaves the range of motion"):
        build_controller("sysid", cfg, {"sweep_deg": 30.0, "margin_deg": 10.0})


def test_same_seed_same_prbs():
    cfg = load_firmware_config()
    a, b, c = (build_controller("sysid", cfg, {"seed": s}) for s in (1, 1, 2))
    t0 = a.bounds[2][1] + 0.001  # inside the PRBS
    seq = [[x.target_and_excitation(t0 + k * 0.03)[1] for k in range(50)] for x in (a, b, c)]
    assert seq[0] == seq[1] != seq[2]
    assert set(seq[0]) == {1.0, -1.0}


def test_experiment_run_records_and_stays_in_run(tmp_path):
    out = tmp_path / "sysid"
    profile = tmp_path / "short.toml"
    profile.write_text((ROOT / "profiles" / "firmware.toml").read_text() + '\n[controller]\nname = "sysid"\n'
                       'hold_s = 0.3\nsweep_deg = 5.0\nsweep_deg_s = 20.0\nchirp_s = 0.5\nprbs_s = 0.3\n')
    assert main(["run", "--experiment", "sysid", "--profile", str(profile), "--quiet", "--no-plot", "--no-trace",
                 "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["faults"] == [] and (out / "record.bin").stat().st_size > 0
    assert s["sim_time_s"] < 5.0  # the profile's short experiment, not the default 29 s
    assert "sysid_segment" in (out / "telemetry.csv").read_text().splitlines()[0]


def test_plant_file_is_the_plant_and_the_seed_draws_around_it(tmp_path):
    nominal = load_plant_params()
    path = _plant_file(tmp_path, foot_inertia_kg_m2=0.0039 * 1.3, coulomb_friction_nm=0.25)
    options, record = RunConfig(plant_file=path).bench_setup()
    p = options["plant_params"]
    assert p.foot_inertia_kg_m2 == pytest.approx(0.0039 * 1.3) and p.coulomb_friction_nm == 0.25
    assert record["plant"]["file"] == str(path)
    drawn, _ = RunConfig(plant_file=path, plant_seed=7).bench_setup()
    assert drawn["plant_params"] != p and drawn["plant_params"].coulomb_friction_nm <= 0.15  # its tolerance range
    assert p.kt_nm_per_a == nominal.kt_nm_per_a


def test_bad_plant_file_is_one_line_exit_2(tmp_path, capsys):
    path = _plant_file(tmp_path, foot_mass_kg=-1.0)
    assert main(["run", "--plant", str(path), "--strides", "1", "--quiet", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "foot_mass_kg" in err[0] and "allowed range" in err[0]
    assert main(["run", "--plant", str(tmp_path / "none.toml"), "--strides", "1", "--quiet"]) == 2


def test_emulate_has_the_bench_imperfections_and_the_plant(tmp_path):
    path = _plant_file(tmp_path, coulomb_friction_nm=0.3)
    args = argparse.Namespace(seed=3, plant=path, plant_seed=None, ideal=[])
    o = served_plant(seed=args.seed, plant_file=args.plant).options
    assert o["plant_params"].coulomb_friction_nm == 0.3
    assert o["backlash_rad"] > 0 and o["imu_config"].bias_sigma_rad > 0 and o["initial_angle_rad"] != 0.0
    ideal = served_plant(seed=3, ideal=("all",)).options
    assert ideal["backlash_rad"] == 0 and ideal["imu_config"].bias_sigma_rad == 0 and ideal["initial_angle_rad"] == 0


def test_sweep_spec_runs_a_plant_file(tmp_path):
    from host_tools.studies.sweep_engine import tasks_of
    from host_tools.studies.sweep_point import plant_seed_run_options, run_config_of
    from host_tools.studies.sweep_spec import SpecError, load_spec

    plant = _plant_file(tmp_path, coulomb_friction_nm=0.3)
    spec = tmp_path / "spec.toml"
    spec.write_text('[base]\nplant = "plant.toml"\nstrides = 1\n\n[[grid]]\nkey = "run.seed"\nvalues = [0, 1]\n\n'
                    '[monte_carlo]\nsamples = 2\nseed = 1\n')
    tasks = tasks_of(load_spec(spec))
    cfg = run_config_of(tasks[0], plant_seed_run_options)
    assert cfg.plant_file == plant and cfg.plant_seed is not None
    options, _ = cfg.bench_setup()
    assert options["plant_params"] != load_plant_params(plant)  # drawn around the file
    (tmp_path / "plant.toml").write_text(PLANT.read_text().replace("foot_mass_kg = ", "foot_mass_kg = -", 1))
    with pytest.raises(SpecError, match="foot_mass_kg"):
        load_spec(spec)

"""Options that would be ignored or misused are refused in one line before any work (issue 35, cases 5 and 8):
`run --experiment` with --strides or --controller, `fit --params` naming a parameter twice, `fit` on a directory
mixing two runs' files, a repeated --sensor-fault, `bench --out` on a directory of other files; the IMU model
and the controllers' origins on the command line.
"""

from __future__ import annotations

import json
import shutil
import warnings

import numpy as np
import pytest

from firmware.control.registry import CONTROLLERS
from host_tools.calibration.fit_model import fit_percentage
from host_tools.cli import main


def _one_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("pafp ")]
    assert "Traceback" not in err and len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("extra, option", [(["--strides", "3"], "--strides 3"),
                                           (["--controller", "impedance"], "--controller impedance")])
def test_run_experiment_refuses_the_options_it_would_ignore(tmp_path, capsys, extra, option):
    out = tmp_path / "run"
    assert main(["run", "--experiment", "sysid", *extra, "--quiet", "--out", str(out)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert f"{option} is not allowed with --experiment sysid" in line
    assert not out.exists()


def test_fit_refuses_a_parameter_named_twice(tmp_path, capsys):
    names = "output_inertia_kg_m2,coulomb_friction_nm,output_inertia_kg_m2"
    assert main(["fit", str(tmp_path), "--params", names]) == 2
    line = _one_line(capsys.readouterr().err)
    assert f"--params {names!r}" in line
    assert "output_inertia_kg_m2 is named 2 times" in line


def test_fit_refuses_a_directory_that_mixes_two_runs_files(tmp_path, capsys):
    for seed in (0, 1):
        assert main(["run", "--strides", "1", "--record", "--seed", str(seed), "--quiet", "--no-plot", "--no-trace",
                     "--out", str(tmp_path / f"run{seed}")]) in (0, 1)
    capsys.readouterr()
    shutil.copy(tmp_path / "run1" / "telemetry.csv", tmp_path / "run0" / "telemetry.csv")
    assert main(["fit", str(tmp_path / "run0"), "--no-plot"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert str(tmp_path / "run0" / "telemetry.csv") in line and "mixes the files of two runs" in line
    assert not (tmp_path / "run0" / "fit").exists()


def test_a_fit_percentage_of_a_part_without_samples_is_nan_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(fit_percentage(np.array([]), np.array([])))


def test_a_repeated_sensor_fault_on_one_sensor_is_refused(tmp_path, capsys):
    assert main(["run", "--scenario", "walk", "--sensor-fault", "fsr_heel:open", "--sensor-fault", "fsr_heel:short",
                 "--strides", "1", "--quiet", "--out", str(tmp_path / "run")]) == 2
    assert "fsr_heel already has 'fsr_heel:open': one fault per sensor" in _one_line(capsys.readouterr().err)


def test_bench_out_refuses_a_directory_of_other_files_and_takes_its_own(tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "kinematics.csv").write_text("my own table, not a bench output's name clash by chance")
    (out / "notes.txt").write_text("keep me")
    assert main(["bench", "kinematics", "--quick", "--out", str(out)]) == 2
    assert "notes.txt" in _one_line(capsys.readouterr().err)
    assert (out / "kinematics.csv").read_text().startswith("my own table")
    (out / "notes.txt").unlink()
    assert main(["bench", "kinematics", "--quick", "--out", str(out)]) == 0  # a previous bench's: taken
    capsys.readouterr()
    assert main(["bench", "kinematics", "--quick", "--out", str(out)]) == 0
    assert sorted(p.suffix for p in out.iterdir()) == [".csv", ".json", ".md", ".png"]


class _Plugin:
    """A controller class a plug-in would register."""


def test_help_lists_a_plug_in_controller_as_a_plug_in(capsys):
    CONTROLLERS.register("acme-law", _Plugin)
    try:
        with pytest.raises(SystemExit):
            main(["run", "--help"])
    finally:
        CONTROLLERS.unregister("acme-law")
    text = " ".join(capsys.readouterr().out.split())
    shipped, _, rest = text.partition("(shipped)")
    assert "acme-law" not in shipped.rpartition("the control law:")[2] and rest.lstrip("; ").startswith(
        "acme-law (plug-in)")


def test_the_imu_model_is_chosen_on_the_command_line(tmp_path, capsys):
    assert main(["run", "--imu-model", "ak60-6", "--strides", "1", "--quiet", "--out", str(tmp_path / "x")]) == 2
    assert "--imu-model 'ak60-6' is a motor device, not an IMU" in _one_line(capsys.readouterr().err)
    out = tmp_path / "run"
    assert main(["run", "--imu-model", "bno085", "--strides", "1", "--quiet", "--no-plot", "--no-trace",
                 "--out", str(out)]) in (0, 1)
    assert json.loads((out / "summary.json").read_text())["imu_rms_error_deg"] is not None

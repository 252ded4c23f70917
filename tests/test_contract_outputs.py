"""The output half of the commands' contract (host_tools/contract.py, docs/commands.md "The contract"): an output that
is, holds or lies inside one of the command's inputs is refused in one line before any work, with the input intact;
an existing --out is replaced only when it is provably pafp's own previous output; re-run commands are shell-quoted.
"""

from __future__ import annotations

import json
import shlex
import shutil
from pathlib import Path

import pytest
from contract_cases import one_line, pafp, record_run, tree

from profiles import profile_path


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    return record_run(tmp_path_factory.mktemp("rec") / "run")


@pytest.fixture
def run_copy(recorded, tmp_path):
    copy = tmp_path / "R"
    shutil.copytree(recorded, copy)
    return copy


@pytest.mark.parametrize("command", ["replay", "fit"])
def test_out_the_input_run_directory_is_refused_and_the_run_kept(command, run_copy, capsys):
    """Issue 35, case 1: `replay R --out R` and `fit R --out R` deleted record.bin, telemetry and report.md."""
    before = tree(run_copy)
    code, _, err = pafp(capsys, command, run_copy, "--out", run_copy)
    line = one_line(err)
    assert code == 2 and f"--out {run_copy}" in line and "input" in line
    assert tree(run_copy) == before


def test_out_holding_the_plant_file_is_refused(tmp_path, capsys):
    """Issue 35, case 1: `run --plant F/plant_fitted.toml --out F` deleted the plant it had just read."""
    fitted = tmp_path / "F"
    fitted.mkdir()
    plant = fitted / "plant_fitted.toml"
    shutil.copy(profile_path("plant_ak60_6.toml"), plant)
    (fitted / "summary.json").write_text("{}")  # as `pafp fit` leaves it: once enough to be "a previous run"
    before = tree(fitted)
    code, _, err = pafp(capsys, "run", "--strides", "1", "--plant", plant, "--out", fitted)
    line = one_line(err)
    assert code == 2 and str(plant) in line and "input" in line
    assert tree(fitted) == before


def test_default_out_inside_the_run_is_allowed_but_not_over_an_input(run_copy, capsys):
    """`fit R`'s default --out is R/fit (inside the input directory: allowed); R/fit holding the --base it reads is
    not."""
    base = run_copy / "fit" / "plant_fitted.toml"
    base.parent.mkdir()
    shutil.copy(profile_path("plant_ak60_6.toml"), base)
    before = tree(run_copy)
    code, _, err = pafp(capsys, "fit", run_copy, "--base", base)
    assert code == 2 and "holds the input" in one_line(err) and str(base) in err
    assert tree(run_copy) == before


def test_an_output_file_that_is_the_input_is_refused(run_copy, capsys):
    """decode --csv over its own capture would replace the capture."""
    capture = run_copy / "telemetry.bin"
    before = capture.read_bytes()
    code, _, err = pafp(capsys, "decode", "--protocol", "telemetry", "--csv", capture, capture)
    assert code == 2 and "--csv" in one_line(err)
    assert capture.read_bytes() == before


def test_a_summary_json_alone_does_not_make_a_directory_replaceable(tmp_path, capsys):
    """Issue 35, case 1: any directory holding a summary.json was treated as a previous run and replaced whole."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "summary.json").write_text('{"my": "notes"}')
    (mine / "data.csv").write_text("precious\n")
    before = tree(mine)
    code, _, err = pafp(capsys, "run", "--strides", "1", "--quiet", "--no-plot", "--no-trace", "--out", mine)
    assert code == 2 and "not a pafp run's" in one_line(err)
    assert tree(mine) == before


def test_pafp_own_previous_output_is_replaced_and_a_foreign_file_in_it_stops_that(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ("run", "--strides", "1", "--quiet", "--no-plot", "--no-trace", "--out", out)
    assert pafp(capsys, *argv)[0] == 0
    listed = json.loads((out / ".pafp-outputs.json").read_text())["files"]
    assert set(listed) == {p.name for p in out.iterdir()} - {".pafp-outputs.json"}
    assert pafp(capsys, *argv)[0] == 0  # its own previous output: replaced
    (out / "my_notes.txt").write_text("keep")
    code, _, err = pafp(capsys, *argv)
    assert code == 2 and "'my_notes.txt'" in one_line(err)
    assert (out / "my_notes.txt").read_text() == "keep"


def test_rerun_commands_survive_paths_with_spaces(tmp_path):
    """Issue 35, case 7: the re-run commands faults prints and design.md holds were not shell-quoted."""
    from host_tools.studies.design_point import rerun_command as design_rerun
    from host_tools.studies.design_spec import load_design_spec
    from host_tools.studies.fault_report import rerun_command as fault_rerun
    from host_tools.studies.fault_spec import load_fault_spec

    where = tmp_path / "my specs"
    where.mkdir()
    faults = where / "my campaign.toml"
    shutil.copy(profile_path("faults/default.toml"), faults)
    shutil.copy(profile_path("faults/criteria.toml"), where / "criteria.toml")
    (tmp_path / "designs").mkdir()  # the adult scenario's profile, named relative to the spec
    shutil.copy(profile_path("designs/adult_80kg.toml"), tmp_path / "designs" / "adult_80kg.toml")
    words = shlex.split(fault_rerun(load_fault_spec(faults), 3))
    assert words[:5] == ["pafp", "faults", str(faults), "--point", "3"] and words[6] == "runs/my campaign-point-3"
    design = where / "my design.toml"
    design.write_text('[search]\nmotors = ["ak60_6"]\nbody_masses_kg = [20]\nspeeds = ["free"]\nstrides = 1\n'
                      "[[belt]]\ndriver_teeth = 30\ndriven_teeth = 140\npitch_mm = 2.0\n", encoding="utf-8")
    point = load_design_spec(design).points(tmp_path / "out dir")[0]
    words = shlex.split(design_rerun(point))
    assert words[words.index("--profile") + 1] == str(Path(point.profile_name))


def test_serial_mode_marks_what_it_wrote_in_place(tmp_path, capsys):
    """Serial mode writes into --out directly (not staged): it leaves the manifest too, so a second run may replace."""
    out = tmp_path / "serial"
    argv = ("run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--duration", "0.3", "--no-realtime",
            "--quiet", "--out", out)
    assert pafp(capsys, *argv)[0] in (0, 1)
    listed = json.loads((out / ".pafp-outputs.json").read_text())["files"]
    assert "summary.json" in listed and set(listed) == {p.name for p in out.iterdir()} - {".pafp-outputs.json"}
    code, _, err = pafp(capsys, *argv)
    assert code in (0, 1) and "not a pafp run's" not in err

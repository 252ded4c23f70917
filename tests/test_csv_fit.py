"""`pafp fit LOG.csv`: a bench log pafp did not make (tests/data_gen/ak80_9_log.py, numpy only) is fitted to its
truth; bad logs are refused in one line before any fitting."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from host_tools.cli import main

GENERATOR = Path(__file__).parent / "data_gen" / "ak80_9_log.py"
PAFP_PACKAGES = ("hal", "host_tools", "firmware", "protocol", "rtos", "profiles")
COLUMNS = "command=current_command,torque=torque_sensor"
# the script runs in a fresh interpreter outside the repository, then says which of pafp's packages it imported
_RUN = ("import json, runpy, sys; truth = runpy.run_path(sys.argv[1], run_name='_gen')['make_log'](sys.argv[2]); "
        f"print(json.dumps([truth, sorted({{m.split('.')[0] for m in sys.modules}} & set({PAFP_PACKAGES!r}))]))")


@pytest.fixture(scope="module")
def bench_log(tmp_path_factory):
    """(the generated log's path, its truth)."""
    path = tmp_path_factory.mktemp("csv") / "ak80_9.csv"
    out = subprocess.run([sys.executable, "-c", _RUN, str(GENERATOR), str(path)], capture_output=True, text=True,
                         check=True,
                         env={"PATH": "/usr/bin:/bin"}, cwd=GENERATOR.parent)
    truth, imported = json.loads(out.stdout)
    assert imported == []  # the log is made with none of pafp's code
    return path, truth


def _fit(path, out, *extra):
    code = main(["fit", str(path), "--out", str(out), *extra])
    return code, (json.loads((out / "fit.json").read_text()) if code == 0 else None)


def test_the_generator_imports_none_of_pafp():
    source = GENERATOR.read_text()
    imports = [line.split()[1] for line in source.splitlines() if line.startswith(("import ", "from "))]
    assert set(imports) <= {"__future__", "json", "math", "sys", "numpy"}


def test_a_foreign_log_is_fitted_within_10_percent(bench_log, tmp_path, capsys):
    """The done-when of issue 34: Kt, Coulomb and viscous friction within 10 % of the simulated AK80-9's (and the
    inertia and the current lag too), through the command and its preset for TMotorCANControl's columns."""
    path, truth = bench_log
    code, doc = _fit(path, tmp_path / "fit", "--columns", COLUMNS)
    assert code == 0
    assert doc["columns"]["position"] == {"header": "motor_position", "unit": "rad", "from": "preset tmotor-servo"}
    p = doc["params"]
    for key in ("kt_nm_per_a", "coulomb_friction_nm", "viscous_friction_nm_s_per_rad", "rotor_inertia_kg_m2",
                "current_time_constant_s"):
        assert p[key]["identifiable"], key
        assert p[key]["value"] == pytest.approx(truth[key], rel=0.10), key
    assert doc["command_delay_samples"] == 0
    assert (tmp_path / "fit" / "fit.md").read_text().count("| identified |") == 5
    assert "kt_nm_per_a" in capsys.readouterr().out


def _without(path, tmp_path, column):
    """The log without one of its columns."""
    data = np.genfromtxt(path, delimiter=",", names=True)
    keep = [n for n in data.dtype.names if n != column]
    slim = tmp_path / f"no_{column}.csv"
    np.savetxt(slim, np.column_stack([data[n] for n in keep]), delimiter=",", header=",".join(keep), comments="")
    return slim


def test_a_log_with_speed_but_no_position_is_fitted_too(bench_log, tmp_path):
    path, truth = bench_log
    code, doc = _fit(_without(path, tmp_path, "motor_position"), tmp_path / "fit", "--columns", COLUMNS)
    assert code == 0 and "position" not in doc["columns"]
    for key in ("kt_nm_per_a", "coulomb_friction_nm", "viscous_friction_nm_s_per_rad"):
        assert doc["params"][key]["value"] == pytest.approx(truth[key], rel=0.10), key


def test_an_output_side_log_with_its_gear_ratio_gives_the_rotor_figures(bench_log, tmp_path):
    """TMotorCANControl's MIT-mode columns are the output's (after the 9:1 gearbox): --gear-ratio 9 brings the fit
    back to the rotor (the gearbox taken lossless here, so the figures are the rotor's own)."""
    path, truth = bench_log
    d = np.genfromtxt(path, delimiter=",", names=True)
    mit = tmp_path / "mit.csv"
    cols = {"pi_time": d["pi_time"], "output_angle": d["motor_position"] / 9, "output_velocity": d["motor_speed"] / 9,
            "current": d["motor_current"], "output_torque": 9 * 0.115 * d["motor_current"],
            "i_cmd": d["current_command"], "sensor": 9 * d["torque_sensor"]}
    np.savetxt(mit, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    code, doc = _fit(mit, tmp_path / "fit", "--columns", "command=i_cmd,torque=sensor", "--gear-ratio", "9")
    assert code == 0 and doc["columns"]["position"]["from"] == "preset tmotor-mit"
    assert doc["columns"]["torque"]["header"] == "sensor"  # never the MIT log's computed output_torque
    for key in ("kt_nm_per_a", "coulomb_friction_nm", "viscous_friction_nm_s_per_rad"):
        assert doc["params"][key]["value"] == pytest.approx(truth[key], rel=0.10), key


def test_without_torque_sensor_kt_is_reported_not_in_the_data(bench_log, tmp_path):
    path, _ = bench_log
    slim = _without(path, tmp_path, "torque_sensor")
    code, doc = _fit(slim, tmp_path / "fit", "--columns", "command=current_command")
    assert code == 0
    assert "kt_nm_per_a" not in doc["params"]
    assert doc["not_in_the_data"]["kt_nm_per_a"].startswith("no torque column")
    assert doc["params"]["coulomb_friction_nm"]["unit"] == "A (Tc/Kt)"


def _bad_log(tmp_path, header, rows):
    path = tmp_path / "bad.csv"
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.9g}" for v in r) for r in rows) + "\n")
    return path


def _rows(n=400, dt=1e-3, current=1.0, speed_scale=1.0):
    t = np.arange(n) * dt
    pos = np.sin(2 * np.pi * 2 * t)
    return [(ti, p, speed_scale * 4 * np.pi * np.cos(2 * np.pi * 2 * ti), current * np.sin(9 * ti))
            for ti, p in zip(t, pos, strict=True)]


HEADER = ["pi_time", "motor_position", "motor_speed", "motor_current"]


@pytest.mark.parametrize("case, expect", [
    ("missing", "no column for current ('motor_current' in preset tmotor-servo); the header has pi_time, "
                "motor_position, motor_speed"),
    ("backwards", "row 102: time 0.0985 s is not after row 101's 0.099 s (column 'pi_time' [s] (preset tmotor-servo)): "
                  "time must increase strictly"),
    ("milliamps", "current 1499.99 A from column 'motor_current' [A] (preset tmotor-servo) outside the allowed range "
                  "[-200, 200] A: is the unit right?"),
    ("milliseconds", "median sample period 1 s from column 'pi_time' [s] (preset tmotor-servo) outside the allowed "
                     "range [1e-05, 0.5] s"),
    ("degrees", "is 57.3 x the derivative of the position"),
    ("text", "row 5, column 'motor_current' (current): 'n/a' is not a finite number"),
    ("unknown column", "column 'i_cmd' (--columns command) not in the header"),
    ("bad role", "--columns item 'volts=motor_current': expected ROLE=HEADER[:unit]"),
])
def test_bad_logs_are_refused_in_one_line_before_fitting(tmp_path, capsys, case, expect):
    rows, header, extra = _rows(), list(HEADER), []
    if case == "missing":
        header, rows = header[:3], [r[:3] for r in rows]
    elif case == "backwards":
        rows[100] = (rows[99][0] - 0.0005, *rows[100][1:])
    elif case == "milliamps":
        rows = _rows(current=1500.0)
    elif case == "milliseconds":
        rows = _rows(dt=1.0)
    elif case == "degrees":
        rows = _rows(speed_scale=57.2958)
    elif case == "unknown column":
        extra = ["--columns", "command=i_cmd"]
    elif case == "bad role":
        extra = ["--columns", "volts=motor_current"]
    path = _bad_log(tmp_path, header, rows)
    if case == "text":
        lines = path.read_text().splitlines()
        lines[4] = ",".join(lines[4].split(",")[:3] + ["n/a"])
        path.write_text("\n".join(lines) + "\n")
    assert main(["fit", str(path), "--out", str(tmp_path / "out"), *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expect in err, err
    assert not (tmp_path / "out").exists()


def test_opensourceleg_columns_are_matched_by_their_attribute_name(tmp_path):
    """opensourceleg's Logger.track_attributes prefixes the actuator: 'TMotor[ankle].motor_current' etc."""
    from host_tools.calibration.csv_log import read_log

    header = ["time", "TMotor[ankle].motor_position", "TMotor[ankle].motor_velocity", "TMotor[ankle].motor_current"]
    log = read_log(_bad_log(tmp_path, header, _rows()))
    roles = ("time", "position", "speed", "current")
    assert {r: c.header for r, c in log.columns.items()} == dict(zip(roles, header, strict=True))
    assert log.columns["current"].source == "preset opensourceleg"


def test_a_log_too_still_to_fit_is_refused_naming_the_threshold(tmp_path, capsys):
    rows = [(r[0], 0.0, 0.0, r[3]) for r in _rows()]
    assert main(["fit", str(_bad_log(tmp_path, HEADER, rows)), "--out", str(tmp_path / "o"), "--min-speed", "1"]) == 2
    assert "windows of 10 ms where the shaft turns one way faster than 1 rad/s" in capsys.readouterr().err


def test_run_directory_options_are_refused_for_a_csv_log(tmp_path, capsys):
    path = _bad_log(tmp_path, HEADER, _rows())
    assert main(["fit", str(path), "--validate", str(tmp_path)]) == 2
    assert "--validate applies to a run directory" in capsys.readouterr().err

"""`pafp sweep`: spec validation, failure rows, resume, worker-count independence, Monte Carlo seeding.

Clusters here are LocalClusters of 1-2 worker threads (processes=False: no process start-up on a busy
machine); one CLI test runs the real thing, a LocalCluster of one worker process on 127.0.0.1.
"""

import io
import json
import math
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

from hal.virtual.plant.params import load_plant_params
from host_tools.cli import main
from host_tools.studies.sweep_engine import Progress, check_points, dask_client, run_sweep, tasks_of
from host_tools.studies.sweep_point import plant_seed_run_options, run_point
from host_tools.studies.sweep_report import write_report
from host_tools.studies.sweep_spec import SpecError, load_spec, plant_seed_of
from host_tools.studies.sweep_table import JOURNAL, TIMING_COLUMNS, read_rows


def plant_double(seed: int) -> dict:
    """Test double of the issue-13 plant draw: the foot mass within +-20 %, drawn from the seed."""
    u = float(np.random.default_rng(seed).uniform(-1.0, 1.0))
    p = load_plant_params()
    return {"bench_options": {"plant_params": replace(p, foot_mass_kg=p.foot_mass_kg * (1 + 0.2 * u))}}


def failing_double(seed: int) -> dict:
    """A plant draw that fails for one sample (the plant seed of sample 1 of mc seed 7)."""
    if seed == plant_seed_of(7, 1):
        raise RuntimeError("no plant for this seed")
    return plant_double(seed)


def spec_file(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


MC_SPEC = """
[base]
strides = 1
seed = 4

[[grid]]
key = "control.position.kp"
values = [6.0, 8.0]

[monte_carlo]
samples = 2
seed = 7
"""


def _table(out: Path) -> list[dict]:
    rows = pq.read_table(out / "results.parquet").to_pylist()
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def _sweep(spec, out, workers, plant=plant_double, resume=False):
    with dask_client(workers=workers, processes=False) as client:
        return run_sweep(spec, out, client, resume=resume, plant_options=plant, progress=False)


@pytest.fixture(scope="module")
def mc_sweeps(tmp_path_factory):
    """MC_SPEC swept on one worker and on two: {workers: (spec, result, out)}, made once for the tests that read
    them (copy an out before writing into it)."""
    d = tmp_path_factory.mktemp("mc")
    spec = load_spec(spec_file(d, MC_SPEC))
    return {n: (spec, _sweep(spec, d / f"w{n}", n), d / f"w{n}") for n in (1, 2)}


@pytest.mark.parametrize("text, words", [
    ("[base]\nstrides = 0\n", ["strides = 0", "1..100"]),
    ("[base]\nbaud = 300\n", ["baud = 300", "9600..3000000"]),
    ("[base]\nscenario = 'walk'\n", ["scenario = 'walk'", "gait"]),
    ("[base]\ncontroller = 'impedance'\n", ["controller = 'impedance'", "cascade"]),
    ("[base]\ntimeout_s = -1\n", ["timeout_s = -1", "(0, 86400]"]),
    ("[base]\nstride = 2\n", ["no key 'stride'", "strides"]),
    ("[base]\nboard = 'stm32h7'\n", ["board", "stm32h7", "stm32f4"]),
    ("[[grid]]\nkey = 'run.baud'\nvalues = [921600, 1]\n", ["run.baud", "value = 1", "9600..3000000"]),
    ("[[grid]]\nkey = 'run.speed'\nvalues = [1]\n", ["run.speed", "run.strides"]),
    ("[[grid]]\nkey = 'control.position.kq'\nvalues = [1.0]\n", ["control.position.kq", "control.position.kp"]),
    ("[[grid]]\nkey = 'control.position.kp'\n", ["control.position.kp", "values = [...]"]),
    ("[[grid]]\nkey = 'control.position.kp'\nvalues = []\n", ["values = []", "1..10000"]),
    ("[[grid]]\nkey = 'control.position.kp'\nlogspace = [0, 1, 3]\n", ["logspace = [0, 1, 3]", "> 0"]),
    ("[[grid]]\nkey = 'run.seed'\nvalues = [1]\n[[grid]]\nkey = 'run.seed'\nvalues = [2]\n", ["twice"]),
    ("[monte_carlo]\nsamples = -3\n", ["samples = -3", "0..100000"]),
    ("[monte_carlo]\nsamples = 2\nseed = 'x'\n", ["seed = 'x'"]),
    ("[[grid]]\nkey = 'control.position.kp'\nlinspace = [1, 2, 1000]\n[monte_carlo]\nsamples = 1000\n",
     ["1000000 points"]),
    ("[base\n", ["not valid TOML"]),
    ("[[grid]]\nkey = 'run.strides'\nlinspace = [1, 2, 3]\n", ["value = 1.5", "an int in 1..100"]),
])
def test_bad_specs_are_one_line_errors_naming_the_value_and_range(tmp_path, text, words):
    with pytest.raises(SpecError) as e:
        load_spec(spec_file(tmp_path, text))
    msg = str(e.value)
    assert "\n" not in msg and str(tmp_path / "spec.toml") in msg
    for w in words:
        assert w in msg


def test_profile_values_are_checked_before_any_run(tmp_path, capsys):
    spec = spec_file(tmp_path, "[[grid]]\nkey = 'safety.motor_timeout_s'\nvalues = [0.02, -1.0]\n")
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "safety.motor_timeout_s" in err and "-1.0" in err and "(0, 0.1] s" in err
    assert not out.exists()  # nothing ran, nothing written
    # a combination that only fails together names the point
    spec = spec_file(tmp_path, "[[grid]]\nkey = 'rates_hz.control'\nvalues = [1000, 100]\n"
                     "[[grid]]\nkey = 'rates_hz.full_values'\nvalues = [10, 200]\n")
    with pytest.raises(SpecError, match=r"point 3 \(rates_hz.control = 100, rates_hz.full_values = 200\)"):
        check_points(load_spec(spec))


def test_monte_carlo_points_draw_their_plants_like_pafp_run_plant_seed(tmp_path):
    assert plant_seed_run_options(5) == {"plant_seed": 5}  # the option of `pafp run --plant-seed 5`
    spec = load_spec(spec_file(tmp_path, MC_SPEC.replace("values = [6.0, 8.0]", "values = [8.0]")))
    check_points(spec)  # the real draw, once, before any run
    rows = _sweep(spec, tmp_path / "out", 1, plant=plant_seed_run_options).rows
    assert len(rows) == 2 and all(r["status"] in ("ok", "fault") for r in rows)
    assert rows[0]["plant_seed"] != rows[1]["plant_seed"]
    assert rows[0]["rms_error_deg"] != rows[1]["rms_error_deg"]  # two plants, the same firmware


def test_points_and_seeds_come_from_the_spec(tmp_path):
    spec = load_spec(spec_file(tmp_path, MC_SPEC))
    pts = spec.points()
    assert spec.n_points == len(pts) == 4
    assert [p.index for p in pts] == [0, 1, 2, 3]
    assert [dict(p.params)["control.position.kp"] for p in pts] == [6.0, 6.0, 8.0, 8.0]
    assert [p.sample for p in pts] == [0, 1, 0, 1]
    assert [p.plant_seed for p in pts] == [plant_seed_of(7, 0), plant_seed_of(7, 1)] * 2  # same plants per cell
    assert plant_seed_of(7, 0) != plant_seed_of(7, 1) != plant_seed_of(8, 1)
    assert all(p.seed == 4 for p in pts)
    assert load_spec(spec_file(tmp_path, MC_SPEC, "again.toml")).points() == pts


def test_rows_are_the_same_whatever_the_worker_count(tmp_path, mc_sweeps):
    (spec, a, one), (_, b, two) = mc_sweeps[1], mc_sweeps[2]
    shutil.copytree(one, tmp_path / "one")  # the report below writes into it
    assert a.ran == b.ran == 4
    ta, tb = _table(tmp_path / "one"), _table(two)
    assert ta == tb
    assert [r["point"] for r in ta] == [0, 1, 2, 3]
    assert all(r["status"] == "ok" for r in ta)
    # the draws reach the plant: the two samples of a grid point differ, the same sample on both cells too
    assert ta[0]["rms_error_deg"] != ta[1]["rms_error_deg"]
    assert ta[0]["plant_seed"] == ta[2]["plant_seed"]
    # the CSV holds the same table
    csv = pacsv.read_csv(tmp_path / "one" / "results.csv").to_pylist()
    assert [r["rms_error_deg"] for r in csv] == [r["rms_error_deg"] for r in ta]
    assert all(math.isfinite(r[c]) for r in csv for c in TIMING_COLUMNS)
    # the report: each axis against each figure, the Monte Carlo distributions, the worst with their commands
    report = write_report(spec, a.rows, tmp_path / "one").read_text()
    assert "## control.position.kp" in report and "## Monte Carlo" in report
    assert (tmp_path / "one" / "plots" / "monte_carlo.png").stat().st_size > 1000
    worst = max(ta, key=lambda r: r["rms_error_deg"])
    kp, seed = worst["control.position.kp"], worst["plant_seed"]
    assert f"| {worst['point']} | control.position.kp = {kp} | {seed} |" in report
    assert f"pafp sweep {spec.path} --point {worst['point']} " in report


def test_progress_line_has_rate_and_eta():
    stream = io.StringIO()
    bar = Progress(4, stream=stream)
    for k in range(4):
        bar.step(failed=k == 2)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 4 and lines[-1].endswith("ETA 0m00s")
    assert "4/4 points, 1 failed" in lines[-1] and "/s, elapsed" in lines[-1]
    assert "ETA" in lines[0] and "1/4 points, 0 failed" in lines[0]


def test_failing_points_are_rows_with_their_error(tmp_path):
    text = MC_SPEC.replace("values = [6.0, 8.0]", "values = [8.0]") + """
[[grid]]
key = "run.baud"
values = [921600, 115200]
"""
    spec = load_spec(spec_file(tmp_path, text))
    rows = _sweep(spec, tmp_path / "out", 2, plant=failing_double).rows
    by = {(r["run.baud"], r["sample"]): r for r in rows}
    assert len(rows) == 4
    assert by[(921600, 0)]["status"] == "ok" and by[(921600, 0)]["error"] == ""
    ex = by[(921600, 1)]
    assert ex["status"] == "error" and "RuntimeError: no plant for this seed" in ex["error"]
    assert math.isnan(ex["rms_error_deg"])
    fault = by[(115200, 0)]  # a link too slow for 1 kHz: the supervisor latches MOTOR_TIMEOUT
    assert fault["status"] == "fault" and fault["faults"] == "MOTOR_TIMEOUT" and "MOTOR_TIMEOUT" in fault["error"]
    assert math.isnan(fault["rms_error_deg"])  # latched before a stride in RUN: no figure, not a number
    # a timeout
    timed = load_spec(spec_file(tmp_path, "[base]\nstrides = 1\ntimeout_s = 1e-6\n", "timeout.toml"))
    row = run_point(tasks_of(timed)[0])
    assert row["status"] == "timeout" and "timeout" in row["error"]


def test_resume_runs_only_the_missing_points(tmp_path, mc_sweeps):
    spec, full, swept = mc_sweeps[2]
    out = tmp_path / "out"
    shutil.copytree(swept, out)  # a whole sweep on two workers, then cut short below
    whole = _table(out)
    # as if killed after two points: the journal keeps two rows and a torn third line, no tables yet
    lines = (out / JOURNAL).read_text().splitlines()
    (out / JOURNAL).write_text("\n".join([lines[0], lines[2], lines[3][:20]]))
    kept = {json.loads(lines[i])["point"] for i in (0, 2)}
    (out / "results.parquet").unlink()
    assert {r["point"] for r in read_rows(out)} == kept
    with pytest.raises(ValueError, match="--resume"):
        _sweep(spec, out, 1)
    again = _sweep(spec, out, 1, resume=True)
    assert (again.ran, again.skipped) == (2, 2) and full.ran == 4
    assert _table(out) == whole
    # another spec cannot resume into this directory
    other = load_spec(spec_file(tmp_path, MC_SPEC.replace("seed = 7", "seed = 8"), "other.toml"))
    with pytest.raises(ValueError, match="another spec"):
        _sweep(other, out, 1, resume=True)


def test_sweep_command_on_a_local_process_cluster(tmp_path, capsys):
    spec = spec_file(tmp_path, "[base]\nstrides = 1\n[[grid]]\nkey = 'run.baud'\nvalues = [921600, 115200]\n")
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert [(r["point"], r["run.baud"], r["status"]) for r in rows] == [(0, 921600, "ok"), (1, 115200, "fault")]
    report = (out / "report.md").read_text()
    assert "## run.baud" in report and (out / "plots" / "axis_run_baud.png").stat().st_size > 1000
    assert f"pafp sweep {spec} --point 1" in report
    assert main(["sweep", str(spec), "--out", str(out), "--workers", "1", "--quiet"]) == 2  # rows, no --resume
    assert "--resume" in capsys.readouterr().err
    assert main(["sweep", str(spec), "--point", "0", "--out", str(tmp_path / "p0")]) == 0
    summary = json.loads((tmp_path / "p0" / "summary.json").read_text())
    assert summary["tracking"]["truth"]["rms_deg"] == rows[0]["rms_error_deg"]


def test_an_out_that_is_a_file_is_refused_before_any_cluster(tmp_path, capsys):
    spec = spec_file(tmp_path, "[base]\nstrides = 1\n")
    (tmp_path / "f").write_text("x")
    assert main(["sweep", str(spec), "--out", str(tmp_path / "f"), "--workers", "1"]) == 2
    assert "is a file" in capsys.readouterr().err


def _worker_filters() -> list[str]:
    import logging

    return [getattr(f, "__name__", type(f).__name__) for f in logging.getLogger("distributed.worker").filters]


def test_local_process_workers_drop_only_the_lost_heartbeat_error():
    """A worker still finishing a point when a stop closes the scheduler would print the heartbeat's traceback on the
    command's stderr (seen once in the faults stop test); the workers filter that record and no other."""
    import logging

    from host_tools.studies.quiet_workers import HEARTBEAT_LOST, drop_lost_heartbeat

    def record(msg: str) -> logging.LogRecord:
        return logging.LogRecord("distributed.worker", logging.ERROR, __file__, 1, msg, None, None)
    assert not drop_lost_heartbeat(record(HEARTBEAT_LOST + "."))
    assert drop_lost_heartbeat(record("Compute Failed")) and drop_lost_heartbeat(record("Worker is at 95% memory"))
    with dask_client(workers=1) as client:
        assert list(client.run(_worker_filters).values()) == [["drop_lost_heartbeat"]]

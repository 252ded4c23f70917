"""`pafp faults`: the campaign spec, points paired with their fault-free run, the criteria, the report, resume.

Clusters are LocalClusters of worker threads (processes=False) except the one command test (one worker process).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from host_tools.cli import main
from host_tools.commands.faults import columns
from host_tools.studies.fault_point import fault_error_row, run_fault_point
from host_tools.studies.fault_report import check_criteria, hazard_rows, load_criteria
from host_tools.studies.fault_spec import load_fault_spec
from host_tools.studies.sweep_engine import dask_client, run_tasks
from host_tools.studies.sweep_spec import SpecError
from host_tools.studies.sweep_table import TIMING_COLUMNS
from tests.study_clusters import threads_cluster  # noqa: F401 - a fixture
from tests.trace_reader import read_trace

SPEC = """
[campaign]
onsets = [0.0, 0.5]
durations_s = [0.05]
links = ["uart"]
settle_s = 0.1
{extra}
[[scenario]]
name = "suspended"
[[fault]]
name = "motor_replies_lost"
[[fault]]
name = "{second}"
{params}
"""


def spec_file(tmp_path: Path, extra: str = "", second: str = "motor_stall", params: str = "",
              criteria: str | None = None) -> Path:
    if criteria is not None:
        (tmp_path / "criteria.toml").write_text(criteria, encoding="utf-8")
        extra += '\ncriteria = "criteria.toml"'
    p = tmp_path / "spec.toml"
    p.write_text(SPEC.format(extra=extra, second=second, params=params), encoding="utf-8")
    return p


def _run(spec, out: Path, workers: int = 1, resume: bool = False):
    with dask_client(workers=workers, processes=False) as client:
        return run_tasks(spec.points(), run_fault_point, out, client, columns=columns(), digest=spec.digest,
                         error_row=fault_error_row, resume=resume, progress=False)


def test_points_are_the_product_and_can_faults_pair_only_with_can_links(tmp_path):
    spec = load_fault_spec(spec_file(tmp_path))
    assert spec.n_points == 2 * 2 and [p.index for p in spec.points()] == [0, 1, 2, 3]
    p = tmp_path / "can.toml"
    p.write_text('[campaign]\nlinks = ["uart", "can-servo"]\n[[fault]]\nname = "can_bus_off"\n'
                 '[[fault]]\nname = "imu_silent"\n', encoding="utf-8")
    pts = load_fault_spec(p).points()
    assert [(q.fault, q.link) for q in pts] == [("can_bus_off", "can-servo"), ("imu_silent", "uart"),
                                                ("imu_silent", "can-servo")]


@pytest.mark.parametrize("text, match", [
    ('[campaign]\nonsets = [1.0]\n[[fault]]\nname = "imu_silent"\n', r"onsets = 1.0 out of range"),
    ('[campaign]\ndurations_s = [0]\n[[fault]]\nname = "imu_silent"\n', r"durations_s = 0 out of range"),
    ('[[fault]]\nname = "imu_melted"\n', r"\[\[fault\]\] 0 name = 'imu_melted'"),
    ('[[fault]]\nname = "imu_corrupt"\nbit_error_rate = 3\n', r"bit_error_rate = 3 out of range"),
    ('[campaign]\nlinks = ["rs485"]\n[[fault]]\nname = "imu_silent"\n', r"links = 'rs485'"),
    ('[campaign]\nspeed = 1\n[[fault]]\nname = "imu_silent"\n', r"key 'speed' unknown"),
    ('[campaign]\nlinks = ["uart"]\n[[fault]]\nname = "can_bus_off"\n', r"0 points"),
    ('[[scenario]]\nname = "walk"\nbody_mass_kg = 0\n[[fault]]\nname = "imu_silent"\n', r"body_mass_kg = 0"),
])
def test_a_bad_spec_is_one_line_naming_the_value(tmp_path, text, match, capsys):
    p = tmp_path / "bad.toml"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(SpecError, match=match):
        load_fault_spec(p)
    assert main(["faults", str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pafp faults: fault spec")
    assert not (tmp_path / "o").exists()


def test_bad_criteria_are_refused(tmp_path):
    for text, match in (("[default]\nexcursion_deg = -1\n", "excursion_deg = -1"),
                        ("[default]\nspeed = 1\n", "key 'speed' unknown"),
                        ("[fault.nope]\nexcursion_deg = 1\n", r"\[fault.nope\] names no injector")):
        (tmp_path / "c.toml").write_text(text, encoding="utf-8")
        with pytest.raises(ValueError, match=match):
            load_criteria(tmp_path / "c.toml")
    (tmp_path / "c.toml").write_text("[default]\nexcursion_deg = 5\n[fault.encoder_glitch]\nexcursion_deg = 9\n",
                                     encoding="utf-8")
    c = load_criteria(tmp_path / "c.toml")
    assert c["encoder_glitch"]["excursion_deg"] == 9 and c["imu_silent"]["excursion_deg"] == 5


def test_a_point_is_paired_with_its_fault_free_run(tmp_path):
    spec = load_fault_spec(spec_file(tmp_path))
    lost, stall = spec.points()[0], spec.points()[2]
    row = run_fault_point(lost)
    assert row["status"] == "ok" and row["fired"] and row["reason"] == "MOTOR_TIMEOUT"
    assert 20.0 <= row["detect_ms"] <= 23.0 and row["detect_ms"] < row["safe_ms"] < row["detect_ms"] + 1.0
    assert row["excursion_deg"] < 1.0 and row["fired_first_s"] >= row["onset_s"]
    g = run_fault_point(stall)  # a jam: encoder and motor agree, no check catches it
    assert g["status"] == "ok" and not g["detected"] and math.isnan(g["safe_ms"])
    assert g["excursion_deg"] > 1.0 and g["torque_nm"] > 5.0 and g["cmd_peak_a"] > 0
    glitch = load_fault_spec(spec_file(tmp_path, second="encoder_glitch", params="counts = 40")).points()[2]
    e = run_fault_point(glitch)  # a 3.6 deg jump of the count: caught by the encoder's plausibility check
    assert e["reason"] == "MOTOR_ENCODER_DISAGREEMENT" and e["detect_ms"] < 2.0 and e["excursion_deg"] < 1.0


def test_a_fault_that_never_fires_is_an_error_not_a_pass(tmp_path):
    spec = load_fault_spec(spec_file(tmp_path, second="encoder_glitch", params="counts = 0"))  # changes nothing
    row = run_fault_point(spec.points()[2])
    assert row["status"] == "not_fired" and "never fired" in row["error"]


@pytest.fixture(scope="module")
def one_worker(tmp_path_factory):
    """The default spec_file's campaign on one worker: (its spec, its rows), shared by the tests that read them."""
    tmp_path = tmp_path_factory.mktemp("one_worker")
    spec = load_fault_spec(spec_file(tmp_path))
    return spec, _run(spec, tmp_path / "a", workers=1).rows


def test_same_table_on_one_or_two_workers_and_after_a_resume(tmp_path, one_worker):
    spec, a = one_worker
    b = _run(spec, tmp_path / "b", workers=2).rows

    def strip(rows):  # NaN as None, so that equal rows compare equal
        return [{k: None if isinstance(v, float) and math.isnan(v) else v for k, v in r.items()
                 if k not in TIMING_COLUMNS} for r in rows]
    assert strip(a) == strip(b) and len(a) == 4
    journal = tmp_path / "b" / "rows.jsonl"
    lines = journal.read_text(encoding="utf-8").splitlines()
    journal.write_text("\n".join(lines[:2]) + "\n" + lines[2][:17], encoding="utf-8")  # killed mid-line
    c = _run(spec, tmp_path / "b", workers=1, resume=True)
    assert c.ran == 2 and c.skipped == 2 and strip(c.rows) == strip(a)


def test_criteria_and_hazard_table(one_worker):
    spec, rows = one_worker
    strict = {name: {"excursion_deg": 0.5, "time_to_safe_ms": 10.0} for name in load_criteria(spec.criteria)}
    fails = check_criteria(rows, strict)
    assert {(f.fault, f.criterion) for f in fails} == {("motor_replies_lost", "time_to_safe_ms"),
                                                       ("motor_stall", "excursion_deg")}
    lenient = {name: {"excursion_deg": 90.0, "time_to_safe_ms": 100.0} for name in strict}
    assert check_criteria(rows, lenient) == []
    table = {h["fault"]: h for h in hazard_rows(rows)}
    assert table["motor_replies_lost"]["detection"] == "MOTOR_TIMEOUT 2/2"
    assert table["motor_stall"]["detection"] == "undetected 2/2"
    assert table["motor_stall"]["control"].startswith("none")


def _row(point: int, safe: str, shipped: str, excursion: float) -> dict:
    return {"point": point, "fault": "motor_stall", "safe_state": safe, "profile_safe_state": shipped,
            "status": "ok", "detected": True, "excursion_deg": excursion}


def test_the_verdict_judges_the_shipped_safe_state_and_compares_the_others():
    limit = {"motor_stall": {"excursion_deg": 5.0}}
    rows = [_row(0, "graded", "graded", 4.0), _row(1, "brake", "graded", 40.0), _row(2, "graded", "graded", 3.0)]
    fails = check_criteria(rows, limit)
    assert [(f.safe_state, f.judged, f.point, f.value) for f in fails] == [("brake", False, 1, 40.0)]
    rows[2]["excursion_deg"] = 6.0  # the shipped state over its limit: judged
    fails = check_criteria(rows, limit)
    assert [(f.safe_state, f.judged, f.point) for f in fails] == [("graded", True, 2), ("brake", False, 1)]
    assert "not met by motor_stall (graded): 6 deg at point 2" in fails[0].line(load_fault_spec(
        Path(__file__).resolve().parents[1] / "profiles" / "faults" / "safe_states.toml"))
    what_if = [_row(0, "brake", "graded", 40.0), _row(1, "short", "graded", 1.0)]  # none shipped: judged whole
    assert [(f.safe_state, f.judged) for f in check_criteria(what_if, limit)] == [("brake", True)]
    one = [_row(0, "graded", "graded", 6.0)]  # one safe state: no name in the line
    assert [(f.safe_state, f.judged) for f in check_criteria(one, limit)] == [("", True)]


@pytest.mark.usefixtures("threads_cluster")  # the command's cluster of processes: tests/test_contract_studies.py
def test_the_command_writes_the_table_and_report_and_exits_1_per_failed_criterion(tmp_path, capsys):
    crit = "[default]\nexcursion_deg = 0.5\ntime_to_safe_ms = 100\n"
    spec = spec_file(tmp_path, criteria=crit)
    out = tmp_path / "out"
    assert main(["faults", str(spec), "--out", str(out), "--workers", "1", "--quiet"]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("pafp faults: criterion")]
    assert len(err) == 1 and "excursion_deg <= 0.5 deg not met by motor_stall" in err[0] and "--point" in err[0]
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "## Hazard table" in report and "| motor_stall |" in report
    assert (out / "plots" / "heatmap.png").stat().st_size > 1000 and (out / "results.parquet").is_file()
    assert len(list((out / "plots").glob("trace_point_*.png"))) == 3
    tripped = 0
    for png in (out / "plots").glob("trace_point_*.png"):  # each worst point's Perfetto trace beside its plot
        tr = read_trace(png.with_suffix(".pftrace"))
        safety = [i.name for i in tr.instants_on("safety")]
        trips = [n for n in safety if n.startswith("fault trip")]
        assert tr.instants_on("fault injector") and safety.count("safe command on the wire") == len(trips)
        tripped += len(trips)
    assert tripped >= 1  # of 2 stalls and 2 lost replies, 3 are plotted: a lost reply's MOTOR_TIMEOUT among them
    assert main(["faults", str(spec), "--out", str(out), "--workers", "1", "--quiet"]) == 2  # rows, no --resume
    (tmp_path / "criteria.toml").write_text("[default]\nexcursion_deg = 90\n", encoding="utf-8")
    assert main(["faults", str(spec), "--out", str(tmp_path / "ok"), "--workers", "1", "--quiet",
                 "--no-traces"]) == 0
    assert main(["faults", str(spec), "--point", "0", "--out", str(tmp_path / "p0")]) == 0
    s = json.loads((tmp_path / "p0" / "summary.json").read_text(encoding="utf-8"))
    assert s["fault"]["fired"] and s["fault"]["name"] == "motor_replies_lost" and s["faults"] == ["MOTOR_TIMEOUT"]

"""The input/output/interrupt contract held by the study commands (`pafp faults`, `design`) and `pafp fit` (issue 35).

A spec of the wrong shape is one line naming the file, the key and what was expected (exit 2); an --out that
cannot take the outputs is refused before a cluster starts; a disk that fills during a campaign is exit 74 with
a journal of whole rows; a stop signal ends a campaign with a report of what finished, "N of M finished" and the
--resume hint; `--point N` writes the full outputs of `pafp run`, trace.pftrace too; criteria that judge nothing are
refused. Campaigns are one fault at one or two onsets, on a LocalCluster of threads where the command's own
cluster is not what is tested.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from host_tools.cli import main
from host_tools.studies import sweep_table
from tests.study_clusters import no_cluster, threads_cluster  # noqa: F401 - fixtures

PAFP = [sys.executable, "-m", "host_tools"]
ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = """[campaign]
onsets = {onsets}
durations_s = [0.05]
links = ["uart"]
settle_s = 0.1
{extra}
[[scenario]]
name = "suspended"
[[fault]]
name = "motor_replies_lost"
"""


def _campaign(tmp_path: Path, onsets: list[float], extra: str = "") -> Path:
    p = tmp_path / "campaign.toml"
    p.write_text(CAMPAIGN.format(onsets=onsets, extra=extra), encoding="utf-8")
    return p


def _one_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("pafp ")]
    assert "Traceback" not in err and len(lines) == 1, err
    return lines[0]


# ---- specs read back: the shape of every table ------------------------------------------------------------

@pytest.mark.usefixtures("no_cluster")
@pytest.mark.parametrize("command, text, key, expected", [
    ("faults", '[[campaign]]\nseed = 0\n[[fault]]\nname = "imu_silent"\n', "campaign", "a table, written [campaign]"),
    ("faults", '[scenario]\nname = "walk"\n[[fault]]\nname = "imu_silent"\n', "scenario",
     "an array of tables, each written [[scenario]]"),
    ("faults", 'fault = "imu_silent"\n', "fault", "an array of tables, each written [[fault]]"),
    ("faults", 'scenario = [1, 2]\n[[fault]]\nname = "imu_silent"\n', "scenario",
     "an array of tables, each written [[scenario]]"),
    ("design", "[[search]]\nstrides = 1\n", "search", "a table, written [search]"),
    ("design", "belt = 3\n", "belt", "an array of tables, each written [[belt]]"),
])
def test_a_spec_table_of_the_wrong_shape_is_one_line_naming_file_key_and_shape(tmp_path, capsys,
                                                                                command, text, key, expected):
    spec = tmp_path / "spec.toml"
    spec.write_text(text, encoding="utf-8")
    assert main([command, str(spec), "--out", str(tmp_path / "out")]) == 2
    line = _one_line(capsys.readouterr().err)
    assert str(spec) in line
    if expected is not None:
        assert f"key {key!r}" in line and line.endswith(f"expected {expected}")
    assert not (tmp_path / "out").exists()


# ---- outputs checked before the work -----------------------------------------------------------------------

@pytest.mark.usefixtures("no_cluster")
@pytest.mark.parametrize("command", ["faults", "design"])
def test_an_out_below_a_file_is_refused_before_a_cluster_starts(tmp_path, capsys, command):
    (tmp_path / "afile").write_text("x")
    spec = _campaign(tmp_path, [0.0]) if command == "faults" else ROOT / "profiles" / "designs" / "adult.toml"
    assert main([command, str(spec), "--out", str(tmp_path / "afile" / "out")]) == 2
    assert "is not a directory" in _one_line(capsys.readouterr().err)


@pytest.mark.usefixtures("no_cluster")
@pytest.mark.parametrize("command", ["faults", "design"])
def test_less_than_a_mebibyte_free_is_refused_before_a_cluster_starts(tmp_path, capsys, monkeypatch,
                                                                       command):
    real = os.statvfs
    monkeypatch.setattr(os, "statvfs", lambda p: os.statvfs_result(tuple(real(p))[:3] + (100, 100)
                                                                   + tuple(real(p))[5:]))
    spec = _campaign(tmp_path, [0.0]) if command == "faults" else ROOT / "profiles" / "designs" / "adult.toml"
    assert main([command, str(spec), "--out", str(tmp_path / "out")]) == 2
    assert "1 MiB" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "out").exists()


# ---- a disk that fills during a campaign -------------------------------------------------------------------

@pytest.mark.usefixtures("threads_cluster")
def test_a_disk_that_fills_while_a_row_is_appended_is_exit_74_and_the_journal_keeps_whole_rows(
        tmp_path, capsys, monkeypatch):
    spec, out = _campaign(tmp_path, [0.0, 0.5]), tmp_path / "out"
    real_write = os.write
    appended = []

    def filling(fd, data):  # the second row: half of it reaches the disk, then the disk is full
        if Path(f"/proc/self/fd/{fd}").resolve() == (out / sweep_table.JOURNAL).resolve():
            appended.append(len(data))
            if len(appended) == 2:
                real_write(fd, bytes(data[:len(data) // 2]))
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(fd, data)
    monkeypatch.setattr(sweep_table.os, "write", filling)
    assert main(["faults", str(spec), "--out", str(out), "--quiet"]) == 74
    line = _one_line(capsys.readouterr().err)
    assert f"cannot write {out / sweep_table.JOURNAL}: No space left on device" in line and "--resume" in line
    text = (out / sweep_table.JOURNAL).read_text()  # the first row whole, nothing of the second (--resume reruns it)
    assert text.endswith("\n") and [json.loads(ln)["point"] for ln in text.splitlines()] in ([0], [1])


def test_a_journal_torn_by_a_kill_is_cut_to_its_whole_rows_before_the_next_row(tmp_path):
    out = tmp_path / "out"
    table = sweep_table.ResultsTable(out, ["point", "x"], "d", 3, False)
    table.add({"point": 0, "x": 1})
    table.close()
    with open(out / sweep_table.JOURNAL, "a") as f:
        f.write('{"point": 1, "x"')  # what a kill mid-write leaves
    table = sweep_table.ResultsTable(out, ["point", "x"], "d", 3, True)
    table.add({"point": 2, "x": 3})
    table.close()
    assert [json.loads(ln) for ln in (out / sweep_table.JOURNAL).read_text().splitlines()] == [
        {"point": 0, "x": 1}, {"point": 2, "x": 3}]


# ---- a stop signal -----------------------------------------------------------------------------------------

POINTS = 48


def test_faults_stopped_by_a_signal_reports_what_finished_and_how_to_resume(tmp_path, sig=signal.SIGTERM):
    """SIGTERM (SIGINT and SIGHUP take the same path: host_tools/studies/interrupt.py; the sweep's test sends a
    Ctrl-C to the whole process group)."""
    # 48 points: on the compiled build 12 had all finished between the first journal row and the signal
    spec, out = _campaign(tmp_path, [round(k / POINTS, 4) for k in range(POINTS)]), tmp_path / "out"
    proc = subprocess.Popen([*PAFP, "faults", str(spec), "--out", str(out), "--workers", "1", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            start_new_session=True)
    journal = out / sweep_table.JOURNAL
    deadline = time.monotonic() + 180
    while proc.poll() is None and time.monotonic() < deadline and not (journal.exists() and journal.read_text()):
        time.sleep(0.1)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, err
    assert "leaked semaphore" not in err and "Traceback" not in err, err
    n = len(journal.read_text().splitlines())
    assert 1 <= n < POINTS
    assert f"pafp faults: stopped by {sig.name} after " in err and f"{n} of {POINTS} points finished, kept in {out}" \
        in err
    assert "`--resume` runs the rest" in err
    report = (out / "report.md").read_text()
    assert f"**Interrupted** by {sig.name}: {n} of {POINTS} points finished" in report and "--resume" in report


# ---- one point with the full outputs; criteria ------------------------------------------------------------

def test_faults_point_writes_the_outputs_of_pafp_run_with_its_trace(tmp_path, capsys):
    out = tmp_path / "point"
    assert main(["faults", str(_campaign(tmp_path, [0.25])), "--point", "0", "--out", str(out)]) == 0
    assert "trace.pftrace" in capsys.readouterr().out
    from tests.trace_reader import read_trace

    assert read_trace(out / "trace.pftrace").slices
    summary = json.loads((out / "summary.json").read_text())
    assert summary["fault"]["name"] == "motor_replies_lost" and summary["fault"]["count"] > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign.toml", "point"]  # nothing staged left


@pytest.mark.usefixtures("no_cluster")
@pytest.mark.parametrize("criteria", ["", "[default]\n", "[fault.imu_silent]\nexcursion_deg = 1.0\n"])
def test_criteria_that_judge_nothing_are_refused(tmp_path, capsys, criteria):
    (tmp_path / "criteria.toml").write_text(criteria, encoding="utf-8")
    spec = _campaign(tmp_path, [0.0], 'criteria = "criteria.toml"')
    assert main(["faults", str(spec), "--out", str(tmp_path / "out")]) == 2
    line = _one_line(capsys.readouterr().err)
    assert str(tmp_path / "criteria.toml") in line and "no criterion for" in line and "excursion_deg" in line


# ---- pafp fit under a stop signal ---------------------------------------------------------------------------

def test_fit_stopped_by_sigterm_says_so_and_leaves_no_staging_directory(tmp_path, capsys):
    fw = tmp_path / "fw.toml"
    fw.write_text((ROOT / "profiles" / "firmware.toml").read_text() + '\n[controller]\nname = "sysid"\nhold_s = '
                  '0.5\nsweep_deg = 8.0\nsweep_deg_s = 16.0\nchirp_s = 1.0\nprbs_s = 0.5\n')
    run = tmp_path / "run"
    assert main(["run", "--experiment", "sysid", "--quiet", "--no-plot", "--no-trace", "--profile", str(fw),
                 "--out", str(run)]) == 0
    capsys.readouterr()
    proc = subprocess.Popen([*PAFP, "fit", str(run), "--no-plot"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)
    assert proc.stdout is not None
    line = proc.stdout.readline()  # "pafp fit: ... fitting N parameters -> ..." once the inputs are checked
    assert line.startswith("pafp fit: "), line + proc.communicate()[1]
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "pafp fit: stopped by SIGTERM after " in err and "nothing written" in err and "Traceback" not in err
    assert not (run / "fit").exists() and [p.name for p in run.iterdir() if p.name.endswith(".partial")] == []

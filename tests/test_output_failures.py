"""Outputs that cannot be written (issue 25, item 4) and work that is interrupted (item 5).

Every output path is checked before the work (exit 2, one line, nothing written); a write that fails during
the work is one line naming the file, exit 74 (EX_IOERR), with no partial file and no temporary left behind.

How a failing disk is made here, without privileges: a full filesystem is an ``os.statvfs`` that reports
no free block (the check reads nothing else); a disk that fills during the work is a child process whose
file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored) makes every write past it fail with EFBIG, as a full disk
makes it fail with ENOSPC; a read-only directory is chmod 0o555, or, for root (whom chmod does not stop), a
tmpfs mounted read-only, skipped where mount is not allowed. With mount allowed, one run fills a real tmpfs.
"""

from __future__ import annotations

import errno
import json
import os
import resource
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from host_tools import outdir
from host_tools.cli import main
from host_tools.outdir import EXIT_WRITE_FAILED, clean_stale
from host_tools.studies.sweep_table import JOURNAL
from tests.study_clusters import threads_cluster  # noqa: F401 - a fixture
from tests.test_serial_run import is_graded_stop
from tests.trace_reader import read_trace

PAFP = [sys.executable, "-m", "host_tools"]
ROOT = Path(__file__).resolve().parents[1]


def _file_size_limit(limit: int):
    def pre() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return pre


def _pafp_limited(limit: int, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """pafp in a child process whose writes fail past `limit` bytes per file."""
    return subprocess.run([*PAFP, *args], preexec_fn=_file_size_limit(limit), capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def _one_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("pafp ") and not ln.endswith(" ...")]
    assert "Traceback" not in err and len(lines) == 1, err
    return lines[0]


def _leftovers(directory: Path) -> list[str]:
    """Temporary and staged names under directory (none may survive a failed write)."""
    return sorted(str(p.relative_to(directory)) for p in directory.rglob("*")
                  if p.name.endswith((".tmp", ".partial", ".old")) or ".tmp." in p.name)


@pytest.fixture
def full_disk(monkeypatch):
    """Every filesystem reports no free block."""
    real = os.statvfs

    def statvfs(path):
        st = tuple(real(path))
        return os.statvfs_result(st[:3] + (0, 0) + st[5:])
    monkeypatch.setattr(os, "statvfs", statvfs)


@pytest.fixture
def read_only(tmp_path):
    """A directory this process cannot write into."""
    d = tmp_path / "ro"
    d.mkdir()
    if os.geteuid() != 0:
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    yield from _tmpfs(d, "ro,size=64k", "root, and no mount: chmod does not stop root's writes")


@pytest.fixture
def small_tmpfs(tmp_path):
    """A 2 MiB tmpfs (root with mount allowed only)."""
    d = tmp_path / "disk"
    d.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    yield from _tmpfs(d, "size=2m", "mounting a tmpfs needs mount")


def _tmpfs(d: Path, options: str, why_not: str):
    """Mount a tmpfs with `options` on d for the test (skipped with why_not if mount fails)."""
    if subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(d)], capture_output=True).returncode:
        pytest.skip(why_not)
    try:
        yield d
    finally:
        subprocess.run(["umount", str(d)], check=False)


def _unwritable(tmp_path: Path, request, kind: str, name: str) -> Path:
    """A directory path that cannot take outputs: an existing file, below a read-only directory, on a full disk."""
    if kind == "file":
        path = tmp_path / name
        path.write_text("not a directory")
        return path
    if kind == "read-only":
        return request.getfixturevalue("read_only") / name
    request.getfixturevalue("full_disk")
    return tmp_path / name


# ---- pafp run (virtual) --------------------------------------------------------------------------------------

def test_a_run_on_a_disk_that_fills_is_one_line_exit_74_and_out_keeps_the_previous_run(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "--quiet", "--strides", "1", "--seed", "5", "--no-plot", "--no-trace", "--out", str(out)]) \
        in (0, 1)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    r = _pafp_limited(150_000, "run", "--quiet", "--strides", "6", "--no-plot", "--no-trace", "--out", str(out))
    assert r.returncode == EXIT_WRITE_FAILED, r.stderr
    line = _one_line(r.stderr)
    assert "cannot write" in line and "telemetry.csv" in line and os.strerror(errno.EFBIG) in line, line
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # the previous run, untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging directory left


def test_a_run_filling_a_real_tmpfs_leaves_nothing(small_tmpfs):
    out = small_tmpfs / "run"
    r = subprocess.run([*PAFP, "run", "--quiet", "--strides", "20", "--out", str(out)], capture_output=True,
                       text=True, timeout=300, cwd=ROOT)
    assert r.returncode == EXIT_WRITE_FAILED, r.stderr
    assert os.strerror(errno.ENOSPC) in _one_line(r.stderr)
    assert list(small_tmpfs.iterdir()) == []


def test_a_run_on_a_full_disk_is_refused_before_it_starts(tmp_path, capsys, full_disk):
    code = main(["run", "--quiet", "--strides", "1", "--out", str(tmp_path / "run")])
    _, err = capsys.readouterr()
    assert code == 2 and "bytes free" in _one_line(err) and str(tmp_path / "run") in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kind", ["file", "read-only", "full"])
def test_a_capture_directory_that_cannot_be_written_is_refused_before_the_run(tmp_path, capsys, request, kind):
    capture = _unwritable(tmp_path, request, kind, "cap")
    code = main(["run", "--quiet", "--strides", "1", "--out", str(tmp_path / "run"), "--capture", str(capture)])
    _, err = capsys.readouterr()
    assert code == 2 and "--capture" in _one_line(err) and str(capture) in err
    assert not (tmp_path / "run").exists() and _leftovers(tmp_path) == []


def test_a_capture_inside_out_is_published_with_the_run(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "--quiet", "--strides", "1", "--no-plot", "--no-trace", "--out", str(out), "--capture",
                 str(out / "capture")])
    capsys.readouterr()
    assert code in (0, 1)
    assert (out / "summary.json").exists() and (out / "capture" / "index.csv").stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


@pytest.fixture(scope="module")
def sysid_run(tmp_path_factory) -> Path:
    """A recorded identification experiment of about 4 s (for `pafp fit` and `pafp replay`)."""
    d = tmp_path_factory.mktemp("sysid")
    fw = d / "fw.toml"
    fw.write_text((ROOT / "profiles" / "firmware.toml").read_text() + '\n[controller]\nname = "sysid"\nhold_s = '
                  '0.5\nsweep_deg = 8.0\nsweep_deg_s = 16.0\nchirp_s = 1.0\nprbs_s = 0.5\n')
    assert main(["run", "--experiment", "sysid", "--quiet", "--no-plot", "--no-trace", "--profile", str(fw),
                 "--out", str(d / "run")]) == 0
    return d / "run"


def _work(command: str, src: Path) -> list[str]:
    return {"run": ["run", "--strides", "1", "--quiet", "--no-trace", "--no-plot"],
            # one parameter: these tests are about the outputs, and the full fit takes three times as long
            "fit": ["fit", str(src), "--no-plot", "--params", "foot_damping_nm_s_per_rad"],
            "replay": ["replay", str(src)]}[command]


@pytest.mark.parametrize("command", ["run", "fit", "replay"])
def test_an_out_taken_by_other_files_during_the_work_keeps_the_outputs_beside_it(tmp_path, capsys, monkeypatch,
                                                                              command, request):
    """Files that are not a run's put into --out while the work runs: one line, exit 74, nothing replaced, and the
    outputs kept in a directory the line names (never removed by the next run's clean-up)."""
    src = request.getfixturevalue("sysid_run") if command != "run" else tmp_path
    out = tmp_path / "out"
    publish = outdir.RunDir.publish

    def intruder(self):  # another program writes into --out just before the outputs are published
        out.mkdir(exist_ok=True)
        (out / "notes.txt").write_text("mine")
        publish(self)

    monkeypatch.setattr(outdir.RunDir, "publish", intruder)
    code = main([*_work(command, src), "--out", str(out)])
    _, err = capsys.readouterr()
    line = _one_line(err)
    assert code == EXIT_WRITE_FAILED and "notes.txt" in line and "kept in" in line, err
    kept = Path(line.split("kept in ")[1].split()[0])
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert (kept / "summary.json").exists() and kept.parent == tmp_path
    assert clean_stale(out) == [] and kept.exists()


@pytest.mark.parametrize("command", ["fit", "replay"])
def test_a_fit_or_replay_whose_disk_fills_is_one_line_exit_74_and_publishes_nothing(tmp_path, capsys, sysid_run,
                                                                                   atomic_writes_fill, command):
    out = tmp_path / "out"
    code = main([*_work(command, sysid_run), "--out", str(out)])
    _, err = capsys.readouterr()
    line = _one_line(err)
    assert code == EXIT_WRITE_FAILED and "cannot write" in line and os.strerror(errno.ENOSPC) in line, err
    assert list(tmp_path.iterdir()) == []


# ---- serial mode ------------------------------------------------------------------------------------------------

SIM = ["--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--no-realtime", "--quiet"]


def test_a_serial_run_on_a_full_disk_exits_2_before_any_port_and_leaves_nothing(tmp_path, capsys, full_disk):
    code = main(["run", *SIM, "--duration", "1", "--out", str(tmp_path / "run")])
    stdout, err = capsys.readouterr()
    assert code == 2 and "bytes free" in _one_line(err) and stdout == ""
    assert list(tmp_path.iterdir()) == []


def test_a_serial_capture_onto_a_file_is_refused_before_any_port(tmp_path, capsys):
    (tmp_path / "cap").write_text("x")
    code = main(["run", *SIM, "--duration", "1", "--out", str(tmp_path / "run"), "--capture", str(tmp_path / "cap")])
    stdout, err = capsys.readouterr()
    assert code == 2 and "--capture" in _one_line(err) and stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap"]


def test_a_serial_run_whose_disk_fills_stops_the_motor_first_then_one_line_exit_74(tmp_path):
    out = tmp_path / "run"
    # no trace: written at the end, it would fill the disk first on a machine too loaded for 40 kB of telemetry in 3 s
    r = _pafp_limited(40_000, "run", *SIM, "--duration", "3", "--no-trace", "--out", str(out), timeout=120)
    assert r.returncode == EXIT_WRITE_FAILED, r.stderr
    line = _one_line(r.stderr)
    # the limit is per file: telemetry.bin or telemetry.csv reaches it first, as the writes' buffers fill (both seen)
    failed = [name for name in ("telemetry.bin", "telemetry.csv") if f"{out / name}:" in line]
    assert "cannot write" in line and len(failed) == 1, line
    assert "the motor was stopped first (the safe frames on the wire)" in line, line
    assert not (out / failed[0]).exists()  # the partial file is removed
    assert _leftovers(tmp_path) == []


def test_a_virtual_run_whose_capture_fills_the_disk_is_one_line_exit_74(tmp_path):
    r = _pafp_limited(150_000, "run", "--quiet", "--strides", "6", "--no-plot", "--no-trace",
                      "--capture", str(tmp_path / "cap"), "--out", str(tmp_path / "run"))
    assert r.returncode == EXIT_WRITE_FAILED, r.stderr
    line = _one_line(r.stderr)
    assert f"cannot write {tmp_path / 'cap'}" in line and os.strerror(errno.EFBIG) in line, line
    assert not (tmp_path / "run").exists() and _leftovers(tmp_path) == []


class _Filling:
    """A file on a disk that fills after `room` bytes."""

    def __init__(self, f, room: list[int]) -> None:
        self.f, self.room = f, room

    def write(self, data: bytes) -> int:
        if len(data) > self.room[0]:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.room[0] -= len(data)
        return self.f.write(data)

    def __getattr__(self, name: str):
        return getattr(self.f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.f.close()


@pytest.fixture
def atomic_writes_fill(monkeypatch):
    """Files written whole (outdir.write_atomic, save_figure) find the disk full once `room[0]` bytes are used."""
    room = [0]
    real = os.fdopen
    monkeypatch.setattr(os, "fdopen", lambda fd, *a, **k: _Filling(real(fd, *a, **k), room))
    return room


def test_a_serial_capture_that_fills_the_disk_stops_the_motor_writes_the_run_and_exits_74(tmp_path, capsys,
                                                                                          monkeypatch):
    from host_tools.wire_capture import WireCapture

    room = [20_000]  # bytes the capture's port files may take, together
    real = WireCapture._file
    monkeypatch.setattr(WireCapture, "_file", lambda self, name: _Filling(real(self, name), room))
    out, cap = tmp_path / "run", tmp_path / "cap"
    code = main(["run", *SIM, "--duration", "2", "--out", str(out), "--capture", str(cap), "--no-plot"])
    _, err = capsys.readouterr()
    assert code == EXIT_WRITE_FAILED, err
    line = _one_line(err)
    assert f"cannot write {cap}/" in line and os.strerror(errno.ENOSPC) in line and "stopped first" in line, line
    s = json.loads((out / "summary.json").read_text())
    stop = s["stop"]
    assert stop["reason"] == "exception" and stop["safe_on_wire"] is True
    assert is_graded_stop(stop["safe_frames"][-1], bool(s["faults"])), (stop, s["faults"])


def test_an_emulator_whose_capture_fills_the_disk_stops_serving_with_one_line_exit_74(tmp_path, capsys,
                                                                                    monkeypatch):
    from host_tools.wire_capture import WireCapture

    room = [400]  # the IMU streams 100 RVC frames of 19 bytes a second
    real = WireCapture._file
    monkeypatch.setattr(WireCapture, "_file", lambda self, name: _Filling(real(self, name), room))
    cap = tmp_path / "cap"
    code = main(["emulate", "imu", "--pty", "--duration", "5", "--capture", str(cap)])
    _, err = capsys.readouterr()
    assert code == EXIT_WRITE_FAILED, err
    assert f"cannot write {cap / 'imu.tx.bin'}: {os.strerror(errno.ENOSPC)}" in _one_line(err)


def test_an_emulator_capture_on_a_full_disk_is_refused_before_serving(tmp_path, capsys, full_disk):
    code = main(["emulate", "imu", "--pty", "--duration", "1", "--capture", str(tmp_path / "cap")])
    stdout, err = capsys.readouterr()
    assert code == 2 and "--capture" in _one_line(err) and stdout == ""
    assert list(tmp_path.iterdir()) == []


# ---- pafp bench ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["file", "read-only", "full"])
def test_bench_out_that_cannot_be_written_is_refused_before_any_test(tmp_path, capsys, request, kind):
    out = _unwritable(tmp_path, request, kind, "bench")
    code = main(["bench", "uncontrolled", "--quick", "--out", str(out)])
    stdout, err = capsys.readouterr()
    assert code == 2 and "--out" in _one_line(err) and stdout == ""
    assert "uncontrolled ..." not in err  # refused before the test ran


def test_bench_on_a_disk_that_fills_leaves_no_empty_png_and_exits_74(tmp_path):
    out = tmp_path / "bench"
    r = _pafp_limited(50_000, "bench", "uncontrolled", "--quick", "--out", str(out))
    assert r.returncode == EXIT_WRITE_FAILED, r.stderr
    assert "uncontrolled.png" in _one_line(r.stderr)
    assert "| uncontrolled [level-com] |" in r.stdout  # the comparison table is printed all the same
    assert [p.name for p in out.iterdir()] == []  # no 0-byte PNG, no temporary


# ---- pafp tune and sweep: --out checked before the work --------------------------------------------------------

def _spec(tmp_path: Path, text: str = "[base]\nstrides = 1\n") -> Path:
    spec = tmp_path / "s.toml"
    spec.write_text(text)
    return spec


@pytest.mark.parametrize("kind", ["file", "read-only", "full"])
def test_tune_and_sweep_point_refuse_an_unwritable_out_before_the_work(tmp_path, capsys, request, kind):
    out = _unwritable(tmp_path, request, kind, "out")
    t0 = time.perf_counter()
    assert main(["tune", "--budget", "5", "--strides", "1", "--workers", "1", "--quiet", "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert "--out" in _one_line(err) and "pafp tune: budget" not in stdout  # before the cluster and the search
    assert main(["sweep", str(_spec(tmp_path)), "--point", "0", "--out", str(out)]) == 2
    stdout, err = capsys.readouterr()
    assert "--out" in _one_line(err) and "pafp sweep: point" not in stdout
    assert time.perf_counter() - t0 < 60


def test_sweep_point_writes_the_files_docs_sweeps_md_lists(tmp_path, capsys):
    out = tmp_path / "p0"
    assert main(["sweep", str(_spec(tmp_path)), "--point", "0", "--out", str(out)]) == 0
    names = {p.name for p in out.iterdir()}
    assert {"tracking.png", "summary.json", "report.md", "trace.pftrace", "telemetry.bin", "telemetry.csv"} <= names
    assert read_trace(out / "trace.pftrace").slices
    assert "trace.pftrace" in capsys.readouterr().out


def test_a_table_that_cannot_be_written_leaves_no_temporary(tmp_path, monkeypatch):
    from host_tools.studies.sweep_table import ResultsTable

    real = Path.write_text

    def half_then_full(self, data, *a, **k):  # the first bytes land, then the disk is full
        real(self, data[: len(data) // 2], *a, **k)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(Path, "write_text", half_then_full)
    with pytest.raises(OSError) as e:
        ResultsTable(tmp_path / "out", ["point"], "d" * 64, 1, resume=False)
    assert e.value.filename == str(tmp_path / "out" / "sweep.json")
    assert _leftovers(tmp_path) == [] and not (tmp_path / "out" / "sweep.json").exists()


# ---- interrupted work --------------------------------------------------------------------------------------------

def _stopped_cleanly(err: str) -> None:
    """No leaked semaphore, no worker killed by the signal, no traceback through pafp's code, no warning that the
    worker still computing a point was killed (the clean-up's intent). (A worker's log may show distributed's own
    chatter as the cluster closes on a busy host: a heartbeat to a scheduler already gone.)"""
    assert "leaked semaphore" not in err and "KeyboardInterrupt" not in err and "Interrupted" not in err, err
    assert "Worker process still alive" not in err, err
    frames = [ln for ln in err.splitlines() if ln.strip().startswith('File "')]
    assert not [f for f in frames if "host_tools" in f or "/tests/" in f], err


def _wait_for(predicate, proc: subprocess.Popen, timeout: float = 180) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None and not predicate():
        time.sleep(0.1)
    assert proc.poll() is None, proc.communicate()


@pytest.mark.parametrize(("sig", "group"), [(signal.SIGTERM, False), (signal.SIGINT, True)],
                         ids=["SIGTERM", "Ctrl-C to the process group"])
def test_sweep_stopped_by_a_signal_closes_its_cluster_and_its_report_says_how_far_it_got(tmp_path, sig, group):
    spec = _spec(tmp_path, "[base]\nstrides = 1\n[[grid]]\nkey = 'run.seed'\nvalues = "
                 + str(list(range(60))) + "\n")
    out = tmp_path / "out"
    proc = subprocess.Popen([*PAFP, "sweep", str(spec), "--out", str(out), "--workers", "1", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            start_new_session=True)
    journal = out / "rows.jsonl"
    _wait_for(lambda: journal.exists() and journal.read_text().count("\n") >= 2, proc)
    if group:  # as a terminal does: the workers get it too, and must leave the stop to the sweep
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    stdout, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, err
    _stopped_cleanly(err)
    rows = [json.loads(ln) for ln in journal.read_text().splitlines()]
    assert 2 <= len(rows) < 60
    report = (out / "report.md").read_text()
    assert f"**Interrupted** by {sig.name}: {len(rows)} of 60 points finished" in report and "--resume" in report
    import pyarrow.parquet as pq

    assert pq.read_table(out / "results.parquet").num_rows == len(rows)
    assert _leftovers(out) == []


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_tune_stopped_by_a_signal_keeps_the_best_candidate_so_far(tmp_path, sig):
    out = tmp_path / "tune"
    proc = subprocess.Popen([*PAFP, "tune", "--budget", "40", "--strides", "1", "--workers", "1", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    assert proc.stderr is not None
    for line in proc.stderr:  # the progress line of the first candidate finished (one per tenth, not a tty)
        if " candidates, " in line:
            break
    proc.send_signal(sig)
    _, rest = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, rest
    _stopped_cleanly(rest)
    doc = json.loads((out / "tune.json").read_text())
    assert doc["complete"] is False and doc["interruption"]["by"] == sig.name
    n = doc["interruption"]["candidates_run"]
    assert 1 <= n < 40 and len(doc["evaluations"]) == n
    best = doc["best"]
    feasible = [e for e in doc["evaluations"] if e["feasible"]]
    assert best["score"] == min(e["score"] for e in feasible)
    from firmware.config import load_firmware_config
    from host_tools.studies.tuning import gains_of

    assert gains_of(load_firmware_config(out / "firmware_tuned.toml")) == pytest.approx(best["gains"])
    assert not (out / "tune.png").exists()
    assert f"stopped by {sig.name} after {n} of 40 candidates" in rest


def test_a_run_killed_by_sigkill_leaves_a_staging_directory_the_next_run_removes(tmp_path, capsys):
    out = tmp_path / "run"
    proc = subprocess.Popen([*PAFP, "run", "--strides", "2000", "--quiet", "--no-plot", "--no-trace", "--out",
                             str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    _wait_for(lambda: any(tmp_path.glob(".run.*.partial")), proc)
    proc.kill()
    proc.wait(timeout=60)
    assert [p.name for p in tmp_path.glob(".run.*.partial")]  # what SIGKILL leaves
    assert main(["run", "--quiet", "--strides", "1", "--no-plot", "--no-trace", "--out", str(out)]) in (0, 1)
    capsys.readouterr()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_the_staging_directory_of_a_live_run_is_never_removed(tmp_path):
    host = socket.gethostname().replace(".", "-")
    live = tmp_path / f".run.{os.getpid()}@{host}.abc.partial"  # this process: alive
    other_host = tmp_path / f".run.1@{host}x.abc.partial"  # another machine on a shared disk: unknown
    unrelated = tmp_path / ".runner.1@x.abc.partial"
    gone = tmp_path / f".run.{_dead_pid()}@{host}.abc.partial"
    for d in (live, other_host, unrelated, gone):
        d.mkdir()
    assert clean_stale(tmp_path / "run") == [gone]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in (live, other_host, unrelated))


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_write_failed_names_the_file_and_the_exit_code():
    line = outdir.write_failed("run", OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "/x/summary.json"), "kept")
    assert line == f"pafp run: cannot write /x/summary.json: {os.strerror(errno.ENOSPC)}; kept (exit 74)"


# ---- a write that fails after the work: tune, sweep --point, sweep ------------------------------------------------

def test_tune_whose_disk_fills_keeps_the_files_written_whole_and_exits_74(tmp_path, capsys, monkeypatch,
                                                                        atomic_writes_fill):
    import contextlib

    from host_tools.studies import sweep_engine
    monkeypatch.setattr(sweep_engine, "dask_client", lambda **k: contextlib.nullcontext(None))  # in-process search
    atomic_writes_fill[0] = 20_000  # the tuned profile fits, the PNG does not
    out = tmp_path / "tune"
    code = main(["tune", "--budget", "5", "--strides", "1", "--quiet", "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == EXIT_WRITE_FAILED, err
    assert f"cannot write {out / 'tune.png'}: {os.strerror(errno.ENOSPC)}" in _one_line(err)
    assert sorted(p.name for p in out.iterdir()) == ["firmware_tuned.toml"]  # whole; no PNG, no temporary
    from firmware.config import load_firmware_config

    load_firmware_config(out / "firmware_tuned.toml")


def test_sweep_point_whose_disk_fills_publishes_nothing_and_exits_74(tmp_path, capsys, atomic_writes_fill):
    out = tmp_path / "p0"
    code = main(["sweep", str(_spec(tmp_path)), "--point", "0", "--out", str(out)])
    _, err = capsys.readouterr()
    assert code == EXIT_WRITE_FAILED, err
    assert "cannot write" in _one_line(err) and "tracking.png" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]  # no --out, no staging directory


@pytest.mark.usefixtures("threads_cluster")  # the sweep's cluster of processes: its stop signal test above
def test_a_sweep_whose_report_cannot_be_written_keeps_its_rows_and_exits_74(tmp_path, capsys, atomic_writes_fill):
    out = tmp_path / "out"
    code = main(["sweep", str(_spec(tmp_path, "[base]\nstrides = 1\n[[grid]]\nkey = 'run.seed'\nvalues = [0, 1]\n")),
                 "--out", str(out), "--workers", "1", "--quiet"])
    _, err = capsys.readouterr()
    assert code == EXIT_WRITE_FAILED, err
    assert "cannot write" in _one_line(err) and str(out / "plots") in err
    assert len((out / JOURNAL).read_text().splitlines()) == 2
    import pyarrow.parquet as pq

    assert pq.read_table(out / "results.parquet").num_rows == 2
    assert _leftovers(out) == [] and not (out / "report.md").exists()


# ---- pafp decode --csv onto a device -----------------------------------------------------------------------------

def _device(tmp_path: Path, name: str, minor: int) -> Path:
    """A private node of the memory device `minor` (3 null, 7 full) in tmp_path: never the system's own."""
    path = tmp_path / name
    try:
        os.mknod(path, 0o666 | 0o020000, os.makedev(1, minor))  # S_IFCHR
    except (PermissionError, OSError):
        pytest.skip("creating a device node needs root")
    return path


def test_decode_csv_onto_a_device_writes_into_it_and_never_replaces_the_node(tmp_path, capsys):
    import stat

    capture = tmp_path / "t.bin"
    assert main(["run", "--quiet", "--strides", "1", "--no-plot", "--no-trace", "--out", str(tmp_path / "r")]) in (0, 1)
    capture.write_bytes((tmp_path / "r" / "telemetry.bin").read_bytes())
    null, full = _device(tmp_path, "null", 3), _device(tmp_path, "full", 7)
    capsys.readouterr()
    assert main(["decode", "--protocol", "telemetry", str(capture), "--csv", str(null)]) == 0
    assert main(["decode", "--protocol", "telemetry", str(capture), "--csv", str(full)]) == EXIT_WRITE_FAILED
    _, err = capsys.readouterr()
    assert f"cannot write {full}: {os.strerror(errno.ENOSPC)}" in _one_line(err)
    assert all(stat.S_ISCHR(p.stat().st_mode) for p in (null, full))  # still the devices, not CSV files
    assert _leftovers(tmp_path) == []

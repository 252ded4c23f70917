"""`pafp run` (virtual) before and after the simulation: bad input refused up front, outputs staged and put
in place whole, a stop signal still writes what the run had, summary.json strict JSON, streamed files."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from firmware.config import DEFAULT_PROFILE
from host_tools.cli import main
from host_tools.reports.report import summarise, write_outputs
from host_tools.runner import RunConfig, run_virtual
from protocol.telemetry import TelemetryDecoder


def _run(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["run", "--quiet", *args])
    out, err = capsys.readouterr()
    return code, out, err


def _profile(tmp_path: Path, old: str, new: str) -> Path:
    text = DEFAULT_PROFILE.read_text(encoding="utf-8")
    assert text.count(old) >= 1, old
    path = tmp_path / "fw.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    return path


@pytest.mark.parametrize(("old", "new", "needles"), [
    ("current_limit_a = 12.0", "current_limit_a = -12.0", ["[control] current_limit_a = -12.0", "(0, 22.7] A"]),
    ("current_limit_a = 12.0", "current_limit_a = 1e9", ["[control] current_limit_a = 1000000000.0", "(0, 22.7] A"]),
    ("current_limit_a = 12.0", "current_limit_a = 22.8", ["[control] current_limit_a = 22.8", "(0, 22.7] A"]),
    ("velocity_limit_rad_s = 8.0", "velocity_limit_rad_s = 100", ["[control] velocity_limit_rad_s = 100",
                                                                  "(0, 12.5664] rad/s"]),
    # every [safety] limit is bounded by the hardware (firmware/safety_limits.py names the sources)
    ("brake_current_a = 2.0", "brake_current_a = 500", ["[safety] brake_current_a = 500", "(0, 6.5] A"]),
    ("current_limit_a = 20.0", "current_limit_a = 1e9", ["[safety] current_limit_a = 1000000000.0", "(0, 22.7] A"]),
    ("angle_max_deg = 38.0", "angle_max_deg = 1000", ["[safety] angle_max_deg = 1000", "[-90, 90] deg"]),
    ("angle_min_deg = -33.0", "angle_min_deg = -91", ["[safety] angle_min_deg = -91", "[-90, 90] deg"]),
    ("disagreement_deg = 6.0", "disagreement_deg = 1e9", ["[safety] disagreement_deg = 1000000000.0", "(0, 71] deg"]),
    ("command_timeout_s = 0.020", "command_timeout_s = 1e6", ["[safety] command_timeout_s = 1000000.0", "(0, 0.1] s"]),
    ("motor_timeout_s = 0.020", "motor_timeout_s = 0.2", ["[safety] motor_timeout_s = 0.2", "(0, 0.1] s"]),
    ("imu_timeout_s = 0.040", "imu_timeout_s = 10", ["[safety] imu_timeout_s = 10", "(0, 0.1] s"]),
    ("startup_grace_s = 0.5", "startup_grace_s = 1e9", ["[safety] startup_grace_s = 1000000000.0", "(0, 5] s"]),
    ("brake_delay_s = 0.010", "brake_delay_s = 2", ["[safety] brake_delay_s = 2", "[0, 1] s"]),
    ("deadline_miss_streak = 3", "deadline_miss_streak = 101", ["[safety] deadline_miss_streak = 101", "[1, 100]"]),
    ("stride_s = 1.1", "stride_s = 0", ["[control] stride_s = 0", "[0.2, 10] s"]),
    ("stride_s = 1.1", "stride_s = 1e6", ["[control] stride_s = 1000000.0", "[0.2, 10] s"]),
    ("control = { base = 3500 }", "control = { base = -3500 }", ["[task_cycles] control: base = -3500",
                                                                 "[0, 10000000]"]),
    ("control = { base = 3500 }", "control = { base = 1000000000000 }", ["base = 1000000000000", "[0, 10000000]"]),
    ("[control]\n", "[contorl]\n", ["unknown section [contorl]", "[control]"]),
    ("watchdog = { base = 60 }", "watchdog = { base = 60 }\nwatchdgo = { base = 60 }",
     ["[task_cycles] task 'watchdgo' is not a firmware task", "watchdog"]),
    ("stride_s = 1.1", "stride_s = 1.1\nstrid_s = 1.1", ["[control] has no key 'strid_s'", "stride_s"]),
    ("control = 1000 ", "control = 0 ", ["[rates_hz] control = 0", "[1, 10000]"]),
    # each message names the section and key as written in the profile, and the keys or range allowed
    ('link = "uart"', 'link = "usb"', ["[motor] link 'usb' unknown", "'can-mit', 'can-servo', 'uart'"]),
    ("can_id = 1", "can_id = 300", ["[motor] can_id = 300", "[0, 127]"]),
    ("kp = 8.0", "kpp = 8.0", ["[control.position] has no key 'kpp'", "kp, ki, kd, derivative_tau_s"]),
    ("kp = 8.0", "ki_ = 8.0", ["[control.position] has no key 'ki_'", "kp, ki, kd, derivative_tau_s"]),
    ("kp = 0.2", "# kp = 0.2", ["[control.velocity] needs kp (required"]),
    ("inertia_kg_m2 = 0.0495", "inertia = 0.0495", ["[feedforward] has no key 'inertia'", "inertia_kg_m2, mass_kg"]),
    ("disagreement_deg = 6.0", "disagreement = 6.0", ["[safety] has no key 'disagreement'", "disagreement_deg"]),
])
def test_a_bad_profile_value_is_one_line_naming_file_section_value_and_range(tmp_path, capsys, old, new, needles):
    profile = _profile(tmp_path, old, new)
    out = tmp_path / "never"
    code, stdout, err = _run(capsys, "--profile", str(profile), "--out", str(out))
    assert code == 2 and stdout == "" and len(err.strip().splitlines()) == 1, err
    assert str(profile) in err
    for needle in needles:
        assert needle in err, (needle, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fw.toml"]  # nothing written, no staging left


def test_a_binary_reference_is_named(tmp_path, capsys):
    ref = tmp_path / "gait.csv"
    ref.write_bytes(bytes(range(256)) * 8)
    code, _, err = _run(capsys, "--reference", str(ref), "--out", str(tmp_path / "never"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and str(ref) in err and "UTF-8" in err
    assert not (tmp_path / "never").exists()


def test_out_naming_an_existing_file_is_refused_before_the_run(tmp_path, capsys):
    f = tmp_path / "results"
    f.write_text("keep me")
    code, stdout, err = _run(capsys, "--out", str(f))
    assert code == 2 and stdout == "" and "is an existing file" in err and str(f) in err
    assert f.read_text() == "keep me" and sorted(p.name for p in tmp_path.iterdir()) == ["results"]
    code, _, err = _run(capsys, "--out", str(f / "sub"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and str(f / "sub") in err


def test_out_holding_other_files_is_refused_not_overwritten(tmp_path, capsys):
    d = tmp_path / "mine"
    d.mkdir()
    (d / "notes.txt").write_text("keep me")
    code, _, err = _run(capsys, "--out", str(d))
    assert code == 2 and "'notes.txt'" in err and "not a pafp run's" in err
    assert [p.name for p in d.iterdir()] == ["notes.txt"]


def test_out_that_cannot_be_created_is_refused_before_the_run(capsys):
    code, stdout, err = _run(capsys, "--out", "/proc/pafp-cannot-write-here")
    assert code == 2 and stdout == "" and len(err.strip().splitlines()) == 1 and "/proc/pafp-cannot" in err


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_out_in_a_read_only_directory_is_refused_before_the_run(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        code, _, err = _run(capsys, "--out", str(ro / "run"))
    finally:
        ro.chmod(0o755)
    assert code == 2 and "not writable" in err


def test_a_previous_run_is_replaced_whole_never_mixed(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, _ = _run(capsys, "--strides", "1", "--out", str(out))
    assert code == 0 and {"tracking.png", "trace.pftrace", "summary.json"} <= {p.name for p in out.iterdir()}
    code, stdout, _ = _run(capsys, "--strides", "1", "--seed", "3", "--no-plot", "--no-trace", "--out", str(out))
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == [".pafp-outputs.json", "report.md", "summary.json", "telemetry.bin",
                                                     "telemetry.csv"]
    assert json.loads((out / "summary.json").read_text())["seed"] == 3
    assert [p.name for p in tmp_path.iterdir()] == ["run"]  # no staging or old directory left behind
    assert "tracking.png" not in stdout and "trace.pftrace" not in stdout


def test_summary_is_strict_json_with_null_for_what_a_run_does_not_have(tmp_path):
    """A run whose gait never starts (e-stop pressed from the start) has no tracking error: null, not NaN."""
    def setup(bench, fw):
        bench.estop.set_at(0, True)

    r = run_virtual(RunConfig(strides=1, trace_capacity=0, setup=setup, stream_to=tmp_path))
    s = write_outputs(r, tmp_path, plot=False)
    assert s["imu_rms_error_deg"] is None and s["tracking"]["enough_run"] is False
    text = (tmp_path / "summary.json").read_text()
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in summary.json"))
    assert doc["imu_rms_error_deg"] is None and doc["encoder_lag_ms"] is None and doc["complete"] is True
    # the process's own clock: in a long-lived process (an xdist worker) the factor rounds to 0.0, never NaN
    assert doc["process_wall_time_s"] > 0 and doc["process_realtime_factor"] >= 0
    assert all(doc["tracking"][k]["rms_deg"] is None for k in ("imu", "encoder", "fused", "truth"))
    assert "| imu: IMU pitch as the firmware received it (the report's Figs 4.8-4.10) | n/a | n/a | n/a |" \
        in (tmp_path / "report.md").read_text()


def test_streamed_run_gives_the_in_memory_run_s_telemetry_and_figures(tmp_path):
    memory = run_virtual(RunConfig(strides=2, seed=4, trace_capacity=0))
    streamed = run_virtual(RunConfig(strides=2, seed=4, trace_capacity=0, stream_to=tmp_path))
    assert (tmp_path / "telemetry.bin").read_bytes() == memory.telemetry and streamed.telemetry == b""
    a, b = summarise(memory), summarise(streamed)
    for key in ("imu_rms_error_deg", "encoder_max_error_deg", "encoder_lag_ms", "tracking", "deadline_misses",
                "sim_time_s"):
        assert a[key] == b[key], key
    assert len(streamed.probe.t_s) < 600  # drained segment by segment: at most about one segment's samples


def test_telemetry_csv_has_time_in_seconds_and_float32_precision(tmp_path, capsys):
    code, _, _ = _run(capsys, "--strides", "1", "--no-plot", "--no-trace", "--out", str(tmp_path / "run"))
    lines = (tmp_path / "run" / "telemetry.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[:3] == ["seq", "time_cycles", "time_s"]
    records = TelemetryDecoder().feed((tmp_path / "run" / "telemetry.bin").read_bytes())
    assert len(lines) == len(records) + 1
    for line, rec in zip(lines[1:], records, strict=True):
        cells = dict(zip(header, line.split(","), strict=True))
        assert int(cells["time_cycles"]) == rec.time_cycles
        assert abs(float(cells["time_s"]) - rec.time_cycles / 168e6) <= 5e-10
        for name in ("reference_rad", "fused_angle_rad", "current_cmd_a"):
            value = cells[name]
            assert float(value) == pytest.approx(getattr(rec, name), rel=1e-7, abs=1e-12)
            assert len(value.lstrip("-").replace(".", "").lstrip("0").split("e")[0]) <= 9  # no float64 tail


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_ends_the_run_and_what_it_had_is_written(tmp_path, sig):
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "host_tools", "run", "--strides", "2000", "--quiet", "--no-plot",
                             "--no-trace", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # wait until the run is under way: its staging directory has telemetry
        staged = [p for p in tmp_path.glob(".run.*.partial") if (p / "telemetry.bin").exists()
                  and (p / "telemetry.bin").stat().st_size > 10_000]
        if staged or proc.poll() is not None:
            break
        time.sleep(0.05)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 128 + int(sig), stderr
    assert f"stopped by {sig.name}" in stderr and "Traceback" not in stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and 0 < s["sim_time_s"] < 2000
    stopped = s["interruption"]
    assert stopped["by"] == sig.name and 0 <= stopped["strides_run"] < 2000
    report = (out / "report.md").read_text()  # says so first, and how far the run got
    assert report.splitlines()[2] == (f"**Interrupted**: stopped by {sig.name} after {s['sim_time_s']:.3f} s, with "
                                      f"{stopped['strides_run']} whole strides of gait run; every figure below "
                                      "covers that part only (summary.json: \"complete\": false).")
    assert report.splitlines()[4].startswith("2000 strides asked, ")
    dec = TelemetryDecoder()
    records = dec.feed((out / "telemetry.bin").read_bytes())
    assert records and dec.stats.crc_errors == dec.stats.bad_frames == 0
    assert len((out / "telemetry.csv").read_text().splitlines()) == len(records) + 1
    assert [p.name for p in tmp_path.iterdir()] == ["run"]

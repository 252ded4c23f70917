"""The serial-mode trace (wall clock) has the virtual run's tracks; the trace options are checked before a run."""

from __future__ import annotations

import json
import math

import pytest

from host_tools.cli import main
from host_tools.reports.timeline import COUNTERS
from protocol.telemetry import TelemetryDecoder
from tests.trace_reader import read_trace


def test_a_serial_run_has_the_same_tracks_on_the_wall_clock(tmp_path):
    code = main(["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--encoder", "sim", "--duration", "1",
                 "--out", str(tmp_path), "--quiet"])
    assert code in (0, 1)
    tr = read_trace(tmp_path / "trace.pftrace")
    names = {t.name for t in tr.tracks.values()}
    assert {"encoder", "supervisor", "control", "motor", "imu", "logger", "watchdog", "kernel", "safety",
            "gait (motor load)", "CPU utilisation", "motor-reported winding temperature"} <= names
    assert any(n.startswith("firmware (") and n.endswith("wall clock)") for n in names)
    assert not any(n.startswith("ISR ") for n in names)  # interrupts are not modelled on the wall clock
    records = TelemetryDecoder().feed((tmp_path / "telemetry.bin").read_bytes())
    f = 168_000_000
    for field, name, unit in COUNTERS:
        want = [(r.time_cycles * 10**9 // f, math.degrees(getattr(r, field)) if unit == "deg" else getattr(r, field))
                for r in records]
        assert tr.counter(name) == want, name
    stop = json.loads((tmp_path / "summary.json").read_text())["stop"]
    safe = tr.instants_on("safety")  # the stop path's frames, out of the port
    assert [i.name for i in safe] == ["safe command on the wire"] and stop["safe_on_wire"]
    assert abs(safe[0].ts - (stop["at_s"] + stop["latency_ms"] / 1e3) * 1e9) < 1e3  # summary.json's rounding


@pytest.mark.parametrize("args, message", [
    (["--strides", "1", "--trace-seconds", "0"], "trace window 0.0 s out of range"),
    (["--strides", "1", "--trace-strides", "0"], "--trace-strides 0 out of range"),
    (["--strides", "1", "--trace-strides", "2", "--trace-seconds", "5"], "choose one window"),
    (["--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--trace-wire"], "--trace-wire is not allowed in serial"),
    (["--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--trace-seconds", "5"], "not allowed in serial mode"),
])
def test_bad_trace_options_are_one_line_before_any_run(tmp_path, capsys, args, message):
    assert main(["run", *args, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1

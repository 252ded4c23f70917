"""`pafp decode`: JSON lines, summary, CSV, stdin, and one-line errors with exit code 2."""

import csv
import io
import json
import math
import sys
from types import SimpleNamespace

import pytest

from host_tools.cli import main
from protocol.rvc import RvcFrame
from protocol.telemetry import FaultReason, SupervisorState, TelemetryRecord, encode_record

CONSTRUCTED = bytes.fromhex("AA AA 2A D2 04 C9 FD E2 45 0C 00 DE FF EA 03 00 00 00 C3")
DATASHEET = bytes.fromhex("AA AA DE 01 00 92 FF 25 08 8D FE EC FF D1 03 00 00 00 E7")
BANNER = b"%Hillcrest Labs 10003608\r\n"


def run_cli(capsys, *argv):
    code = main(["decode", *argv])
    captured = capsys.readouterr()
    lines = [json.loads(line) for line in captured.out.splitlines()]
    return code, lines, captured.err


def write(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data)
    return str(path)


def test_rvc_json_lines_and_summary(tmp_path, capsys):
    path = write(tmp_path, "imu.bin", BANNER + CONSTRUCTED + b"\x01\x02" + DATASHEET)
    code, lines, err = run_cli(capsys, "--protocol", "rvc", path)
    assert code == 0 and err == ""
    assert [m["type"] for m in lines[:-1]] == ["RvcFrame", "RvcFrame"]
    first = lines[0]
    assert first["index"] == 42 and math.degrees(first["yaw_rad"]) == pytest.approx(12.34)
    assert RvcFrame(**{k: v for k, v in first.items() if k != "type"}).encode() == CONSTRUCTED
    summary = lines[-1]["summary"]
    assert summary["frames"] == 2 and summary["dropped_bytes"] == 2 and summary["banner_bytes"] == len(BANNER)
    assert summary["bytes_in"] == len(BANNER) + 40
    assert summary["lost_frames"] == (222 - 42 - 1)


def test_telemetry_json_lines_null_for_nan(tmp_path, capsys):
    recs = [TelemetryRecord(seq=s, time_cycles=10 * s, torque_est_nm=math.nan if s == 1 else 0.5,
                            supervisor_state=SupervisorState.RUN) for s in (0, 1, 3)]
    path = write(tmp_path, "log.bin", b"".join(encode_record(r) for r in recs))
    code, lines, _ = run_cli(capsys, "--protocol", "telemetry", path)
    assert code == 0
    assert [m["seq"] for m in lines[:-1]] == [0, 1, 3]
    assert lines[1]["torque_est_nm"] is None and lines[0]["torque_est_nm"] == 0.5
    assert lines[0]["supervisor_state"] == 1 and lines[0]["type"] == "TelemetryRecord"
    assert lines[-1]["summary"]["records"] == 3 and lines[-1]["summary"]["lost_records"] == 1


def test_large_capture_is_read_in_chunks(tmp_path, capsys):
    n = 3000  # 168 kB > one 64 KiB chunk: records straddle chunk borders
    path = write(tmp_path, "big.bin", b"".join(encode_record(TelemetryRecord(i, i)) for i in range(n)))
    code, lines, _ = run_cli(capsys, "--protocol", "telemetry", path)
    assert code == 0 and len(lines) == n + 1
    assert lines[-1]["summary"]["records"] == n and lines[-1]["summary"]["dropped_bytes"] == 0


def test_stdin_dash(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", SimpleNamespace(buffer=io.BytesIO(CONSTRUCTED * 2)))
    code, lines, _ = run_cli(capsys, "--protocol", "rvc", "-")
    assert code == 0 and len(lines) == 3 and lines[-1]["summary"]["frames"] == 2


def test_csv_telemetry_has_degree_and_name_columns(tmp_path, capsys):
    rec = TelemetryRecord(seq=7, time_cycles=70, reference_rad=math.pi / 6,
                          supervisor_state=SupervisorState.SAFE, fault_reason=FaultReason.IMU_TIMEOUT)
    path = write(tmp_path, "log.bin", encode_record(rec))
    out = tmp_path / "out.csv"
    code, lines, _ = run_cli(capsys, "--protocol", "telemetry", "--csv", str(out), path)
    assert code == 0 and len(lines) == 1 and lines[0]["summary"]["records"] == 1
    rows = list(csv.DictReader(out.open(newline="")))
    assert len(rows) == 1
    assert float(rows[0]["reference_deg"]) == pytest.approx(30.0, abs=1e-5)
    assert rows[0]["supervisor_state_name"] == "SAFE" and rows[0]["fault_reason_name"] == "IMU_TIMEOUT"


def test_csv_rvc_adds_deg_columns(tmp_path, capsys):
    path = write(tmp_path, "imu.bin", CONSTRUCTED + DATASHEET)
    out = tmp_path / "imu.csv"
    code, _, _ = run_cli(capsys, "--protocol", "rvc", "--csv", str(out), path)
    assert code == 0
    rows = list(csv.DictReader(out.open(newline="")))
    assert [float(r["pitch_deg"]) for r in rows] == pytest.approx([-5.67, -1.10])
    assert "yaw_rad" in rows[0] and "accel_z_mps2" in rows[0]


def test_bad_path_is_one_line_and_exit_2(tmp_path, capsys):
    code, lines, err = run_cli(capsys, "--protocol", "rvc", str(tmp_path / "missing.bin"))
    assert code == 2 and lines == []
    assert err.count("\n") == 1 and "missing.bin" in err and "Traceback" not in err


def test_directory_as_file_is_one_line_and_exit_2(tmp_path, capsys):
    code, _, err = run_cli(capsys, "--protocol", "telemetry", str(tmp_path))
    assert code == 2 and err.count("\n") == 1 and str(tmp_path) in err


def test_unwritable_csv_is_one_line_and_exit_2(tmp_path, capsys):
    path = write(tmp_path, "imu.bin", CONSTRUCTED)
    code, _, err = run_cli(capsys, "--protocol", "rvc", "--csv", str(tmp_path / "no" / "dir.csv"), path)
    assert code == 2 and err.count("\n") == 1 and "dir.csv" in err


def test_direction_with_non_vesc_protocol_is_refused(tmp_path, capsys):
    path = write(tmp_path, "imu.bin", CONSTRUCTED)
    code, _, err = run_cli(capsys, "--protocol", "rvc", "--direction", "to-motor", path)
    assert code == 2 and "--direction" in err and err.count("\n") == 1


def test_garbage_file_decodes_to_summary_only(tmp_path, capsys):
    path = write(tmp_path, "junk.bin", bytes(range(256)) * 4)
    for protocol in ("rvc", "telemetry"):
        code, lines, _ = run_cli(capsys, "--protocol", protocol, path)
        assert code == 0 and len(lines) == 1 and lines[0]["summary"]["bytes_in"] == 1024


def test_vesc_both_directions(tmp_path, capsys):
    vesc = pytest.importorskip("protocol.vesc")
    frames = vesc.SetCurrent(2.5).encode() + vesc.GetValues().encode()
    to_motor = write(tmp_path, "tx.bin", b"\x00\x02" + frames)
    code, lines, _ = run_cli(capsys, "--protocol", "vesc", "--direction", "to-motor", to_motor)
    assert code == 0
    assert [m["type"] for m in lines[:-1]] == ["SetCurrent", "GetValues"]
    assert lines[0]["current_a"] == 2.5
    assert lines[-1]["summary"]["dropped_bytes"] == 2 and lines[-1]["summary"]["frames"] == 2

    reply = vesc.Values(temp_fet_c=31.5, avg_motor_current_a=1.25, erpm=1400, v_in_v=24.0, pid_pos_rad=0.5)
    from_motor = write(tmp_path, "rx.bin", reply.encode())
    code, lines, _ = run_cli(capsys, "--protocol", "vesc", from_motor)  # default direction: from-motor
    assert code == 0 and lines[0]["type"] == "Values"
    assert lines[0]["erpm"] == 1400 and lines[0]["v_in_v"] == pytest.approx(24.0)

    out = tmp_path / "rx.csv"
    code, _, _ = run_cli(capsys, "--protocol", "vesc", "--csv", str(out), from_motor)
    row = next(csv.DictReader(out.open(newline="")))
    assert row["type"] == "Values" and float(row["pid_pos_deg"]) == pytest.approx(math.degrees(0.5), rel=1e-3)


def test_vesc_unknown_ids_and_bytes_fields_become_hex(tmp_path, capsys):
    vesc = pytest.importorskip("protocol.vesc")
    data = vesc.encode_frame(b"\x63\x01\x02") + vesc.FwVersion(1, 2, "AK60").encode()
    path = write(tmp_path, "rx.bin", data)
    code, lines, _ = run_cli(capsys, "--protocol", "vesc", path)
    assert code == 0
    assert lines[0] == {"type": "Unknown", "command_id": 0x63, "data": "0102"}
    assert lines[1]["type"] == "FwVersion" and lines[1]["hw_name"] == "AK60" and lines[1]["uuid"] == "00" * 12
    assert lines[-1]["summary"]["unknown_ids"] == 1


def test_vesc_frame_behind_a_false_header_at_end_of_input_is_recovered(tmp_path, capsys):
    vesc = pytest.importorskip("protocol.vesc")
    frame = vesc.SetCurrent(2.5).encode()
    path = write(tmp_path, "tx.bin", bytes.fromhex("03 01 ff") + frame)  # a long-frame header holds it pending
    code, lines, _ = run_cli(capsys, "--protocol", "vesc", "--direction", "to-motor", path)
    assert code == 0 and [m["type"] for m in lines[:-1]] == ["SetCurrent"]
    s = lines[-1]["summary"]
    assert s["frames"] == 1 and s["pending_skipped"] >= 1
    assert s["end_of_input"]["held_bytes"] == 3 + len(frame) and s["end_of_input"]["messages_recovered"] == 1
    assert s["bytes_in"] == len(frame) + s["dropped_bytes"]  # every byte in a frame or counted as dropped


def test_leftover_bytes_of_a_truncated_frame_are_counted(tmp_path, capsys):
    vesc = pytest.importorskip("protocol.vesc")
    frame = vesc.SetCurrent(2.5).encode()
    path = write(tmp_path, "tx.bin", frame + frame[:-3])
    code, lines, _ = run_cli(capsys, "--protocol", "vesc", "--direction", "to-motor", path)
    end = lines[-1]["summary"]["end_of_input"]
    assert code == 0 and len(lines) == 2
    assert end["held_bytes"] == len(frame) - 3 and end["leftover_bytes"] == len(frame) - 3
    assert end["messages_recovered"] == 0 and end["candidates_given_up"] >= 1
    rec = encode_record(TelemetryRecord(seq=1, time_cycles=5))
    path = write(tmp_path, "log.bin", rec + rec[:10])
    code, lines, _ = run_cli(capsys, "--protocol", "telemetry", path)
    end = lines[-1]["summary"]["end_of_input"]
    assert code == 0 and end == {"held_bytes": 10, "candidates_given_up": 1, "messages_recovered": 0,
                                 "leftover_bytes": 10}


def test_csv_dash_writes_the_table_to_stdout_and_the_summary_to_stderr(tmp_path, capsys):
    path = write(tmp_path, "imu.bin", CONSTRUCTED + DATASHEET)
    code = main(["decode", "--protocol", "rvc", "--csv", "-", path])
    out, err = capsys.readouterr()
    assert code == 0 and not (tmp_path / "-").exists()
    rows = list(csv.DictReader(io.StringIO(out)))
    assert [float(r["pitch_deg"]) for r in rows] == pytest.approx([-5.67, -1.10])
    assert json.loads(err)["summary"]["frames"] == 2


def test_csv_goes_to_a_temporary_name_first(tmp_path, capsys):
    out = tmp_path / "imu.csv"
    out.write_text("old table\n")
    path = write(tmp_path, "imu.bin", CONSTRUCTED)
    code, _, _ = run_cli(capsys, "--protocol", "rvc", "--csv", str(out), path)
    assert code == 0 and out.read_text().startswith("type,")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imu.bin", "imu.csv"]  # no temporary file left
    code, _, err = run_cli(capsys, "--protocol", "rvc", "--csv", str(out), str(tmp_path / "missing.bin"))
    assert code == 2 and out.read_text().startswith("type,")  # a failed decode leaves the old table whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imu.bin", "imu.csv"]


def test_a_closed_stdout_ends_quietly(tmp_path):
    import subprocess

    path = write(tmp_path, "big.bin", b"".join(encode_record(TelemetryRecord(i, i)) for i in range(20000)))
    cmd = f"{sys.executable} -m host_tools decode --protocol telemetry {path} | head -1"
    r = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stderr == "" and json.loads(r.stdout)["seq"] == 0

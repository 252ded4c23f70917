"""Record and replay: a recorded run replays byte for byte; a changed gain diverges where it should; bad records."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from firmware.config import load_firmware_config
from hal.errors import HalError
from hal.record.format import Kind, RecordError
from hal.record.reader import RecordReader
from hal.record.recorder import Recorder
from host_tools.calibration.replay_run import replay_record
from host_tools.cli import main
from host_tools.recording import RECORD_NAME, config_dict, config_from_dict
from protocol.vesc import Decoder, SetCurrent

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A one-stride virtual run with --record."""
    out = tmp_path_factory.mktemp("rec") / "run"
    assert main(["run", "--strides", "1", "--quiet", "--no-plot", "--no-trace", "--record", "--out", str(out)]) == 0
    return out


def test_config_round_trips_through_the_header():
    cfg = load_firmware_config()
    assert config_from_dict(json.loads(json.dumps(config_dict(cfg)))) == cfg


def test_events_round_trip(tmp_path):
    rec = Recorder(tmp_path / "r.bin", {"x": 1})
    rec.job(2, 1000, 7)
    rec.emit(Kind.READ, 1, data=b"\x01\x02")
    rec.emit(Kind.ENC_CNT, 0, 1234)
    rec.raised(Kind.READ, 0, HalError("port gone"))
    rec.emit(Kind.WRITE, 2, 3, data=b"abcd")
    rec.job(3, 2000, 8)
    rec.emit(Kind.HEALTH, 0, 5, 1)
    rec.close({"done": True})
    reader = RecordReader(tmp_path / "r.bin")
    assert reader.header == {"x": 1}
    a, b = list(reader.sections())
    assert (a.task_id, a.start, a.index) == (2, 1000, 7)
    assert list(a.inputs[Kind.READ << 2 | 1]) == [b"\x01\x02"]
    assert list(a.inputs[Kind.ENC_CNT << 2]) == [1234]
    assert isinstance(a.inputs[Kind.READ << 2][0], HalError)
    assert a.outputs[Kind.WRITE << 2 | 2] == [(3, b"abcd")]
    assert list(b.inputs[Kind.HEALTH << 2]) == [(5, 1)]
    assert reader.footer["done"] is True and reader.footer["events"] == 7


def test_every_event_kind_decodes_what_was_packed(tmp_path):
    # the parser decodes the common kinds byte by byte: each kind at its extremes against its struct layout
    from hal.can import CanFrame
    from hal.record.format import FIXED, VARIABLE

    rec = Recorder(tmp_path / "r.bin", {})
    rec.job(253, 2**64 - 1, 2**32 - 1)
    expected_in, expected_out = {}, {}
    outputs = {Kind.WRITE, Kind.ENC_SET, Kind.LED, Kind.KICK, Kind.CAN_TX}
    for kind, st in FIXED.items():
        if kind == Kind.JOB:
            continue
        fields = st.unpack(b"\xff" * st.size)  # every field at its maximum
        rec.emit(kind, 3, *fields)
        value = None if not fields else fields[0] if len(fields) == 1 else tuple(fields)
        (expected_out if kind in outputs else expected_in)[kind << 2 | 3] = value
    data = bytes(range(256)) * 3
    rec.emit(Kind.READ, 1, data=data)
    rec.emit(Kind.WRITE, 1, 65535, data=b"\x00")
    rec.emit(Kind.CAN_RX, 3, 3, 2**29 - 1, data=b"\x01\x02")
    rec.emit(Kind.CAN_TX, 3, 1, 0, 0x7FF, data=b"")
    rec.close({})
    (s,) = RecordReader(tmp_path / "r.bin").sections()
    assert (s.task_id, s.start, s.index) == (253, 2**64 - 1, 2**32 - 1)
    inputs = {k: v[0] for k, v in s.inputs.items()}
    assert inputs == {**expected_in, Kind.READ << 2 | 1: data,
                      Kind.CAN_RX << 2 | 3: CanFrame(2**29 - 1, b"\x01\x02", True)}
    assert {k: v[0] for k, v in s.outputs.items()} == {**expected_out, Kind.WRITE << 2 | 1: (65535, b"\x00"),
                                                       Kind.CAN_TX << 2 | 3: (1, CanFrame(0x7FF, b"", False))}
    assert set(VARIABLE) == {Kind.READ, Kind.WRITE, Kind.RAISE, Kind.CAN_RX, Kind.CAN_TX}


@pytest.mark.parametrize(("raw", "needle"), [
    (bytes([0, 1]) + bytes(12) + bytes([Kind.CLOCK << 2, 1, 2]),
     "ends inside an event (the event at byte 14 of the chunk)"),
    (bytes([0, 1]) + bytes(12) + bytes([Kind.READ << 2, 9, 0, 1]), "ends inside an event"),
    (bytes([0, 1]) + bytes(5), "ends inside an event"),
    (bytes([0, 1]) + bytes(12) + bytes([63 << 2]), "unknown event kind 63"),
    (bytes([Kind.CLOCK << 2]) + bytes(8), "does not start with a job"),
])
def test_a_damaged_chunk_is_one_error_naming_it(tmp_path, raw, needle):
    from hal.record.format import pack_chunk, pack_end, write_header

    path = tmp_path / "r.bin"
    with path.open("wb") as f:
        write_header(f, {})
        f.write(pack_chunk(raw) + pack_end({}))
    with pytest.raises(RecordError, match="chunk at byte offset") as info:
        list(RecordReader(path).sections())
    assert needle in str(info.value) and len(str(info.value).splitlines()) == 1


def test_unchanged_firmware_replays_byte_identical(recorded, tmp_path):
    out = tmp_path / "replay"
    assert main(["replay", str(recorded), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["identical"] and s["first_divergence"] is None and s["diverging_jobs"] == 0
    assert s["starved_calls"] == 0 and s["unused_inputs"] == 0
    assert {"motor", "telemetry", "watchdog"} <= set(s["ports"])
    assert all(p["identical"] and p["replayed_items"] > 0 for p in s["ports"].values())
    assert (out / "telemetry.bin").read_bytes() == (recorded / "telemetry.bin").read_bytes()
    assert (out / "telemetry.csv").read_text() == (recorded / "telemetry.csv").read_text()


def test_changed_gain_diverges_at_the_first_command_in_run(recorded, tmp_path):
    profile = tmp_path / "kp.toml"
    profile.write_text((ROOT / "profiles" / "firmware.toml").read_text().replace("kp = 8.0", "kp = 9.0", 1))
    r = replay_record(recorded / RECORD_NAME, load_firmware_config(profile))
    assert not r.identical and r.first is not None
    assert "position_gains" in r.changed
    d = r.first
    assert (d.task, d.port) == ("motor", "motor")
    exp, got = Decoder("to-motor").feed(bytes.fromhex(d.expected_hex)), Decoder("to-motor").feed(
        bytes.fromhex(d.produced_hex))
    assert isinstance(exp[0], SetCurrent) and isinstance(got[0], SetCurrent)
    assert exp[0].current_a != got[0].current_a
    assert d.expected[0]["type"] == "SetCurrent"
    # the first control job in RUN where kp acts: the first one starts the trajectory at the measured angle
    # (zero error, the same command whatever kp), so the commands part one period later
    rows = [line.split(",") for line in (recorded / "telemetry.csv").read_text().splitlines()]
    col = rows[0].index("supervisor_state_name")
    t_run = next(float(r[2]) for r in rows[1:] if r[col] == "RUN")
    assert d.control_t_s is not None and t_run - 0.002 < d.control_t_s <= t_run + 0.0015
    same = replay_record(recorded / RECORD_NAME)
    assert same.identical
    assert r.diverging_jobs > 100


def test_truncated_record_names_the_offset(recorded, tmp_path, capsys):
    data = (recorded / RECORD_NAME).read_bytes()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / RECORD_NAME).write_bytes(data[: len(data) // 2])
    assert main(["replay", str(cut), "--out", str(tmp_path / "o1")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "truncated at byte offset" in err[0]
    assert not (tmp_path / "o1").exists()


def test_corrupted_record_names_the_chunk(recorded, tmp_path, capsys):
    data = bytearray((recorded / RECORD_NAME).read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / RECORD_NAME).write_bytes(bytes(data))
    assert main(["replay", str(bad), "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "corrupted" in err[0] and "byte offset" in err[0]


def test_not_a_record(tmp_path, capsys):
    (tmp_path / RECORD_NAME).write_bytes(b"hello world, not a record")
    with pytest.raises(RecordError, match="byte offset 0"):
        RecordReader(tmp_path / RECORD_NAME)
    assert main(["replay", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o3")]) == 2
    assert "not found" in capsys.readouterr().err


def test_serial_run_records_and_replays_with_its_stop_path(tmp_path):
    out = tmp_path / "serial"
    code = main(["run", "--motor", "sim://ak60-6", "--imu", "sim://bno08x", "--duration", "0.6", "--quiet",
                 "--no-realtime", "--out", str(out)])
    assert code in (0, 1)  # a stall of this shared host may latch a timeout: the replay reproduces it either way
    r = replay_record(out / RECORD_NAME)
    assert r.identical, r.first
    assert r.footer["stop"] in ("duration", "link_lost")
    # every command the motor was sent, the stop path's last, is replayed (how many a 0.6 s wall-clock run sends
    # depends on this host's load: 100 at one busy moment, about 600 idle)
    motor = r.streams["motor"]
    assert motor["replayed_items"] == motor["recorded_items"] > 0, motor
    tel = tmp_path / "tel.bin"
    with tel.open("wb") as f:
        replay_record(out / RECORD_NAME, telemetry_out=f)
    assert tel.read_bytes() == (out / "telemetry.bin").read_bytes()


@pytest.mark.parametrize("link", ["can-servo", "can-mit"])
def test_can_motor_link_replays_byte_identical(link, tmp_path):
    out = tmp_path / link
    assert main(["run", "--strides", "1", "--motor-link", link, "--record", "--quiet", "--no-plot", "--no-trace",
                 "--out", str(out)]) == 0
    r = replay_record(out / RECORD_NAME)
    assert r.identical, r.first
    assert r.streams["can"]["replayed_items"] > 1000 and r.starved == 0

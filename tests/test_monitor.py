"""`pafp monitor` on a capture file (with a gap) and on a live pty killed mid-stream; plain-pyserial sim:// use."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import textwrap
import time
import tty
from pathlib import Path

from host_tools.cli import main
from protocol.telemetry import RECORD_COLUMNS, TelemetryRecord, encode_record

ROOT = Path(__file__).resolve().parents[1]


def _frames(n: int, skip: frozenset[int] = frozenset()) -> bytes:
    return b"".join(encode_record(TelemetryRecord(seq=k, time_cycles=k * 336_000, reference_rad=0.01 * k))
                    for k in range(n) if k not in skip)


def test_capture_file_with_a_gap(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    cap = tmp_path / "telemetry.bin"
    cap.write_bytes(b"\x55junk\x00" + _frames(50, frozenset({10, 11, 12})))
    code = main(["monitor", str(cap), "--csv", str(tmp_path / "t.csv")])
    out = capsys.readouterr().out
    assert code == 0 and "records 47, lost 3" in out
    rows = list(csv.DictReader((tmp_path / "t.csv").open()))
    assert len(rows) == 47 and [int(r["seq"]) for r in rows[9:11]] == [9, 13]


def test_live_pty_killed_mid_stream_leaves_a_valid_csv(tmp_path: Path) -> None:
    master, slave = os.openpty()
    tty.setraw(slave)
    path, out = os.ttyname(slave), tmp_path / "live.csv"
    proc = subprocess.Popen([sys.executable, "-m", "host_tools", "monitor", path, "--csv", str(out)], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        time.sleep(1.0)
        data = _frames(2000)
        for k in range(0, len(data), 997):  # odd chunks: frames torn across writes
            os.write(master, data[k:k + 997])
            time.sleep(0.002)
        time.sleep(0.3)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    finally:
        os.close(master)
        os.close(slave)
    text = out.read_text()
    assert text.endswith("\n")
    rows = list(csv.reader(text.splitlines()))
    assert rows[0] == list(RECORD_COLUMNS)
    assert len(rows) > 100 and all(len(r) == len(RECORD_COLUMNS) for r in rows)
    assert [int(r[0]) for r in rows[1:]] == list(range(len(rows) - 1))


PLAIN = textwrap.dedent('''
    import binascii, struct, time, serial
    from hal.serial.protocol_sim import register_sim_handler
    register_sim_handler()
    def vesc(payload):
        return bytes([2, len(payload)]) + payload + struct.pack(">H", binascii.crc_hqx(payload, 0)) + b"\\x03"
    m = serial.serial_for_url("sim://ak60-6", timeout=0.5)
    m.write(vesc(bytes([6]) + struct.pack(">i", 1000)) + vesc(bytes([4])))  # SET_CURRENT 1 A, GET_VALUES
    head = m.read(2); assert head[0] == 2, head
    body = m.read(head[1] + 3); payload = body[:-3]
    assert body[-1] == 3 and struct.unpack(">H", body[-3:-1])[0] == binascii.crc_hqx(payload, 0)
    assert payload[0] == 4
    imu = serial.serial_for_url("sim://bno08x", timeout=0.3)
    data = imu.read(4096); i = data.find(b"\\xaa\\xaa"); frame = data[i:i + 19]
    assert len(frame) == 19 and sum(frame[2:18]) & 0xFF == frame[18]
    print("ok", len(payload), struct.unpack("<hhh", frame[3:9]))
''')


def test_plain_pyserial_script_exchanges_real_frames() -> None:
    done = subprocess.run([sys.executable, "-c", PLAIN], cwd=ROOT, capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("ok ")

"""Serial mode's stop paths that need the wall clock to judge: CAN's stop latency, and the host watchdog's bound.

* CAN: `pafp run --motor can://udp_multicast/...` against `pafp emulate bench --can` (one plant, the IMU on a
  pty), servo and MIT mode, three 1.5 s runs each: the median latency from the end of the run to the stop
  path's flush returning, against the goal (one control period plus the two frames' worst-case wire time).
* The host watchdog: a controller that sleeps 2 s in `update` (tests/misbehaving_controllers.py:Blocks), over
  UART (`pafp emulate bench --pty`) and CAN, three runs each: the median time from the loop's last kick to the
  watchdog's first write (`summary.json["host_watchdog"]["silent_ms"]`) and, on the motor's side of the
  wire (the emulator's capture), from the last bytes or frame of the loop to the watchdog's frames; the bound
  is the timeout (100 ms) plus one interpreter switch interval (5 ms).
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))
can = pytest.importorskip("can")
pytest.importorskip("msgpack")

from test_controller_exit import run_against_emulator, watchdog_on_the_wire  # noqa: E402
from test_serial_can import can_bench, can_url, stop_bench  # noqa: E402

from host_tools.cli import main  # noqa: E402

RUNS = 3


def _can_stop(tmp: Path, mode: str) -> dict:
    url = can_url(mode)
    bench, imu = can_bench(url, tmp / "device")
    try:
        main(["run", "--motor", url, "--imu", imu, "--duration", "1.5", "--out", str(tmp / "out"), "--quiet"])
    finally:
        stop_bench(bench)
    return json.loads((tmp / "out" / "summary.json").read_text())["stop"]


def _watchdog(tmp: Path, link: str) -> tuple[float, float]:
    _, s, device = run_against_emulator(tmp, link, "Blocks", 3.5, "servo")
    return s["host_watchdog"]["silent_ms"], watchdog_on_the_wire(device, link)[0]


def test_can_stop_latency_and_host_watchdog_bound(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    def table() -> dict:
        rows: dict[str, dict] = {}
        for mode in ("servo", "mit"):
            stops = [_can_stop(tmp_path / f"can-{mode}-{k}", mode) for k in range(RUNS)]
            latencies = [s["latency_ms"] for s in stops]
            rows[f"CAN {mode} stop latency"] = {"median_ms": statistics.median(latencies),
                                                "goal_ms": stops[0]["goal_ms"], "runs": latencies}
        for link in ("uart", "can"):
            runs = [_watchdog(tmp_path / f"wd-{link}-{k}", link) for k in range(RUNS)]
            rows[f"host watchdog over {link}"] = {
                "median_ms": statistics.median(r[0] for r in runs), "goal_ms": 105.0,
                "wire_gap_median_ms": round(statistics.median(r[1] for r in runs), 3),
                "runs": [r[0] for r in runs]}
        return rows

    rows = benchmark.pedantic(table, rounds=1, iterations=1)
    print("\n| what | median ms | goal ms | on the motor's side (median ms) | runs |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {r['median_ms']} | {r['goal_ms']} | {r.get('wire_gap_median_ms', '')} | {r['runs']} |")
    benchmark.extra_info.update(rows)
    for name, r in rows.items():
        assert r["median_ms"] <= r["goal_ms"], (name, r)

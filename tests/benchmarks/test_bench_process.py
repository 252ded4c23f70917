"""What a user waits for and what the machine must hold: whole `pafp` processes (--benchmark-only).

Each figure is one `pafp` process started the way a user starts it (``python -m host_tools ...``), timed from
outside; its peak resident memory is the kernel's high-water mark of the process's own memory (``VmHWM`` in
/proc/self/status, read as it exits). Not ``ru_maxrss``: Linux carries the high-water mark of the memory a
child had before its exec into it, and a child forked from this pytest process starts with pytest's:

- ``test_bench_run_memory``: peak RSS of `pafp run` at 10, 100 and 1000 strides, all outputs on; goal: the
  1000-stride run within 1.3 x the 10-stride run.
- ``test_bench_decode_csv_memory``: peak RSS of `pafp decode --csv` on a 1 MB and a 10 MB VESC capture;
  goal: within 1.3 x.
- ``test_bench_whole_process_realtime_factor``: simulated time / process wall time of the default run (10
  strides, every output) and of 300 strides; goals >= 25 and >= 40. Also with ``--no-plot --no-trace``, and the
  simulation's own factor (``summary.json``) beside each.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

from host_tools.build_info import describe

MEMORY_GOAL = 1.3
DEFAULT_RUN_GOAL = 25.0
LONG_RUN_GOAL = 40.0


# `python -m host_tools ARGS`, which also writes its VmHWM to the file named by PAFP_HWM_FILE as it exits
_LAUNCH = ("import atexit, os, re, runpy, sys\n"
           "def hwm():\n"
           "    status = open('/proc/self/status').read()\n"
           "    open(os.environ['PAFP_HWM_FILE'], 'w').write(re.search(r'VmHWM:\\s+(\\d+)', status).group(1))\n"
           "atexit.register(hwm)\n"
           "sys.argv = ['pafp', *sys.argv[1:]]\n"
           "runpy.run_module('host_tools', run_name='__main__')\n")


def _process(args: list[str], cwd: Path) -> tuple[float, float, str]:
    """Run `pafp args` in a fresh process: (wall seconds, peak RSS in MB, stdout)."""
    hwm = cwd / "vmhwm.txt"
    env = {**os.environ, "PAFP_HWM_FILE": str(hwm)}
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _LAUNCH, *args], cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    assert proc.returncode in (0, 1), f"pafp {args} exited {proc.returncode}: {proc.stderr[-500:]}"
    return wall, int(hwm.read_text()) / 1024, proc.stdout


def test_bench_run_memory(benchmark, tmp_path: Path) -> None:
    rss: dict[int, float] = {}

    def measure() -> None:
        for strides in (10, 100, 1000):
            _, rss[strides], _ = _process(["run", "--quiet", "--strides", str(strides), "--out",
                                           str(tmp_path / f"run{strides}")], tmp_path)

    benchmark.pedantic(measure, rounds=1, iterations=1)
    info = benchmark.extra_info
    info["build"] = describe()
    info["peak_rss_mb"] = {str(k): round(v, 1) for k, v in rss.items()}
    info["ratio_1000_to_10"] = round(rss[1000] / rss[10], 3)
    info["goal_met"] = rss[1000] <= MEMORY_GOAL * rss[10]
    s = json.loads((tmp_path / "run1000" / "summary.json").read_text())
    assert s["strides"] == 1000 and s["complete"]


def _vesc_capture(path: Path, megabytes: int) -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from test_bench_codecs import build_capture

    one = build_capture()
    with path.open("wb") as f:
        for _ in range(megabytes):
            f.write(one.from_motor)


def test_bench_decode_csv_memory(benchmark, tmp_path: Path) -> None:
    rss: dict[int, float] = {}
    for mb in (1, 10):
        _vesc_capture(tmp_path / f"cap{mb}.bin", mb)

    def measure() -> None:
        for mb in (1, 10):
            _, rss[mb], _ = _process(["decode", "--protocol", "vesc", "--csv", str(tmp_path / f"cap{mb}.csv"),
                                      str(tmp_path / f"cap{mb}.bin")], tmp_path)

    benchmark.pedantic(measure, rounds=1, iterations=1)
    info = benchmark.extra_info
    info["capture_mb"] = {str(mb): round((tmp_path / f"cap{mb}.bin").stat().st_size / 1e6, 2) for mb in (1, 10)}
    info["peak_rss_mb"] = {str(k): round(v, 1) for k, v in rss.items()}
    info["ratio_10mb_to_1mb"] = round(rss[10] / rss[1], 3)
    info["goal_met"] = rss[10] <= MEMORY_GOAL * rss[1]
    rows = sum(1 for _ in (tmp_path / "cap10.csv").open()) - 1
    assert rows > 100_000


def test_bench_whole_process_realtime_factor(benchmark, tmp_path: Path) -> None:
    figures: dict[str, dict[str, float]] = {}

    def one(name: str, args: list[str]) -> None:
        out = tmp_path / name
        wall, _, _ = _process(["run", "--quiet", *args, "--out", str(out)], tmp_path)
        s = json.loads((out / "summary.json").read_text())
        figures[name] = {"sim_time_s": s["sim_time_s"], "process_wall_s": round(wall, 3),
                         "whole_process_factor": round(s["sim_time_s"] / wall, 2),
                         "simulation_factor": s["realtime_factor"],
                         "summary_process_factor": s["process_realtime_factor"]}

    def measure() -> None:
        one("default", [])
        one("default_no_plot_no_trace", ["--no-plot", "--no-trace"])
        one("strides300", ["--strides", "300"])
        one("strides300_no_plot_no_trace", ["--strides", "300", "--no-plot", "--no-trace"])

    benchmark.pedantic(measure, rounds=1, iterations=1)
    info = benchmark.extra_info
    info["build"] = describe()
    info.update(figures)
    info["goal_default_met"] = figures["default"]["whole_process_factor"] >= DEFAULT_RUN_GOAL
    info["goal_300_met"] = figures["strides300"]["whole_process_factor"] >= LONG_RUN_GOAL
    assert all(f["whole_process_factor"] > 0 for f in figures.values())

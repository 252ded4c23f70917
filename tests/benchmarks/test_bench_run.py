"""Speed of a whole firmware run on the virtual bench: realtime factor of 2 strides (--benchmark-only).

The realtime factor is simulated seconds per wall second of the scheduler's run (what ``pafp run``
prints), with the default trace on; it goes into ``benchmark.extra_info["realtime_factor"]`` (median over
the rounds). In the same session the pure-Python source (the tree copied without its compiled
extensions, see setup.py) runs the same 2 strides in a subprocess: ``pure_python_realtime_factor`` and
the ratio, measured side by side. ``default_run_realtime_factor`` is one default 10-stride run.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

from host_tools.build_info import compiled_sources, describe, run_pure_python
from host_tools.runner import RunConfig, run_virtual

ROUNDS = 5
PURE_SCRIPT = """
import statistics
from host_tools.runner import RunConfig, run_virtual
f = []
for _ in range({rounds}):
    r = run_virtual(RunConfig(strides=2))
    f.append(r.sim_time_s / r.wall_time_s)
print(statistics.median(f))
"""


def _pure_python_factor(tmp: Path) -> float:
    return float(run_pure_python(PURE_SCRIPT.format(rounds=ROUNDS), tmp).strip())


def test_bench_run_two_strides(benchmark, tmp_path: Path):
    factors: list[float] = []

    def run() -> float:
        result = run_virtual(RunConfig(strides=2))
        factors.append(result.sim_time_s / result.wall_time_s)
        return result.sim_time_s

    sim_s = benchmark.pedantic(run, rounds=ROUNDS, iterations=1)
    info = benchmark.extra_info
    info["build"] = describe()
    info["python"] = sys.version.split()[0] + " " + sys.executable
    info["realtime_factor"] = round(statistics.median(factors), 2)
    default = run_virtual(RunConfig())
    info["default_run_realtime_factor"] = round(default.sim_time_s / default.wall_time_s, 2)
    if compiled_sources():
        pure = _pure_python_factor(tmp_path)
        info["pure_python_realtime_factor"] = round(pure, 2)
        info["compiled_over_pure"] = round(info["realtime_factor"] / pure, 2)
    assert sim_s > 2.0
    assert all(f > 0.0 for f in factors)

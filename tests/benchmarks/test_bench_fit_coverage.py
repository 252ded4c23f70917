"""The fit's intervals over six plants (docs/calibration.md, "Limits"): how many identified parameter-runs fall inside
their reported 95 % interval.

The tests' 10 s identification experiment (tests/test_plant_fit_done_when.py's `[controller]` table) on
`--plant-seed` 3, 7, 11, 21, 42 and the hand-made plant file, each fitted with `pafp fit`'s defaults; the truth is
the emulator's (`host_tools.calibration.plant_truth`, emulation only). A calibrated marginal 95 % interval would
put about 95 % inside. Prints each plant's errors in half-widths and the count; records them in ``extra_info``.
The goal (at least 90 % inside) is warned about, not asserted. A few minutes.
"""

from __future__ import annotations

import math
import os
import time
import warnings
from pathlib import Path

from host_tools.calibration.fit_data import load_experiment
from host_tools.calibration.fit_model import load_base
from host_tools.calibration.plant_fit import fit_plant
from host_tools.calibration.plant_truth import truth_of
from host_tools.cli import main

ROOT = Path(__file__).resolve().parents[2]
HANDMADE = ROOT / "tests" / "data" / "plant_handmade.toml"
SHORT = ('\n[controller]\nname = "sysid"\nhold_s = 0.5\nsweep_deg = 12.0\nsweep_deg_s = 16.0\nchirp_s = 4.0\n'
         'prbs_s = 2.0\n')
PLANTS = [["--plant-seed", "3"], ["--plant-seed", "7"], ["--plant-seed", "11"], ["--plant-seed", "21"],
          ["--plant-seed", "42"], ["--plant", str(HANDMADE)]]
COVERAGE_GOAL = 0.90


def test_fit_interval_coverage(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + SHORT)

    def measure() -> dict:
        rows, inside, total, walls = {}, 0, 0, []
        for plant in PLANTS:
            run = tmp_path / plant[1].replace("/", "_")
            assert main(["run", "--experiment", "sysid", "--profile", str(tmp_path / "fw.toml"), *plant, "--quiet",
                         "--no-plot", "--no-trace", "--out", str(run)]) == 0
            t0 = time.perf_counter()
            r = fit_plant(load_base(None), load_experiment(run))
            walls.append(time.perf_counter() - t0)
            truth = truth_of(plant)
            errors = {n: abs(r.values[n] - truth[n]) / r.ci95[n] for n in r.names
                      if r.identifiable.get(n) and n in truth and r.ci95.get(n)}
            rows[plant[1] if plant[0] == "--plant-seed" else "hand-made"] = {n: round(e, 2) for n, e in errors.items()}
            inside += sum(e <= 1.0 for e in errors.values())
            total += len(errors)
        return {"inside": inside, "identified": total, "coverage": round(inside / max(total, 1), 3),
                "half_widths_off": rows, "fit_wall_s_max": round(max(walls), 1),
                "load_average_1min": round(os.getloadavg()[0], 2)}

    figures = benchmark.pedantic(measure, rounds=1, iterations=1)
    benchmark.extra_info.update(figures)
    print(f"\nfit intervals: {figures['inside']} of {figures['identified']} identified parameter-runs inside their "
          f"95 % interval ({100 * figures['coverage']:.1f} %) over {len(PLANTS)} plants; slowest fit "
          f"{figures['fit_wall_s_max']} s (load average {figures['load_average_1min']})")
    for plant, errors in figures["half_widths_off"].items():
        print(f"  {plant}: " + ", ".join(f"{n} {e}" for n, e in errors.items()))
    assert figures["identified"] >= 5 * len(PLANTS) and math.isfinite(figures["coverage"])
    if figures["coverage"] < COVERAGE_GOAL:
        warnings.warn(f"fit interval coverage {figures['coverage']:.3f} below the goal {COVERAGE_GOAL}", stacklevel=1)

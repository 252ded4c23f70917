"""The fit's intervals (docs/calibration.md): how many identified parameter-runs fall inside their reported 95 %
interval, the truth the emulator's (`host_tools.calibration.plant_truth`, emulation only).

- ``test_fit_interval_coverage`` ("Limits"): the tests' 10 s identification experiment
  (tests/fit_shared.py's `[controller]` table) on `--plant-seed` 3, 7, 11, 21, 42 and the hand-made
  plant file. A few minutes. Asserted on `--plant-seed 7` (issue 21's done-when, the hand-made plant's being
  tests/test_plant_fit_done_when.py's): every identified parameter within three half-widths of the truth, inertia,
  damping, gravity and Coulomb friction within 10 %.
- ``test_default_experiment_coverage`` ("What the tests measure"): the default 29 s experiment on `--plant-seed 7`
  with the noise seeds 0-7 and on the hand-made plant with 0 and 1, as `pafp run --experiment sysid --seed N` then
  `pafp fit` make them. About ten minutes.

- ``test_adequacy_flags_unmodelled_effects``: the model-adequacy check (host_tools/calibration/fit_adequacy.py) on the
  issue's four misspecified plants (`hal.virtual.plant.imperfections.MISSPECIFIED`, noise seed 0: Stribeck friction,
  friction 5 % of the transmitted torque and cogging on the tests' 10 s experiment, all three milder on the default
  29 s one): each must say "the model misses something" (asserted: fixed seeds, a deterministic verdict). The belt's
  compliance (`OTHER_PLANTS`), an effect the check was not built around, is fitted and reported beside them. The
  nominal plants' false alarms are counted by the two coverage benchmarks above, which fit correct models (goal: at
  most one recording in ten flagged; warned about). Each recording's share of encoder residuals beyond one count (the
  verdict's test) is printed beside its limit, and its largest cross-correlation |z| beside its bound: how far apart
  the two kinds of recording lie, not only which side of the limit.

- ``test_fit_under_a_rounding_nudge``: the tests' 10 s experiment on `--plant-seed 7` fitted as recorded and with
  its encoder angle, IMU pitch and current multiplied by 1 + 1e-12: how far apart the identified values come, in
  half-widths (goal 0.05: the answer must not hang on rounding).
- ``test_fit_under_another_kernel``: the hand-made plant's 10 s recording (tests/fit_shared.py's) fitted in this
  process and in a process of its own under another BLAS set-up (`other_kernel`: one thread, Sandybridge where the
  CPU has AVX) with its data nudged by 1e-12 (`NUDGED`): how far apart, in half-widths (issue 34's done-when: within
  0.05, asserted). A whole fit in another process (about a CPU minute here) is too long for `make test`, which checks
  the cause instead: the fit's cost has no steps at a hundredth of a half-width (tests/test_plant_located.py).

Each run is fitted with `pafp fit`'s defaults. A calibrated marginal 95 % interval would put about 95 % inside. Prints
each run's errors in half-widths and the count with its exact (Clopper-Pearson) 95 % confidence interval (the
parameter-runs taken as independent, which the parameters of one run are not: the interval is a lower bound on the
uncertainty); records them in ``extra_info``. The goal (at least 90 % inside) is warned about, not asserted.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

from host_tools.calibration.fit_adequacy import BEYOND_COUNT_LIMIT
from host_tools.calibration.fit_data import load_experiment
from host_tools.calibration.fit_model import base_values, load_base, residuals
from host_tools.calibration.plant_fit import fit_parts, fit_plant
from host_tools.calibration.plant_truth import truth_of
from host_tools.cli import main
from tests.fit_shared import HANDMADE, SHORT

ROOT = Path(__file__).resolve().parents[2]
PLANTS = [["--plant-seed", "3"], ["--plant-seed", "7"], ["--plant-seed", "11"], ["--plant-seed", "21"],
          ["--plant-seed", "42"], ["--plant", str(HANDMADE)]]
COVERAGE_GOAL = 0.90
NUDGE_GOAL = 0.05
ADEQUACY_FALSE_GOAL = 0.1  # correct-model recordings the adequacy check may flag
DYNAMICS = ("output_inertia_kg_m2", "foot_damping_nm_s_per_rad", "gravity_moment_nm", "coulomb_friction_nm")


# the fit of argv[1] with its encoder angle, IMU pitch, current and velocity multiplied by 1 + 1e-12: {name: value}
# into argv[2]
NUDGED = """
import json, sys
from pathlib import Path
from host_tools.calibration.fit_data import load_experiment
from host_tools.calibration.fit_model import base_values, load_base, residuals
from host_tools.calibration.plant_fit import fit_parts, fit_plant
exp = load_experiment(Path(sys.argv[1]))
exp.angle, exp.imu, exp.current, exp.vel = (x * (1.0 + 1e-12) for x in (exp.angle, exp.imu, exp.current, exp.vel))
Path(sys.argv[2]).write_text(json.dumps(fit_plant(load_base(None), exp).values))
"""


def other_kernel() -> dict[str, str]:
    """An OpenBLAS set-up other than the default one this CPU runs: one thread, and on an x86 CPU with AVX the
    Sandybridge kernel (numpy's and scipy's OpenBLAS both honour OPENBLAS_CORETYPE; a kernel the CPU lacks the
    instructions for would crash, so none is named without AVX)."""
    env = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        flags = ""
    if " avx " in flags or " avx\n" in flags:
        env["OPENBLAS_CORETYPE"] = "Sandybridge"
    return env


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact two-sided confidence interval of a proportion from k successes in n trials.

    >>> [round(x, 3) for x in clopper_pearson(88, 88)]
    [0.959, 1.0]
    """
    from scipy.stats import beta

    a = 1.0 - level
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def _coverage(runs: list[tuple[str, list[str], int]], profile: list[str], out: Path) -> dict:
    """Record, fit and score each (label, plant options, noise seed) run: the counts and each run's half-widths off."""
    rows, inside, total, walls, flagged, dynamics, largest, beyond = {}, 0, 0, [], {}, {}, {}, {}
    for label, plant, seed in runs:
        run = out / f"{label.replace('/', '_')}_{seed}"
        assert main(["run", "--experiment", "sysid", *profile, *plant, "--seed", str(seed), "--quiet", "--no-plot",
                     "--no-trace", "--out", str(run)]) == 0
        t0 = time.perf_counter()
        r = fit_plant(load_base(None), load_experiment(run))
        walls.append(time.perf_counter() - t0)
        truth = truth_of(plant, seed)
        errors = {n: abs(r.values[n] - truth[n]) / r.ci95[n] for n in r.names
                  if r.identifiable.get(n) and n in truth and r.ci95.get(n)}
        rows[label] = {n: round(e, 2) for n, e in errors.items()}
        dynamics[label] = {n: round(r.values[n] / truth[n] - 1, 4) for n in DYNAMICS if r.identifiable.get(n)}
        largest[label] = _largest_z(r.adequacy)
        beyond[label] = _beyond(r.adequacy)
        if r.adequacy.get("failing"):
            flagged[label] = r.adequacy["failing"]
        inside += sum(e <= 1.0 for e in errors.values())
        total += len(errors)
    lo, hi = clopper_pearson(inside, total)
    return {"inside": inside, "identified": total, "coverage": round(inside / max(total, 1), 3),
            "coverage_ci95": [round(lo, 3), round(hi, 3)],
            "half_widths_off": rows, "dynamics_relative_error": dynamics, "fit_wall_s_max": round(max(walls), 1),
            "adequacy_flagged": flagged, "adequacy_largest_z": largest, "adequacy_beyond_count": beyond,
            "recordings": len(runs),
            "load_average_1min": round(os.getloadavg()[0], 2)}


def _largest_z(adequacy: dict) -> float:
    """The largest |z| over every test of a fit's adequacy check (its verdict fails beyond the check's z_bound)."""
    return max((d["max_abs_z"] for sig in adequacy["tests"].values() for by in sig.values() for d in by.values()),
               default=0.0)


def _beyond(adequacy: dict) -> float:
    """The share of a fit's encoder residuals (both segments) beyond one count (the check fails it beyond
    `fit_adequacy.BEYOND_COUNT_LIMIT`)."""
    return adequacy.get("resolution", {}).get("share_beyond_one_count", 0.0)


def _report(benchmark, figures: dict, what: str, runs: int) -> None:  # type: ignore[no-untyped-def]
    benchmark.extra_info.update(figures)
    print(f"\nfit intervals, {what}: {figures['inside']} of {figures['identified']} identified parameter-runs inside "
          f"their 95 % interval ({100 * figures['coverage']:.1f} %, 95 % confidence "
          f"{100 * figures['coverage_ci95'][0]:.1f}-{100 * figures['coverage_ci95'][1]:.1f} %); slowest fit "
          f"{figures['fit_wall_s_max']} s (load average {figures['load_average_1min']})")
    for label, errors in figures["half_widths_off"].items():
        print(f"  {label}: " + ", ".join(f"{n} {e}" for n, e in errors.items()))
    flagged = figures["adequacy_flagged"]
    print(f"  model adequacy: {len(flagged)} of {figures['recordings']} correct-model recordings flagged (goal at most "
          f"one in ten); largest |z| of each: {figures['adequacy_largest_z']}; largest share of encoder residuals "
          f"beyond one count: {figures['adequacy_beyond_count']}"
          + "".join(f"\n    {label}: {'; '.join(f)}" for label, f in flagged.items()))
    if len(flagged) > ADEQUACY_FALSE_GOAL * figures["recordings"]:
        warnings.warn(f"the adequacy check flagged {len(flagged)} of {figures['recordings']} correct-model "
                      "recordings", stacklevel=2)
    assert figures["identified"] >= 5 * runs and math.isfinite(figures["coverage"])
    if figures["coverage"] < COVERAGE_GOAL:
        warnings.warn(f"fit interval coverage ({what}) {figures['coverage']:.3f} below the goal {COVERAGE_GOAL}",
                      stacklevel=2)


def test_fit_interval_coverage(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + SHORT)
    runs = [(p[1] if p[0] == "--plant-seed" else "hand-made", p, 0) for p in PLANTS]
    figures = benchmark.pedantic(_coverage, args=(runs, ["--profile", str(tmp_path / "fw.toml")], tmp_path),
                                 rounds=1, iterations=1)
    _report(benchmark, figures, f"10 s experiment, {len(PLANTS)} plants", len(runs))
    # issue 21's done-when on `--plant-seed 7` (the hand-made plant's: tests/test_plant_fit_done_when.py): a bias
    # bound, not a coverage claim (a calibrated interval misses by three half-widths about 4 times in a billion)
    seed7 = figures["half_widths_off"]["7"]
    assert len(seed7) >= 5 and max(seed7.values()) <= 3.0, seed7
    dynamics = figures["dynamics_relative_error"]["7"]
    assert len(dynamics) == len(DYNAMICS) and max(map(abs, dynamics.values())) < 0.10, dynamics


def test_default_experiment_coverage(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    runs = [(f"seed 7, noise {n}", ["--plant-seed", "7"], n) for n in range(8)]
    runs += [(f"hand-made, noise {n}", ["--plant", str(HANDMADE)], n) for n in range(2)]
    figures = benchmark.pedantic(_coverage, args=(runs, [], tmp_path), rounds=1, iterations=1)
    _report(benchmark, figures, "default 29 s experiment", len(runs))


def test_fit_under_a_rounding_nudge(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import numpy as np

    (tmp_path / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + SHORT)
    run = tmp_path / "seed7"
    assert main(["run", "--experiment", "sysid", "--profile", str(tmp_path / "fw.toml"), "--plant-seed", "7",
                 "--quiet", "--no-plot", "--no-trace", "--out", str(run)]) == 0

    def measure() -> dict:
        exp = load_experiment(run)
        a = fit_plant(load_base(None), exp)
        exp.angle, exp.imu, exp.current = (x * (1.0 + 1e-12) for x in (exp.angle, exp.imu, exp.current))
        exp.vel = exp.vel * (1.0 + 1e-12)
        b = fit_plant(load_base(None), exp)
        apart = {n: round(abs(a.values[n] - b.values[n]) / a.ci95[n], 4) for n in a.names
                 if a.identifiable.get(n) and a.ci95.get(n)}
        finite = bool(np.isfinite(list(apart.values())).all())
        return {"half_widths_apart": apart, "max": max(apart.values()), "finite": finite,
                "load_average_1min": round(os.getloadavg()[0], 2)}

    figures = benchmark.pedantic(measure, rounds=1, iterations=1)
    benchmark.extra_info.update(figures)
    print(f"\nfit under a 1e-12 nudge of the data: at most {figures['max']} half-widths apart (goal {NUDGE_GOAL}): "
          + ", ".join(f"{n} {e}" for n, e in figures["half_widths_apart"].items()))
    assert figures["finite"] and len(figures["half_widths_apart"]) >= 5
    if figures["max"] > NUDGE_GOAL:
        warnings.warn(f"the fit moved {figures['max']} half-widths under a 1e-12 nudge (goal {NUDGE_GOAL})",
                      stacklevel=2)


def test_fit_under_another_kernel(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    (tmp_path / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + SHORT)
    run = tmp_path / "hand-made"
    assert main(["run", "--experiment", "sysid", "--profile", str(tmp_path / "fw.toml"), "--plant", str(HANDMADE),
                 "--quiet", "--no-plot", "--no-trace", "--out", str(run)]) == 0

    def measure() -> dict:
        env = {**os.environ, **other_kernel(), "PYTHONPATH": str(ROOT)}
        other = subprocess.run([sys.executable, "-c", NUDGED, str(run), str(tmp_path / "other.json")], cwd=ROOT,
                               env=env, capture_output=True, text=True, timeout=3600)
        assert other.returncode == 0, other.stderr
        base, exp = load_base(None), load_experiment(run)
        a, b = fit_plant(base, exp), json.loads((tmp_path / "other.json").read_text())
        apart = {n: round(abs(a.values[n] - b[n]) / a.ci95[n], 4) for n in a.names
                 if a.identifiable.get(n) and a.ci95.get(n)}
        # the fit's cost (this process's kernel) on the line from its solution to the other's: which one is lower,
        # and how rough the cost is between them (an interval spans 1.92 of it)
        v, fit_part = {**base_values(base), **a.values}, fit_parts(exp)[0]
        line = {}
        for t in (0.0, 0.25, 0.5, 0.75, 1.0):
            r = residuals(base, {**v, **{n: v[n] + t * (b[n] - v[n]) for n in a.names}}, fit_part, a.noise_scales)
            line[str(t)] = round(0.5 * float(r @ r), 3)
        return {"half_widths_apart": apart, "max": max(apart.values()), "cost_along_the_line": line,
                "other_kernel": " ".join(f"{k}={x}" for k, x in other_kernel().items()),
                "load_average_1min": round(os.getloadavg()[0], 2)}

    figures = benchmark.pedantic(measure, rounds=1, iterations=1)
    benchmark.extra_info.update(figures)
    print(f"\nfit under {figures['other_kernel']} with the data nudged by 1e-12: at most {figures['max']} half-widths "
          f"apart (goal {NUDGE_GOAL}): " + ", ".join(f"{n} {e}" for n, e in figures["half_widths_apart"].items())
          + "\n  cost from this fit (0) to the other's (1): "
          + ", ".join(f"{t} {c}" for t, c in figures["cost_along_the_line"].items()))
    assert len(figures["half_widths_apart"]) >= 5 and math.isfinite(figures["max"])
    assert figures["max"] <= NUDGE_GOAL, figures["half_widths_apart"]


def test_adequacy_flags_unmodelled_effects(benchmark, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from hal.virtual.plant.imperfections import MISSPECIFIED, OTHER_PLANTS, profile_text

    (tmp_path / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + SHORT)

    def measure() -> dict:
        out = {}
        for name in (*MISSPECIFIED, *OTHER_PLANTS):
            (tmp_path / f"{name}.toml").write_text(profile_text(name))
            profile = [] if name == "all_milder" else ["--profile", str(tmp_path / "fw.toml")]
            run = tmp_path / name
            assert main(["run", "--experiment", "sysid", *profile, "--plant", str(tmp_path / f"{name}.toml"),
                         "--seed", "0", "--quiet", "--no-plot", "--no-trace", "--out", str(run)]) == 0
            r = fit_plant(load_base(None), load_experiment(run))
            out[name] = {"verdict": r.adequacy["verdict"], "failing": r.adequacy["failing"],
                         "largest_z": _largest_z(r.adequacy), "z_bound": r.adequacy["z_bound"],
                         "beyond_count": _beyond(r.adequacy),
                         "held_out_fit_percent": {k: round(v, 1) for k, v in r.fit_pct["held_out"].items()}}
        return out

    figures = benchmark.pedantic(measure, rounds=1, iterations=1)
    benchmark.extra_info.update(figures)
    print("\nmodel adequacy on plants with effects the fit lacks (noise seed 0):")
    for name, f in figures.items():
        print(f"  {name}: {f['verdict']} (largest |z| {f['largest_z']} against the bound {f['z_bound']}; encoder "
              f"residuals beyond one count {100 * f['beyond_count']:.2f} % against {100 * BEYOND_COUNT_LIMIT:g} %; "
              f"held-out fit % {f['held_out_fit_percent']})"
              + "".join(f"\n    {x}" for x in f["failing"]))
    # the four are asserted; the belt's compliance, an effect the check was not built around, is reported
    assert all(figures[name]["verdict"] == "the model misses something" for name in MISSPECIFIED), figures

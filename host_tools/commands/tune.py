"""`pafp tune`: automatic PID gain search on the emulator; writes the best gains as a firmware profile."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from host_tools.arguments import seed, study_cluster

HELP = "automatic PID gain search on the emulator (differential evolution on Dask, seeded): writes a tuned profile"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp tune`."""
    parser.add_argument("--strides", type=int, default=2, help="gait strides per candidate run (default 2)")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the candidate generator and the runs")
    parser.add_argument("--budget", type=int, default=48,
                        help="candidate runs in all, >= 5, spent in generations of 8 (default 48)")
    parser.add_argument("--out", type=Path, default=Path("runs") / "tune",
                        help="output directory (default runs/tune)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="worker processes of a LocalCluster on 127.0.0.1 (default: the number of cores)")
    where.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="an existing Dask scheduler: tcp://HOST:PORT or a scheduler file (.json) (docs/sweeps.md)")
    parser.add_argument("--profile", type=Path, default=None,
                        help="starting firmware profile (default profiles/firmware.toml)")
    parser.add_argument("--plant", type=Path, default=None, metavar="FILE",
                        help="plant profile TOML every candidate runs (keys of profiles/plant_ak60_6.toml, e.g. one "
                             "`pafp fit` wrote) instead of the packaged one; --plant-seed draws around it")
    parser.add_argument("--plant-seed", type=seed, default=None, metavar="N",
                        help="draw the plant's parameters from their tolerances around the plant profile with seed N "
                             "(the same draw for every candidate); default: no draw")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _plot(path: Path, before: object, after: object, title: str) -> None:
    """Before/after tracking: angle against the reference, and the error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from host_tools.outdir import save_figure

    fig, (ax_a, ax_e) = plt.subplots(2, 1, sharex=True, figsize=(9, 7), layout="constrained")
    ax_a.plot(before.t_s, before.reference_deg, "k", lw=1.5, label="reference")  # type: ignore[attr-defined]
    for case, label in ((before, "before"), (after, "after")):
        rms = case.summary["tracking"]["truth"]["rms_deg"]  # type: ignore[attr-defined]
        ax_a.plot(case.t_s, case.angle_deg, lw=0.9, label=f"{label} (RMS {rms:.3f}°)")  # type: ignore[attr-defined]
        err = case.angle_deg - np.interp(case.t_s, before.t_s, before.reference_deg)  # type: ignore[attr-defined]
        ax_e.plot(case.t_s, err, lw=0.8, label=label)  # type: ignore[attr-defined]
    ax_a.set_ylabel("ankle angle [deg]")
    ax_a.set_title(title)
    ax_a.legend(fontsize=8)
    ax_e.set_ylabel("error [deg]")
    ax_e.set_xlabel("time [s]")
    ax_e.legend(fontsize=8)
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    """Search, write firmware_tuned.toml, tune.json and tune.png, print the before/after figures.

    --out is checked before the search (exit 2). After SIGINT, SIGTERM or SIGHUP the search stops where it is
    and the best candidate so far is written (tune.json ``"complete": false``, no tune.png), exit 128 + N. A
    write that fails is one line, exit 74 (files are written whole or not at all).
    """
    from firmware.config import DEFAULT_PROFILE, load_firmware_config
    from host_tools.outdir import EXIT_WRITE_FAILED, check_writable, write_failed
    from host_tools.studies import tuning
    from host_tools.studies.interrupt import Interrupted, interrupting
    from host_tools.studies.sweep_engine import Progress, dask_client

    source = args.profile or DEFAULT_PROFILE
    try:
        base = load_firmware_config(source)
        if not 1 <= args.strides <= 100:
            raise ValueError(f"strides {args.strides!r} out of range: an int in 1..100")
        workers, where = study_cluster(args)
        tuning.check_budget(args.budget)
        plant = tuning.TunePlant(args.plant, args.plant_seed)
        plant.check()
        check_writable(args.out)
        on = "" if args.plant is None else f" on plant {args.plant}"
        on += "" if args.plant_seed is None else f" drawn with seed {args.plant_seed}"
        print(f"pafp tune: budget {args.budget} runs of {args.strides} strides on {where}, seed {args.seed}{on} "
              f"-> {args.out}")
        bar = Progress(args.budget, not args.quiet, label="candidates")
        with interrupting(), dask_client(workers=workers, scheduler=args.scheduler) as client:
            result = tuning.search(base, budget=args.budget, strides=args.strides, seed=args.seed, client=client,
                                   progress=lambda done, total: bar.step(), plant=plant)
    except ValueError as e:
        print(f"pafp tune: {e}", file=sys.stderr)
        return 2
    except Interrupted as stop:
        print(f"pafp tune: stopped by {stop.signal} before any candidate finished: nothing written", file=sys.stderr)
        return stop.exit_code
    try:
        return _write(args, source, base, result, where)
    except OSError as e:
        print(write_failed("tune", e, f"the files complete in {args.out} are kept"), file=sys.stderr)
        return EXIT_WRITE_FAILED


def _write(args: argparse.Namespace, source: Path, base: object, result: object, where: str) -> int:
    """Write the tuned profile, tune.json and (a finished search) tune.png; print the figures; the exit code."""
    from firmware.config import load_firmware_config
    from host_tools.outdir import write_atomic
    from host_tools.stop_signals import EXIT_CODES
    from host_tools.studies import tuning

    assert isinstance(result, tuning.TuneResult)
    out: Path = args.out
    profile_path = tuning.write_profile(source, result.best.gains, out / "firmware_tuned.toml")
    check = tuning.gains_of(load_firmware_config(profile_path))
    if any(abs(check[k] - v) > 1e-12 * max(1.0, abs(v)) for k, v in result.best.gains.items()):
        print(f"pafp tune: {profile_path} does not read back the tuned gains", file=sys.stderr)
        return 1
    if result.interrupted is None:
        from host_tools.benchtests.tracking import run_case  # 1.4 s of imports a stopped search does not wait for

        plant = tuning.TunePlant(args.plant, args.plant_seed).run_options()
        before = run_case("before", base, strides=args.strides, seed=args.seed, run_options=plant)
        after = run_case("after", tuning.with_gains(base, result.best.gains), strides=args.strides, seed=args.seed,
                         run_options=plant)
        _plot(out / "tune.png", before, after,
              f"pafp tune: {args.budget} candidates, {args.strides} strides, seed {args.seed}")
    else:  # no before/after runs after a stop signal: a tune.png of an earlier search would not match
        (out / "tune.png").unlink(missing_ok=True)
    doc = {
        "complete": result.interrupted is None,
        **({"interruption": {"by": result.interrupted, "candidates_run": len(result.evaluations)}}
           if result.interrupted else {}),
        "seed": args.seed, "budget": args.budget, "strides": args.strides, "workers": where,
        "plant": tuning.TunePlant(args.plant, args.plant_seed).as_dict(),
        "source_profile": str(source), "tuned_profile": str(profile_path),
        "objective": {"score": "rms_error_deg + effort_weight * (rms_current_a + rms_current_step_a)",
                      "effort_weight_deg_per_a": tuning.EFFORT_WEIGHT,
                      "saturation_max_fraction": tuning.SATURATION_MAX_FRACTION,
                      "stable_max_error_deg": tuning.STABLE_MAX_ERROR_DEG, "bounds": tuning.BOUNDS,
                      "search": "scipy.optimize.differential_evolution (log space, deferred updating)",
                      "population": tuning.POPULATION, "sigma0": tuning.SIGMA0, "mutation": tuning.MUTATION,
                      "recombination": tuning.RECOMBINATION},
        "before": result.start.as_dict(), "best": result.best.as_dict(),
        "evaluations": [e.as_dict() for e in result.evaluations],
    }
    write_atomic(out / "tune.json", json.dumps(doc, indent=2) + "\n")
    b, a = result.start, result.best
    print(f"  before: RMS {b.rms_error_deg:.4f} deg, max {b.max_error_deg:.4f} deg, score {b.score:.4f}")
    print(f"  after:  RMS {a.rms_error_deg:.4f} deg, max {a.max_error_deg:.4f} deg, score {a.score:.4f} "
          f"(candidate {a.index})")
    print("  gains: " + ", ".join(f"{k} {v:.4g}" for k, v in a.gains.items()))
    feasible = sum(e.feasible for e in result.evaluations)
    if result.interrupted is not None:
        print(f"pafp tune: stopped by {result.interrupted} after {len(result.evaluations)} of {args.budget} "
              f"candidates: the best so far is in {profile_path} and {out / 'tune.json'} (\"complete\": false)",
              file=sys.stderr)
        return EXIT_CODES.get(result.interrupted, 130)
    print(f"  {feasible}/{len(result.evaluations)} candidates feasible; outputs: {profile_path}, "
          f"{out / 'tune.json'}, {out / 'tune.png'}")
    return 0

"""`pafp sweep SPEC.toml`: a grid / Monte Carlo study of virtual runs on Dask; one row per point, a report."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

HELP = "sweep a spec's grid / Monte Carlo points on Dask (local or a cluster): results.parquet/.csv and a report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp sweep`."""
    parser.add_argument("spec", type=Path, help="sweep spec TOML (docs/sweeps.md)")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default runs/sweep-<spec name>)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="worker processes of a LocalCluster on 127.0.0.1 (default: the number of cores)")
    where.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="an existing Dask scheduler: tcp://HOST:PORT or a scheduler file (.json) (docs/sweeps.md)")
    parser.add_argument("--resume", action="store_true", help="keep the finished rows in --out and run the rest")
    parser.add_argument("--point", type=int, default=None, metavar="N",
                        help="run only point N here with the full outputs of `pafp run` (tracking.png, ...)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _one_point(spec: object, index: int, out: Path) -> int:
    from host_tools.report import write_outputs
    from host_tools.runner import run_virtual
    from host_tools.sweep_engine import tasks_of
    from host_tools.sweep_point import run_config_of

    tasks = tasks_of(spec)  # type: ignore[arg-type]
    if not 0 <= index < len(tasks):
        print(f"pafp sweep: --point {index} out of range: an int in 0..{len(tasks) - 1}", file=sys.stderr)
        return 2
    t = tasks[index]
    params = ", ".join(f"{k} = {v!r}" for k, v in t.params) or "base run"
    print(f"pafp sweep: point {index} ({params}; seed {t.seed}, plant seed {t.plant_seed}) -> {out}")
    s = write_outputs(run_virtual(run_config_of(t)), out, extra={"sweep_point": index, "plant_seed": t.plant_seed})
    print(f"  tracking: RMS {s['rms_error_deg']:.4f} deg, max {s['max_error_deg']:.4f} deg; deadline misses "
          f"{s['deadline_misses']}, faults {s['faults'] or 'none'}; outputs: {out}/report.md, tracking.png")
    return 0 if not s["deadline_misses"] and not s["faults"] else 1


def run(args: argparse.Namespace) -> int:
    """Check the spec whole, run the points not yet finished, write the tables and report.md."""
    from host_tools.sweep_engine import check_points, check_scheduler, dask_client, run_sweep
    from host_tools.sweep_report import write_report
    from host_tools.sweep_spec import load_spec
    from host_tools.sweep_table import check_out

    try:
        if args.workers is not None and not 1 <= args.workers <= 1024:
            raise ValueError(f"--workers {args.workers!r} out of range: an int in 1..1024")
        if args.scheduler is not None:
            check_scheduler(args.scheduler)
        spec = load_spec(args.spec)
        out: Path = args.out or Path("runs") / f"sweep-{spec.path.stem}"
        if args.point is not None:
            return _one_point(spec, args.point, out)
        check_points(spec)
        check_out(out, spec.digest, args.resume)  # before a cluster starts
    except ValueError as e:
        print(f"pafp sweep: {e}", file=sys.stderr)
        return 2
    workers = args.workers or os.cpu_count() or 1
    where = f"scheduler {args.scheduler}" if args.scheduler else f"LocalCluster of {workers} workers on 127.0.0.1"
    print(f"pafp sweep: {spec.n_points} points of {spec.run['strides']} strides on {where} -> {out}")
    try:
        with dask_client(workers=workers, scheduler=args.scheduler) as client:
            outcome = run_sweep(spec, out, client, resume=args.resume, progress=not args.quiet)
    except ValueError as e:  # --out holds another sweep, or rows without --resume
        print(f"pafp sweep: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        what = f"cannot reach the Dask scheduler {args.scheduler}" if args.scheduler else "cannot write the results"
        print(f"pafp sweep: {what}: {e}", file=sys.stderr)
        return 2
    report = write_report(spec, outcome.rows, out, wall_time_s=outcome.wall_time_s, where=where)
    bad = sum(r["status"] != "ok" for r in outcome.rows)
    print(f"  {outcome.ran} points run, {outcome.skipped} kept from before, in {outcome.wall_time_s:.1f} s; "
          f"{bad} with a fault or an error")
    print(f"  outputs: {out}/results.parquet, results.csv, {report.name}, plots/")
    return 0

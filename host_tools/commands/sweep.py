"""`pafp sweep SPEC.toml`: a grid / Monte Carlo study of virtual runs on Dask; one row per point, a report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from host_tools.arguments import add_study_options, study_cluster

HELP = "sweep a spec's grid / Monte Carlo points on Dask (local or a cluster): results.parquet/.csv and a report"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp sweep`."""
    parser.add_argument("spec", type=Path, help="sweep spec TOML (docs/sweeps.md)")
    add_study_options(parser, "sweep")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _one_point(spec: object, index: int, out: Path) -> int:
    """Point `index` alone, with the full outputs of `pafp run` staged and published into `out` as `pafp run`
    does (host_tools/reports/report.py: run_into): --out checked before the run, a failing write exits 74."""
    from host_tools.outdir import EXIT_WRITE_FAILED, RunDir, write_failed
    from host_tools.reports.report import run_into
    from host_tools.studies.sweep_engine import tasks_of
    from host_tools.studies.sweep_point import run_config_of

    tasks = tasks_of(spec)  # type: ignore[arg-type]
    if not 0 <= index < len(tasks):
        print(f"pafp sweep: --point {index} out of range: an int in 0..{len(tasks) - 1}", file=sys.stderr)
        return 2
    t = tasks[index]
    run_dir = RunDir(out)  # OutDirError (a ValueError): exit 2 before the run
    params = ", ".join(f"{k} = {v!r}" for k, v in t.params) or "base run"
    print(f"pafp sweep: point {index} ({params}; seed {t.seed}, plant seed {t.plant_seed}) -> {out}")
    try:
        _, s = run_into(run_config_of(t, trace=True), run_dir, extra={"sweep_point": index,
                                                                       "plant_seed": t.plant_seed})
    except OSError as e:
        print(write_failed("sweep", e, f"nothing published: {out} keeps what it held"), file=sys.stderr)
        return EXIT_WRITE_FAILED
    truth = s["tracking"]["truth"]
    print(f"  tracking (truth, emulation only): RMS {truth['rms_deg']:.4f} deg, max {truth['max_deg']:.4f} deg; "
          f"IMU RMS {s['imu_rms_error_deg']:.4f} deg; deadline misses {s['deadline_misses']}, faults "
          f"{s['faults'] or 'none'}; outputs: {out}/summary.json, report.md, tracking.png, trace.pftrace, "
          "telemetry.bin/.csv")
    return 0 if not s["deadline_misses"] and not s["faults"] else 1


def run(args: argparse.Namespace) -> int:
    """Check the spec whole, run the points not yet finished, write the tables and report.md.

    Exit 2 for a bad spec, option or --out (before any run); 74 when a result cannot be written during the
    sweep (the journal keeps every row written before); 128 + N after signal N (the report says how far the
    sweep got; --resume finishes it).
    """
    from host_tools.command_errors import study_error
    from host_tools.outdir import EXIT_WRITE_FAILED, check_writable, write_failed
    from host_tools.studies.interrupt import Interrupted, interrupting
    from host_tools.studies.sweep_engine import check_points, dask_client, run_sweep
    from host_tools.studies.sweep_report import write_report
    from host_tools.studies.sweep_spec import load_spec
    from host_tools.studies.sweep_table import check_out, kept_rows, read_rows

    try:
        workers, where = study_cluster(args)
        spec = load_spec(args.spec)
        out: Path = args.out or Path("runs") / f"sweep-{spec.path.stem}"
        if args.point is not None:
            return _one_point(spec, args.point, out)
        check_points(spec)
        check_writable(out)
        check_out(out, spec.digest, args.resume)  # before a cluster starts
    except ValueError as e:
        print(f"pafp sweep: {e}", file=sys.stderr)
        return 2
    print(f"pafp sweep: {spec.n_points} points of {spec.run['strides']} strides on {where} -> {out}")
    kept = kept_rows(out)
    try:
        with interrupting(), dask_client(workers=workers, scheduler=args.scheduler) as client:
            outcome = run_sweep(spec, out, client, resume=args.resume, progress=not args.quiet)
    except Interrupted as stop:  # the table was flushed and the cluster closed on the way out
        return _interrupted(spec, out, read_rows(out), stop, where)
    except (ValueError, OSError) as e:  # --out holds another sweep, a result file, the scheduler or the cluster
        line, status = study_error("sweep", args.scheduler, e, kept)
        print(line, file=sys.stderr)
        return status
    try:
        report = write_report(spec, outcome.rows, out, wall_time_s=outcome.wall_time_s, where=where)
    except OSError as e:
        print(write_failed("sweep", e, kept), file=sys.stderr)
        return EXIT_WRITE_FAILED
    bad = sum(r["status"] != "ok" for r in outcome.rows)
    print(f"  {outcome.ran} points run, {outcome.skipped} kept from before, in {outcome.wall_time_s:.1f} s; "
          f"{bad} with a fault or an error")
    print(f"  outputs: {out}/results.parquet, results.csv, {report.name}, plots/")
    return 0


def _interrupted(spec: object, out: Path, rows: list, stop: object, where: str) -> int:
    """After a stop signal: the report of the rows finished so far, marked interrupted; exit 128 + N."""
    from host_tools.outdir import EXIT_WRITE_FAILED, write_failed
    from host_tools.studies.interrupt import stopped_line
    from host_tools.studies.sweep_report import write_report

    print(stopped_line("sweep", stop, len(rows), spec.n_points, out), file=sys.stderr)  # type: ignore[arg-type,attr-defined]
    if rows:
        try:
            write_report(spec, rows, out, where=where, interrupted=stop.signal)  # type: ignore[arg-type,attr-defined]
        except OSError as e:
            print(write_failed("sweep", e, f"the rows are in {out}/rows.jsonl"), file=sys.stderr)
            return EXIT_WRITE_FAILED
    return stop.exit_code  # type: ignore[attr-defined,no-any-return]

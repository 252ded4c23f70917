"""`pafp faults SPEC.toml`: a fault-injection campaign on Dask; results.parquet, the hazard table in report.md."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from host_tools.arguments import add_study_options, study_cluster

HELP = ("run a fault-injection campaign (faults x onsets x durations x scenarios x controllers x links) on Dask: "
        "results.parquet and a hazard table; exit 1 when a criterion is not met by the safe state the profiles ship")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp faults`."""
    parser.add_argument("spec", type=Path, help="campaign spec TOML (docs/safety.md), e.g. "
                        "profiles/faults/default.toml")
    add_study_options(parser, "faults")
    parser.add_argument("--no-traces", action="store_true", help="leave the worst points' traces out of report.md")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def columns() -> list[str]:
    """The columns of results.parquet."""
    from host_tools.studies.fault_point import FIGURES, IDENTITY

    return [*IDENTITY, "status", "error", *FIGURES]


def _one_point(spec: object, index: int, out: Path) -> int:
    """Point `index` alone with the full outputs of `pafp run` (trace.json too), staged and published into `out` as
    `pafp run` does: --out checked before the run (exit 2), a failing write exits 74 and publishes nothing."""
    from host_tools.outdir import EXIT_WRITE_FAILED, RunDir, write_failed
    from host_tools.reports.report import run_into
    from host_tools.studies.fault_point import faulted_config

    points = spec.points()  # type: ignore[attr-defined]
    if not 0 <= index < len(points):
        print(f"pafp faults: --point {index} out of range: an int in 0..{len(points) - 1}", file=sys.stderr)
        return 2
    p = points[index]
    run_dir = RunDir(out)  # OutDirError (a ValueError): exit 2 before the run
    print(f"pafp faults: point {index} ({p.label()}; seed {p.seed}) -> {out}")
    cfg, fault, _obs, onset_s = faulted_config(p, trace=True)
    extra = {"fault_point": index, "fault": {"name": p.fault, "onset_s": onset_s, "duration_s": p.duration_s}}
    try:  # the injector's record is complete once the run is: added between the run and the writes
        _, s = run_into(cfg, run_dir, extra=extra, on_run=lambda: extra["fault"].update(fault.record.as_dict()))
    except OSError as e:
        print(write_failed("faults", e, f"nothing published: {out} keeps what it held"), file=sys.stderr)
        return EXIT_WRITE_FAILED
    print(f"  fault: {fault.describe()}; fired {fault.record.count} times, first at {fault.record.first_s} s "
          f"({fault.record.what}); supervisor: {', '.join(s['faults']) or 'no fault latched'}; outputs: "
          f"{out}/report.md, summary.json, trace.pftrace, telemetry.bin/.csv")
    return 0 if fault.record.fired else 1


def run(args: argparse.Namespace) -> int:
    """Check the spec and criteria whole, run the points not yet finished, write the table and report.md.

    Exit 2 for a bad spec, criteria, option or --out (before any run, before the cluster starts); 1 when a
    criterion is not met or a point gave no figures; 74 when a result cannot be written during the campaign (the
    journal keeps every row written before); 128 + N after signal N (report.md holds the points finished so far;
    --resume runs the rest).
    """
    from host_tools.command_errors import study_error
    from host_tools.outdir import EXIT_WRITE_FAILED, check_writable, write_failed
    from host_tools.studies.fault_point import fault_error_row, run_fault_point
    from host_tools.studies.fault_report import check_criteria, load_criteria, write_fault_report
    from host_tools.studies.fault_spec import load_fault_spec
    from host_tools.studies.interrupt import Interrupted, interrupting, stopped_line
    from host_tools.studies.sweep_engine import dask_client, run_tasks
    from host_tools.studies.sweep_table import check_out, kept_rows, read_rows

    try:
        workers, where = study_cluster(args)
        spec = load_fault_spec(args.spec)
        criteria = load_criteria(spec.criteria)
        out: Path = args.out or Path("runs") / f"faults-{spec.path.stem}"
        if args.point is not None:
            return _one_point(spec, args.point, out)
        check_writable(out)  # writable, 1 MiB free: before a cluster starts
        check_out(out, spec.digest, args.resume)
    except ValueError as e:
        print(f"pafp faults: {e}", file=sys.stderr)
        return 2
    points = spec.points()
    kept = kept_rows(out)
    print(f"pafp faults: {len(points)} points on {where} -> {out}")
    interrupted = None
    try:
        with interrupting(), dask_client(workers=workers, scheduler=args.scheduler) as client:
            outcome = run_tasks(points, run_fault_point, out, client, columns=columns(), digest=spec.digest,
                                error_row=fault_error_row, resume=args.resume, progress=not args.quiet)
        rows, wall_time_s = outcome.rows, outcome.wall_time_s
    except Interrupted as stop:  # the table was flushed and the cluster closed on the way out
        interrupted, rows, wall_time_s = stop, read_rows(out), stop.elapsed_s
        print(stopped_line("faults", stop, len(rows), len(points), out), file=sys.stderr)
        if not rows:
            return stop.exit_code
    except (ValueError, OSError) as e:  # --out holds another study, a result file, the scheduler or the cluster
        line, status = study_error("faults", args.scheduler, e, kept)
        print(line, file=sys.stderr)
        return status
    failures = check_criteria(rows, criteria)
    try:
        report = write_fault_report(spec, rows, out, failures, criteria, wall_time_s, where,
                                    traces=not args.no_traces and interrupted is None,
                                    interrupted=(interrupted.signal, len(points)) if interrupted else None)
    except OSError as e:
        print(write_failed("faults", e, kept), file=sys.stderr)
        return EXIT_WRITE_FAILED
    if interrupted is not None:
        return interrupted.exit_code
    errors = [r for r in rows if r["status"] != "ok"]
    print(f"  {outcome.ran} points run, {outcome.skipped} kept from before, in {wall_time_s:.1f} s; "
          f"{len(errors)} without figures; outputs: {out}/results.parquet, results.csv, {report.name}, plots/")
    for r in errors[:20]:
        print(f"pafp faults: point {r['point']} ({r['fault']}): {r['status']}: {r['error']}", file=sys.stderr)
    verdict = [f for f in failures if f.judged]
    for f in verdict:
        print(f"pafp faults: {f.line(spec)}", file=sys.stderr)
    if len(verdict) < len(failures):
        print(f"pafp faults: {len(failures) - len(verdict)} criterion lines of the compared safe states (not judged: "
              f"not the profiles' own) in {report}", file=sys.stderr)
    return 1 if verdict or errors else 0

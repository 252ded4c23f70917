"""`pafp faults SPEC.toml`: a fault-injection campaign on Dask; results.parquet, the hazard table in report.md."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from host_tools.arguments import add_study_options, study_cluster

HELP = ("run a fault-injection campaign (faults x onsets x durations x scenarios x controllers x links) on Dask: "
        "results.parquet and a hazard table; exit 1 when a criterion is not met")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp faults`."""
    parser.add_argument("spec", type=Path, help="campaign spec TOML (docs/safety.md), e.g. "
                        "profiles/faults/default.toml")
    add_study_options(parser, "faults")
    parser.add_argument("--no-traces", action="store_true", help="leave the worst points' traces out of report.md")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def columns() -> list[str]:
    """The columns of results.parquet."""
    from host_tools.studies.fault_point import FIGURES

    return ["point", "fault", "params", "scenario", "body_mass_kg", "controller", "link", "onset_phase",
            "duration_s", "seed", "status", "error", *FIGURES]


def _one_point(spec: object, index: int, out: Path) -> int:
    from host_tools.reports.report import write_outputs
    from host_tools.studies.fault_point import faulted_run

    points = spec.points()  # type: ignore[attr-defined]
    if not 0 <= index < len(points):
        print(f"pafp faults: --point {index} out of range: an int in 0..{len(points) - 1}", file=sys.stderr)
        return 2
    p = points[index]
    print(f"pafp faults: point {index} ({p.label()}; seed {p.seed}) -> {out}")
    r, fault, _obs, onset_s = faulted_run(p, trace=True)
    s = write_outputs(r, out, extra={"fault_point": index, "fault": {"name": p.fault, "onset_s": onset_s,
                                                                      "duration_s": p.duration_s,
                                                                      **fault.record.as_dict()}})
    print(f"  fault: {fault.describe()}; fired {fault.record.count} times, first at {fault.record.first_s} s "
          f"({fault.record.what}); supervisor: {', '.join(s['faults']) or 'no fault latched'}; outputs: "
          f"{out}/report.md")
    return 0 if fault.record.fired else 1


def run(args: argparse.Namespace) -> int:
    """Check the spec and criteria whole, run the points not yet finished, write the table and report.md."""
    from host_tools.command_errors import study_error
    from host_tools.studies.fault_point import fault_error_row, run_fault_point
    from host_tools.studies.fault_report import check_criteria, load_criteria, write_fault_report
    from host_tools.studies.fault_spec import load_fault_spec
    from host_tools.studies.sweep_engine import dask_client, run_tasks
    from host_tools.studies.sweep_table import JOURNAL, check_out

    try:
        workers, where = study_cluster(args)
        spec = load_fault_spec(args.spec)
        criteria = load_criteria(spec.criteria)
        out: Path = args.out or Path("runs") / f"faults-{spec.path.stem}"
        if args.point is not None:
            return _one_point(spec, args.point, out)
        check_out(out, spec.digest, args.resume)  # before a cluster starts
    except ValueError as e:
        print(f"pafp faults: {e}", file=sys.stderr)
        return 2
    points = spec.points()
    print(f"pafp faults: {len(points)} points on {where} -> {out}")
    try:
        with dask_client(workers=workers, scheduler=args.scheduler) as client:
            outcome = run_tasks(points, run_fault_point, out, client, columns=columns(), digest=spec.digest,
                                error_row=fault_error_row, resume=args.resume, progress=not args.quiet)
    except (ValueError, OSError) as e:  # --out holds another study, a result file, the scheduler or the cluster
        line, status = study_error("faults", args.scheduler, e, f"every row finished before it is in {out}/{JOURNAL} "
                                   "(--resume runs the rest)")
        print(line, file=sys.stderr)
        return status
    failures = check_criteria(outcome.rows, criteria)
    report = write_fault_report(spec, outcome.rows, out, failures, criteria, outcome.wall_time_s, where,
                                traces=not args.no_traces)
    errors = [r for r in outcome.rows if r["status"] != "ok"]
    print(f"  {outcome.ran} points run, {outcome.skipped} kept from before, in {outcome.wall_time_s:.1f} s; "
          f"{len(errors)} without figures; outputs: {out}/results.parquet, results.csv, {report.name}, plots/")
    for r in errors[:20]:
        print(f"pafp faults: point {r['point']} ({r['fault']}): {r['status']}: {r['error']}", file=sys.stderr)
    for f in failures:
        print(f"pafp faults: {f.line(spec)}", file=sys.stderr)
    return 1 if failures or errors else 0

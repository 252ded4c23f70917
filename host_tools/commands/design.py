"""`pafp design SPEC.toml`: a design search on Dask; results.parquet, design.md with the Pareto front, pareto.png."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from host_tools.arguments import add_study_options, study_cluster

HELP = ("search actuator designs (motor x belt x spring x battery x body mass x speed), each a walking run of the "
        "firmware, on Dask: results.parquet, design.md (Pareto front, the lightest design that walks each body mass "
        "and speed), pareto.png")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of `pafp design`."""
    parser.add_argument("spec", type=Path, help="search spec TOML (docs/design.md), e.g. profiles/designs/adult.toml")
    add_study_options(parser, "design")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def columns() -> list[str]:
    """The columns of results.parquet."""
    from host_tools.studies.design_point import AXES, FIGURES

    return ["point", *AXES, "status", "error", *FIGURES]


def _write_profiles(points: list, out: Path) -> None:
    """Each point's design profile into its directory (a user reruns it with the row's `pafp run` command)."""
    from host_tools.outdir import write_atomic

    for p in points:
        path = Path(p.profile_name)
        path.parent.mkdir(parents=True, exist_ok=True)
        if not path.is_file() or path.read_text(encoding="utf-8") != p.profile_text:
            write_atomic(path, p.profile_text)


def _one_point(points: list, index: int) -> int:
    from host_tools.studies.design_point import rerun_command, run_design_point

    if not 0 <= index < len(points):
        print(f"pafp design: --point {index} out of range: an int in 0..{len(points) - 1}", file=sys.stderr)
        return 2
    p = points[index]
    _write_profiles([p], Path(p.profile_name).parent)
    print(f"pafp design: point {index} ({p.label()}) -> {Path(p.profile_name).parent}; the same run: "
          f"{rerun_command(p)}")
    row = run_design_point(p)
    print(f"  {row['status']}{': ' + row['error'] if row['error'] else ''}; moment share {row['moment_share']}, "
          f"peak {row['peak_current_a']} A, actuator {row['actuator_kg']} kg")
    return 0 if row["status"] == "ok" else 1


def run(args: argparse.Namespace) -> int:
    """Check the spec whole (every design's profile built), run the points not yet finished, write the report.

    Exit 2 for a bad spec, option or --out (before any run, before the cluster starts); 1 when a point gave no
    figures (error, timeout); 74 when a result cannot be written during the search; 128 + N after signal N
    (design.md holds the points finished so far; --resume runs the rest).
    """
    from host_tools.command_errors import study_error
    from host_tools.outdir import EXIT_WRITE_FAILED, check_writable, write_failed
    from host_tools.studies.design_point import design_error_row, run_design_point
    from host_tools.studies.design_report import write_design_report
    from host_tools.studies.design_spec import load_design_spec
    from host_tools.studies.interrupt import Interrupted, interrupting, stopped_line
    from host_tools.studies.sweep_engine import dask_client, run_tasks
    from host_tools.studies.sweep_table import check_out, kept_rows, read_rows

    try:
        workers, where = study_cluster(args)
        spec = load_design_spec(args.spec)
        out: Path = args.out or Path("runs") / f"design-{spec.path.stem}"
        points = spec.points(out)
        if args.point is not None:
            return _one_point(points, args.point)
        check_writable(out)  # writable, 1 MiB free: before a cluster starts
        check_out(out, spec.digest, args.resume)
        _write_profiles(points, out)
    except ValueError as e:
        print(f"pafp design: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"pafp design: cannot write the design profiles: {e}", file=sys.stderr)
        return 2
    print(f"pafp design: {len(points)} points ({len(spec.designs())} designs) on {where} -> {out}")
    kept = kept_rows(out)
    try:
        with interrupting(), dask_client(workers=workers, scheduler=args.scheduler) as client:
            outcome = run_tasks(points, run_design_point, out, client, columns=columns(), digest=spec.digest,
                                error_row=design_error_row, resume=args.resume, progress=not args.quiet,
                                ok=lambda row: row["status"] in ("ok", "fault"))
    except Interrupted as stop:  # the table was flushed and the cluster closed on the way out
        rows = read_rows(out)
        print(stopped_line("design", stop, len(rows), len(points), out), file=sys.stderr)
        try:
            if rows:
                write_design_report(spec, points, rows, out, stop.elapsed_s, f"{where}, stopped by {stop.signal}")
        except OSError as e:
            print(write_failed("design", e, kept), file=sys.stderr)
            return EXIT_WRITE_FAILED
        return stop.exit_code
    except (ValueError, OSError) as e:  # --out holds another study, a result file, the scheduler or the cluster
        line, status = study_error("design", args.scheduler, e, kept)
        print(line, file=sys.stderr)
        return status
    try:
        report = write_design_report(spec, points, outcome.rows, out, outcome.wall_time_s, where)
    except OSError as e:
        print(write_failed("design", e, kept), file=sys.stderr)
        return EXIT_WRITE_FAILED
    errors = [r for r in outcome.rows if r["status"] not in ("ok", "fault")]
    print(f"  {outcome.ran} points run, {outcome.skipped} kept from before, in {outcome.wall_time_s:.1f} s; "
          f"{len(errors)} without figures; outputs: {out}/{report.name}, pareto.png, results.parquet, results.csv")
    for r in errors[:20]:
        print(f"pafp design: point {r['point']}: {r['status']}: {r['error']}", file=sys.stderr)
    return 1 if errors else 0

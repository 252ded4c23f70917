"""`pafp bench`: reproduce the report's plant-level bench-top tests and compare with its figures."""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from host_tools.benchtests import TESTS
from host_tools.benchtests.output import BenchResult, Figure, markdown_table, write_outputs

HELP = ("reproduce the report's bench-top tests (uncontrolled, backdrive, fast-response, loading, tracking, "
        "baud-study, link-study, all)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register TEST, --out, --seed and --quick."""
    parser.add_argument("test", choices=[*TESTS, "all"], help="which bench test to run, or all")
    parser.add_argument("--out", type=Path, default=None,
                        help="directory for the PNG, CSV, JSON and Markdown outputs (none written if omitted)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the trial variation (default 0)")
    parser.add_argument("--quick", action="store_true", help="shorter runs and fewer trials")


def _run_one(name: str, seed: int, quick: bool) -> BenchResult:
    """Run one test; a test whose module is missing gives a row saying so instead of a number."""
    try:
        module = importlib.import_module(f"host_tools.benchtests.{TESTS[name]}")
    except ImportError as exc:
        return BenchResult(name, [Figure("(not available)", "", "", None, None, f"not available: {exc}",
                                         basis="assumed: nothing (the test did not run)")])
    return module.run(seed=seed, quick=quick)


def run(args: argparse.Namespace) -> int:
    """Run the selected test(s), write outputs if --out is given, print the comparison table.

    --out is checked before any test runs (exit 2); a write that fails afterwards is one line, exit 74 (the
    files already written stay complete, none is left half-written).
    """
    from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError, check_writable, write_failed

    if args.out is not None:
        try:
            check_writable(args.out)
        except OutDirError as e:
            print(f"pafp bench: {e}", file=sys.stderr)
            return 2
    names = list(TESTS) if args.test == "all" else [args.test]
    results = []
    for n in names:
        print(f"pafp bench: {n} ...", file=sys.stderr)
        results.append(_run_one(n, args.seed, args.quick))
    print(markdown_table(results), end="")
    if args.out is not None:
        for r in results:
            try:
                paths = write_outputs(r, args.out)
            except OSError as e:
                print(write_failed("bench", e, f"the files written before it in {args.out} are complete"),
                      file=sys.stderr)
                return EXIT_WRITE_FAILED
            for path in paths:
                print(f"wrote {path}", file=sys.stderr)
    return 0

"""`pafp bench`: reproduce the report's plant-level bench-top tests and compare with its figures."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from host_tools.benchtests import TESTS
from host_tools.benchtests.output import BenchResult, Figure, markdown_table, write_outputs

HELP = f"reproduce the report's bench-top tests ({', '.join(TESTS.names())}, all)"


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
        module = TESTS.load(name)
    except ValueError as exc:  # its module cannot be imported
        return BenchResult(name, [Figure("(not available)", "", "", None, None, f"not available: {exc}",
                                         basis="assumed: nothing (the test did not run)")])
    return module.run(seed=seed, quick=quick)


def run(args: argparse.Namespace) -> int:
    """Run the selected test(s), write outputs if --out is given, print the comparison table."""
    names = list(TESTS) if args.test == "all" else [args.test]
    results = []
    for n in names:
        print(f"pafp bench: {n} ...", file=sys.stderr)
        results.append(_run_one(n, args.seed, args.quick))
    if args.out is not None:
        for r in results:
            for path in write_outputs(r, args.out):
                print(f"wrote {path}", file=sys.stderr)
    print(markdown_table(results), end="")
    return 0

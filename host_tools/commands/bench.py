"""`pafp bench`: reproduce the report's plant-level bench-top tests and compare with its figures."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hal.virtual.plant import load_plant_params
from hal.virtual.plant.readings import GEOMETRIES, geometry_of, with_geometry
from host_tools.arguments import seed
from host_tools.benchtests import TESTS
from host_tools.benchtests.output import BenchResult, Figure, markdown_table, write_outputs

HELP = f"reproduce the report's bench-top tests ({', '.join(TESTS.names())}, all)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register TEST, --out, --seed and --quick."""
    parser.add_argument("test", choices=[*TESTS, "all", "readings-table"],
                        help="which bench test to run, all, or readings-table (the report's figures under both "
                             "geometries and both IMU readings: docs/bench.md)")
    parser.add_argument("--out", type=Path, default=None,
                        help="directory for the PNG, CSV, JSON and Markdown outputs (none written if omitted)")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the trial variation (default 0)")
    parser.add_argument("--quick", action="store_true", help="shorter runs and fewer trials")
    parser.add_argument("--geometry", choices=[*GEOMETRIES, "both"], default=None,
                        help="the gravity geometry the plant tests run under (docs/bench.md, 'Readings'): level-com "
                             "(the profile's), hanging (report eq 3.55) or both; default: both for 'all', the "
                             "profile's for one test")


def _run_one(name: str, seed: int, quick: bool, geometry: str | None = None) -> BenchResult:
    """Run one test under a geometry (None: the profile's); a missing module gives a row saying so.

    A test whose READINGS say its geometry is "n/a" does not depend on it and runs as it is.
    """
    try:
        module = TESTS.load(name)
    except ValueError as exc:  # its module cannot be imported
        return BenchResult(name, [Figure("(not available)", "", "", None, None, f"not available: {exc}",
                                         basis="assumed: nothing (the test did not run)")])
    readings = dict(getattr(module, "READINGS", {}))
    kwargs: dict = {}
    if readings.get("geometry") != "n/a":
        params = load_plant_params()
        if geometry is not None:
            params = with_geometry(params, geometry)
        kwargs["params"] = params
        readings = {"geometry": geometry_of(params), **readings}
    result: BenchResult = module.run(seed=seed, quick=quick, **kwargs)
    result.readings = readings
    return result


def _is_bench_output(path: Path) -> bool:
    """Whether path is a file `pafp bench` writes (<test>.png/.csv/.json/.md, readings_table.md) or a geometry's
    directory holding only such files."""
    if path.is_dir():
        return path.name in GEOMETRIES and all(_is_bench_output(p) and p.is_file() for p in path.iterdir())
    stems = {n.replace("-", "_") for n in TESTS}
    return path.name == "readings_table.md" or (path.suffix in (".png", ".csv", ".json", ".md")
                                                 and path.stem in stems)


def check_bench_dir(out: Path) -> None:
    """OutDirError when an existing --out holds anything but `pafp bench` outputs (it would overwrite or mix with
    a directory of other files): an empty directory, a new one or a previous bench's is taken."""
    from host_tools.outdir import OutDirError

    if not out.is_dir():
        return
    other = sorted(p.name for p in out.iterdir() if not _is_bench_output(p))
    if other:
        raise OutDirError(f"--out {out} holds files that are not pafp bench outputs (e.g. {other[0]!r}): name a new "
                          "directory, an empty one or a previous bench's")


def plan(test: str, geometry: str | None) -> list[tuple[str, str | None]]:
    """The (test, geometry) runs a command line asks for: 'all' runs the geometry-dependent tests under both."""
    names = list(TESTS) if test == "all" else [test]
    if geometry is None:
        geometry = "both" if test == "all" else None
    geometries: list[str | None] = list(GEOMETRIES) if geometry == "both" else [geometry]
    runs: list[tuple[str, str | None]] = []
    for n in names:
        module = TESTS.load(n)
        independent = getattr(module, "READINGS", {}).get("geometry") == "n/a"
        runs += [(n, None)] if independent else [(n, g) for g in geometries]
    return runs


def run(args: argparse.Namespace) -> int:
    """Run the selected test(s), write outputs if --out is given, print the comparison table.

    With more than one geometry the outputs of each go to DIR/<geometry>/ (tests that do not depend on the
    geometry: DIR/). --out is checked before any test runs (exit 2); a write that fails afterwards is one
    line, exit 74 (the files already written stay complete, none is left half-written).
    """
    from host_tools.outdir import EXIT_WRITE_FAILED, OutDirError, check_writable, write_atomic, write_failed

    if args.out is not None:
        try:
            check_writable(args.out)
            check_bench_dir(args.out)
        except OutDirError as e:
            print(f"pafp bench: {e}", file=sys.stderr)
            return 2
    if args.test == "readings-table":
        from host_tools.benchtests.readings_table import default_runner, readings_table

        table = readings_table(default_runner)
        print(table, end="")
        if args.out is not None:
            try:
                args.out.mkdir(parents=True, exist_ok=True)
                write_atomic(args.out / "readings_table.md", table)
            except OSError as e:
                print(write_failed("bench", e, "nothing else was to be written"), file=sys.stderr)
                return EXIT_WRITE_FAILED
            print(f"wrote {args.out / 'readings_table.md'}", file=sys.stderr)
        return 0
    runs = plan(args.test, args.geometry)
    split = len({g for _, g in runs if g is not None}) > 1
    results = []
    for n, g in runs:
        print(f"pafp bench: {n}" + (f" [{g}]" if g else "") + " ...", file=sys.stderr)
        results.append(_run_one(n, args.seed, args.quick, g))
    print(markdown_table(results), end="")
    if args.out is not None:
        for r in results:
            g = r.readings.get("geometry", "n/a")
            out = args.out / g if split and g != "n/a" else args.out
            try:
                paths = write_outputs(r, out)
            except OSError as e:
                print(write_failed("bench", e, f"the files written before it in {args.out} are complete"),
                      file=sys.stderr)
                return EXIT_WRITE_FAILED
            for path in paths:
                print(f"wrote {path}", file=sys.stderr)
    return 0

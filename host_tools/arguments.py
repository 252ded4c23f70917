"""Option types of the `pafp` command line: a bad value is refused by argparse in one line naming the option,
the value and the allowed range (``argument --seed: -1 is not allowed: must be an integer >= 0``)."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable

from firmware.control.validation import interval

__all__ = ["add_study_options", "float_in", "int_in", "seed", "study_cluster"]


def int_in(lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer in [lo, hi] (hi None: no upper bound).

    >>> int_in(1, 10)("3")
    3
    >>> int_in(1, 10)("0")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: 0 is not allowed: must be an integer in [1, 10]
    """
    allowed = f"an integer >= {lo}" if hi is None else f"an integer in [{lo}, {hi}]"

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < lo or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"{text} is not allowed: must be {allowed}")
        return value

    parse.__name__ = "integer"
    return parse


def float_in(lo: float, hi: float = math.inf, *, lo_open: bool = False, hi_open: bool = False,
             unit: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number in the interval (nan and inf refused).

    >>> float_in(0.0, lo_open=True, unit="s")("nan")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: nan is not allowed: must be a finite number in (0, inf) s
    """
    allowed = f"a finite number in {interval(lo, hi, lo_open, hi_open or math.isinf(hi))}{' ' + unit if unit else ''}"

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value) and (value > lo if lo_open else value >= lo) and (
            value < hi if hi_open else value <= hi)
        if not ok:
            raise argparse.ArgumentTypeError(f"{text} is not allowed: must be {allowed}")
        return value

    parse.__name__ = "number"
    return parse


seed = int_in(0)
"""A seed: numpy's SeedSequence takes any integer >= 0."""


def add_study_options(parser: argparse.ArgumentParser, what: str) -> None:
    """The options of a study on the sweep engine (`pafp sweep`, `pafp faults`): --out (default runs/WHAT-<spec
    name>), --workers or --scheduler, --resume and --point."""
    from pathlib import Path

    parser.add_argument("--out", type=Path, default=None, help=f"output directory (default runs/{what}-<spec name>)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="worker processes of a LocalCluster on 127.0.0.1 (default: the number of cores)")
    where.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="an existing Dask scheduler: tcp://HOST:PORT or a scheduler file (.json) (docs/sweeps.md)")
    parser.add_argument("--resume", action="store_true", help="keep the finished rows in --out and run the rest")
    parser.add_argument("--point", type=int, default=None, metavar="N",
                        help="run only point N here with the full outputs of `pafp run` (tracking.png, ...)")


def study_cluster(args: argparse.Namespace) -> tuple[int, str]:
    """(workers, where the study runs) from the options of add_study_options; ValueError in one line for a --workers
    out of range or a --scheduler that is neither a file nor an address with a port (before any cluster starts)."""
    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise ValueError(f"--workers {args.workers!r} out of range: an int in 1..1024")
    if args.scheduler is not None:
        from host_tools.studies.sweep_engine import check_scheduler  # Dask only for the studies

        check_scheduler(args.scheduler)
    workers = args.workers or os.cpu_count() or 1
    where = f"scheduler {args.scheduler}" if args.scheduler else f"LocalCluster of {workers} workers on 127.0.0.1"
    return workers, where

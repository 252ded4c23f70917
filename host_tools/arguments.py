"""Option types of the `pafp` command line: a bad value is refused by argparse in one line naming the option,
the value and the allowed range (``argument --seed: -1 is not allowed: must be an integer >= 0``)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from firmware.control.validation import interval

__all__ = ["float_in", "int_in", "seed"]


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

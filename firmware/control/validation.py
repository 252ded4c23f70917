"""Argument checks shared by the control modules: one ValueError wording for every bad number."""

from __future__ import annotations

import math


def is_number(value: object) -> bool:
    """True for a finite int or float (bool excluded)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def check_range(name: str, value: float, lo: float, hi: float, *, lo_open: bool = False,
                hi_open: bool = False, unit: str = "") -> float:
    """Return value as float if it is a finite number within [lo, hi] (ends open on request), else ValueError.

    >>> check_range("ts_s", 0.001, 0.0, 1.0, lo_open=True, unit="s")
    0.001
    >>> check_range("ts_s", 2, 0.0, 1.0, lo_open=True, unit="s")
    Traceback (most recent call last):
    ...
    ValueError: ts_s = 2 is not allowed: must be a finite number in (0, 1] s
    """
    ok = is_number(value)
    if ok:
        ok = (value > lo if lo_open else value >= lo) and (value < hi if hi_open else value <= hi)
    if not ok:
        suffix = f" {unit}" if unit else ""
        raise ValueError(f"{name} = {value!r} is not allowed: must be a finite number in "
                         f"{interval(lo, hi, lo_open, hi_open)}{suffix}")
    return float(value)


def interval(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False) -> str:
    """An interval as written in the messages.

    >>> interval(0.0, 1.0, lo_open=True)
    '(0, 1]'
    """
    return f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def check_int_range(name: str, value: int, lo: int, hi: int) -> int:
    """Return value if it is an int (not bool) within [lo, hi], else ValueError."""
    if not (isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi):
        raise ValueError(f"{name} = {value!r} is not allowed: must be an integer in [{lo}, {hi}]")
    return value

"""Argument checks shared by the virtual MCU's pieces: counts and rates given as ints, configuration ranges.

Parameters checked here are typed ``object`` at their constructors (docs/compiled.md, "Values checked as
given").
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import fields
from typing import Any

__all__ = ["check_field_ranges", "check_int", "from_table"]


def check_int(label: str, value: object, minimum: int) -> int:
    """Return ``value`` if it is an int >= minimum (a bool is not), else ValueError naming label and value.

    >>> check_int("baud", True, 1)
    Traceback (most recent call last):
    ...
    ValueError: baud True out of range: an int >= 1
    """
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{label} {value!r} out of range: an int >= {minimum}")
    return value


def check_field_ranges(config: Any, ranges: Mapping[str, tuple[float, float]]) -> None:
    """Raise ValueError naming the first field of dataclass ``config`` not a finite number in its [lo, hi].

    Fields without an entry in ``ranges`` are not checked; a bool is not a number here.

    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Cfg:
    ...     rate_hz: float = 100.0
    >>> check_field_ranges(Cfg(5e3), {"rate_hz": (1.0, 1000.0)})
    Traceback (most recent call last):
    ...
    ValueError: Cfg.rate_hz = 5000.0 is outside the allowed range [1.0, 1000.0]
    """
    for f in fields(config):
        bounds = ranges.get(f.name)
        if bounds is None:
            continue
        lo, hi = bounds
        value = getattr(config, f.name)
        if isinstance(value, bool) or not isinstance(value, int | float) or not (
                math.isfinite(value) and lo <= value <= hi):
            raise ValueError(f"{type(config).__name__}.{f.name} = {value!r} is outside the allowed range [{lo}, {hi}]")


def from_table(cls: Any, table: Mapping[str, Any], section: str) -> Any:
    """The dataclass ``cls`` built from a profile table; keys ending in ``_source`` (citations) are skipped.

    ValueError naming the section and an unknown key.
    """
    values = {k: v for k, v in table.items() if not k.endswith("_source")}
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"[{section}] has no key {unknown[0]!r}: known {sorted(known)}")
    return cls(**values)

"""Profiles whose every number carries its source: ``key = { value = 0.078, source = "maker: ..." }``.

The motor catalogue (``profiles/motors/``) and the battery profiles (``profiles/batteries/``) are
written this way, so a test can check that no figure is left without a citation. A value that is not
published says so: its source starts with ``"assumed:"`` and gives the reason.

>>> spec = {"mass_kg": (0.01, 20.0)}
>>> read_sourced_table({"mass_kg": {"value": 0.368, "source": "maker"}}, spec, "motor", "x.toml")
{'mass_kg': 0.368}
>>> read_sourced_table({"mass_kg": {"value": 368.0, "source": "maker"}}, spec, "motor", "x.toml")
Traceback (most recent call last):
...
ValueError: x.toml: motor.mass_kg = 368.0 is outside the allowed range [0.01, 20.0]
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

#: Prefix of the source of a value that no maker or paper publishes.
ASSUMED = "assumed:"


def resolve_profile(name_or_path: str | Path, directory: str, what: str) -> Path:
    """A path as given, or the packaged ``profiles/<directory>/<name>.toml``; ValueError if unknown."""
    from profiles import profile_path, profile_paths

    text = str(name_or_path)
    if isinstance(name_or_path, Path) or text.endswith(".toml") or "/" in text:
        return Path(name_or_path)
    path = profile_path(f"{directory}/{text}.toml")
    if not path.is_file():
        known = ", ".join(p.stem for p in profile_paths(f"{directory}/*.toml"))
        raise ValueError(f"{what} {text!r} is not in profiles/{directory}/ (known: {known})")
    return path


def read_profile(path: str | Path, what: str = "profile") -> dict[str, Any]:
    """Parse a TOML profile; ValueError names the file (and the line of a syntax error; profiles.read_toml)."""
    from profiles import read_toml

    return read_toml(Path(path), what)


def sourced_value(entry: object, key: str, table: str, where: str) -> tuple[object, str]:
    """Split ``{value = ..., source = "..."}`` into (value, source); ValueError if either is missing."""
    if not isinstance(entry, dict) or set(entry) != {"value", "source"}:
        raise ValueError(
            f"{where}: {table}.{key} must be a table {{ value = ..., source = \"...\" }}, got {entry!r}")
    source = entry["source"]
    if not isinstance(source, str) or not source.strip():
        raise ValueError(f"{where}: {table}.{key} has no source (give the maker table, paper or 'assumed: why')")
    return entry["value"], source


def check_number(value: object, key: str, table: str, where: str, lo: float, hi: float) -> float:
    """``value`` as a float if it is a finite number in [lo, hi]; else ValueError naming all of it."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or not lo <= float(value) <= hi:  # type: ignore[arg-type]
        raise ValueError(f"{where}: {table}.{key} = {value!r} is outside the allowed range [{lo}, {hi}]")
    return float(value)  # type: ignore[arg-type]


def read_sourced_table(
    data: dict[str, Any], spec: dict[str, tuple[float, float]], table: str, where: str,
) -> dict[str, float]:
    """Values of one table of numbers, each range-checked against ``spec``; unknown or missing keys fail."""
    unknown = sorted(set(data) - set(spec))
    if unknown:
        raise ValueError(f"{where}: unknown key {table}.{unknown[0]} (allowed: {', '.join(sorted(spec))})")
    missing = [k for k in spec if k not in data]
    if missing:
        raise ValueError(f"{where}: missing key {table}.{missing[0]}")
    out: dict[str, float] = {}
    for key, (lo, hi) in spec.items():
        value, _ = sourced_value(data[key], key, table, where)
        out[key] = check_number(value, key, table, where, lo, hi)
    return out


def sources_of(data: dict[str, Any]) -> dict[str, str]:
    """Every ``table.key -> source`` of a sourced profile (for listing and for the citation test)."""
    out: dict[str, str] = {}
    for table_name, table in data.items():
        if not isinstance(table, dict):
            continue
        for key, entry in table.items():
            if isinstance(entry, dict) and "source" in entry:
                out[f"{table_name}.{key}"] = str(entry["source"])
    return out

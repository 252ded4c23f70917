"""Checks shared by the study specs read from TOML (`pafp faults`, `pafp design`): each failure is one SpecError line
``<kind> <path>: <where> = <value> out of range: <allowed>``, where kind names the spec ("fault spec", ...).

A spec module makes one `SpecValues` (its kind and the table its lists sit in) and uses its checks."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from host_tools.studies.sweep_spec import SpecError

__all__ = ["SpecValues"]


class SpecValues:
    """The checks of one kind of spec ("fault spec"), whose lists sit in ``table`` ("[campaign]")."""

    def __init__(self, kind: str, table: str) -> None:
        """Errors name `kind`; `nonempty_list` names `table`."""
        self.kind = kind
        self.table = table

    def error(self, path: Path, where: str, value: object, allowed: str) -> SpecError:
        """The one-line error of a value out of range."""
        return SpecError(f"{self.kind} {path}: {where} = {value!r} out of range: {allowed}")

    def number(self, path: Path, where: str, v: object, lo: float, hi: float, low_open: bool = False) -> float:
        """v as a float when it is a finite number in [lo, hi] (``(lo, hi]`` when low_open).

        >>> SpecValues("x spec", "[a]").number(Path("s.toml"), "[a] b", 2.0, 0.0, 1.0)
        Traceback (most recent call last):
        ...
        host_tools.studies.sweep_spec.SpecError: x spec s.toml: [a] b = 2.0 out of range: a number in [0, 1]
        """
        ok = (not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
              and (lo < v if low_open else lo <= v) and v <= hi)
        if not ok:
            raise self.error(path, where, v, f"a number in {'(' if low_open else '['}{lo:g}, {hi:g}]")
        return float(v)  # type: ignore[arg-type]

    def integer(self, path: Path, where: str, v: object, lo: int, hi: int) -> int:
        """v when it is an int (not a bool) in lo..hi."""
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise self.error(path, where, v, f"an int in {lo}..{hi}")
        return v

    def choice(self, path: Path, where: str, v: object, choices: Any) -> str:
        """v when it is a string among ``choices`` (a list, a dict or a registry), else the one-line error."""
        if not isinstance(v, str) or v not in choices:
            raise self.error(path, where, v, f"one of {', '.join(choices)}")
        return v

    def file(self, path: Path, where: str, v: object) -> Path:
        """The existing file v names, relative to the spec's folder (v must be a string)."""
        if not isinstance(v, str) or not v or not (path.parent / v).is_file():
            raise self.error(path, where, v, "an existing file, relative to the spec")
        return (path.parent / v).resolve()

    def nonempty_list(self, path: Path, doc: dict[str, Any], key: str, default: list[Any]) -> list[Any]:
        """doc[key] (default if absent) when it is a non-empty list without repeats (doc is the spec's table)."""
        v = doc.get(key, default)
        if not isinstance(v, list) or not v:
            raise self.error(path, f"{self.table} {key}", v, "a non-empty list")
        if len(set(map(repr, v))) != len(v):
            raise self.error(path, f"{self.table} {key}", v, "a list without repeats")
        return v

    def read(self, path: Path, tables: tuple[str, ...]) -> tuple[str, dict[str, Any]]:
        """(the text, the parsed TOML) of a spec whose top-level tables are among ``tables`` (``"[[fault]]"`` for an
        array of tables)."""
        try:
            text = path.read_text(encoding="utf-8")
            doc = tomllib.loads(text)
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
            raise SpecError(f"{self.kind} {path}: cannot be read as TOML ({type(e).__name__}: {e})") from None
        shapes = {t.strip("[]"): t for t in tables}
        unknown = sorted(set(doc) - set(shapes))
        if unknown:
            raise SpecError(f"{self.kind} {path}: table {unknown[0]!r} unknown: {', '.join(tables)}")
        for key, value in doc.items():
            self._check_shape(path, shapes[key], value)
        return text, doc

    def _check_shape(self, path: Path, table: str, value: object) -> None:
        """SpecError unless ``value`` has the shape ``table`` names: a table for ``[x]``, an array of tables for
        ``[[x]]`` (``x = "..."`` or ``[[x]]`` where ``[x]`` belongs are refused here, not as a TypeError later).

        >>> SpecValues("x spec", "[a]")._check_shape(Path("s.toml"), "[a]", [{}])
        Traceback (most recent call last):
        ...
        host_tools.studies.sweep_spec.SpecError: x spec s.toml: key 'a' is an array of tables ([[a]]): expected \
a table, written [a]
        """
        name = table.strip("[]")
        many = table.startswith("[[")
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            got = f"an array of tables ([[{name}]])"
        elif isinstance(value, dict):
            got = f"a table ([{name}])"
        else:
            got = f"a {type(value).__name__} ({name} = {value!r:.40})"
        if (many and got.startswith("an array")) or (not many and got.startswith("a table")):
            return
        want = f"an array of tables, each written [[{name}]]" if many else f"a table, written [{name}]"
        raise SpecError(f"{self.kind} {path}: key {name!r} is {got}: expected {want}")

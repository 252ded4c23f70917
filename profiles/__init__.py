"""The packaged TOML profiles (board, plant, firmware, task sets), found with importlib.resources.

The directory stays at the top of the source tree and installs as the package ``profiles``, so the
same lookup works in the checkout, in an editable install and in an installed wheel:

>>> profile_path("firmware.toml").name
'firmware.toml'
>>> sorted(p.name for p in profile_paths("board_*.toml"))
['board_stm32f1.toml', 'board_stm32f4.toml']
"""

from __future__ import annotations

import re
import tomllib
from importlib.resources import files
from pathlib import Path
from typing import Any

__all__ = ["profile_path", "profile_paths", "profiles_dir", "read_toml", "toml_field"]


def profiles_dir() -> Path:
    """The directory holding the packaged profiles (an installed package is always plain files)."""
    root = files(__name__)
    if not isinstance(root, Path):  # e.g. imported from a zip archive: not how pip installs it
        raise RuntimeError(f"pafp's profiles are not plain files ({root!r}): install pafp with pip")
    return root


def profile_path(name: str) -> Path:
    """Path of the packaged profile ``name``, e.g. ``"firmware.toml"`` or ``"tasksets/davis2007.toml"``."""
    return profiles_dir() / name


def profile_paths(pattern: str) -> list[Path]:
    """The packaged profiles whose names match the glob ``pattern`` (sorted)."""
    return sorted(profiles_dir().glob(pattern))


def read_toml(path: Path, what: str) -> dict[str, Any]:
    """The TOML document at ``path``; ValueError in one line naming ``what``, the file and, for a syntax error, the
    line (cannot read it, not a UTF-8 text file, not valid TOML).

    ``what`` names the kind of file, e.g. "firmware profile". Every TOML file pafp reads goes through here, and
    the values it takes from the document through :func:`toml_field`.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ValueError(f"cannot read {what} {path}: {e.strerror or e}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"{what} {path}: not a UTF-8 TOML file (byte 0x{data[e.start]:02x} at offset "
                         f"{e.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{what} {path}: not valid TOML{_toml_where(str(e), text)}") from None


_AT = re.compile(r"\s*\(at (?:line (\d+), column (\d+)|end of document)\)$")


def _toml_where(message: str, text: str) -> str:
    """`` at line N, column M: <what tomllib says>`` from a TOMLDecodeError's message."""
    m = _AT.search(message)
    if m is None:
        return f": {message}"
    where = (f"line {m[1]}, column {m[2]}" if m[1]
             else f"line {max(1, text.count(chr(10)) + (not text.endswith(chr(10))))} (the end of the file)")
    return f" at {where}: {message[:m.start()]}"


_MISSING: Any = object()


def toml_field(doc: Any, key: str, expected: type | tuple[type, ...], path: Path | str, what: str,
               table: str = "", default: Any = _MISSING) -> Any:
    """``doc[key]`` when it has the ``expected`` type (a bool is not a number here); ValueError in one line naming
    the file, the key and what was expected when it is missing (and no default is given), has another type, or
    ``doc`` itself is not a table. ``table`` names where doc sits in the file (``"[campaign]"``).

    >>> toml_field({"teeth": "12"}, "teeth", int, "d.toml", "design spec", "[belt]")
    Traceback (most recent call last):
    ...
    ValueError: design spec d.toml: [belt] teeth = '12': expected an integer
    >>> toml_field({}, "firmware", dict, "r.bin", "record header")
    Traceback (most recent call last):
    ...
    ValueError: record header r.bin: key 'firmware' missing: expected a table
    """
    where = f"{table} {key}".strip()
    types = expected if isinstance(expected, tuple) else (expected,)
    if not isinstance(doc, dict):
        raise ValueError(f"{what} {path}: {table or 'the document'} is {_kind(doc)}: expected a table")
    if key not in doc:
        if default is not _MISSING:
            return default
        raise ValueError(f"{what} {path}: key {where!r} missing: expected {_expected(types)}")
    value = doc[key]
    if isinstance(value, bool) and bool not in types or not isinstance(value, types):
        raise ValueError(f"{what} {path}: {where} = {_short(value)}: expected {_expected(types)}")
    return value


_NAMES = {dict: "a table", list: "an array", str: "a string", int: "an integer", float: "a number", bool: "a boolean"}


def _expected(types: tuple[type, ...]) -> str:
    names = [_NAMES.get(t, t.__name__) for t in types if not (t is int and float in types)]
    return " or ".join(names)


def _kind(value: object) -> str:
    return _NAMES.get(type(value), type(value).__name__)


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."

"""The packaged TOML profiles (board, plant, firmware, task sets), found with importlib.resources.

The directory stays at the top of the source tree and installs as the package ``profiles``, so the
same lookup works in the checkout, in an editable install and in an installed wheel:

>>> profile_path("firmware.toml").name
'firmware.toml'
>>> sorted(p.name for p in profile_paths("board_*.toml"))
['board_stm32f1.toml', 'board_stm32f4.toml']
"""

from __future__ import annotations

import tomllib
from importlib.resources import files
from pathlib import Path
from typing import Any

__all__ = ["profile_path", "profile_paths", "profiles_dir", "read_toml"]


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
    """The TOML document at ``path``; ValueError in one line naming ``what`` and the file when it cannot be.

    ``what`` names the kind of file, e.g. "firmware profile" (cannot read it, not UTF-8, not valid TOML).
    """
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ValueError(f"cannot read {what} {path}: {e.strerror or e}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{what} {path} is not a text file (not UTF-8)") from None
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{what} {path} is not valid TOML: {e}") from None

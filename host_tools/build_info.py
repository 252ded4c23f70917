"""Which modules run compiled (mypyc, see setup.py) and whether those builds are newer than their source.

A compiled module is an extension file (``app.cpython-311-x86_64-linux-gnu.so``) beside its ``.py``;
Python imports the extension first, so an extension older than its source runs stale code. That can only
happen in a source tree (a checkout with ``setup.py``, installed editable): an installed wheel's files
carry the times they were unpacked at, so there the check is skipped.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from importlib.machinery import EXTENSION_SUFFIXES
from pathlib import Path

__all__ = ["ROOT", "compiled_sources", "copy_pure_source", "describe", "is_source_tree", "run_pure_python",
           "stale_sources", "version"]

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("firmware", "protocol", "hal", "rtos", "host_tools")


def _extension_of(source: Path) -> Path | None:
    for suffix in EXTENSION_SUFFIXES:
        ext = source.with_name(source.stem + suffix)
        if ext.exists():
            return ext
    return None


def compiled_sources(root: Path = ROOT) -> list[Path]:
    """The ``.py`` files of our packages that have a compiled extension beside them (sorted)."""
    return sorted(p for pkg in PACKAGES for p in (root / pkg).rglob("*.py") if _extension_of(p) is not None)


def is_source_tree(root: Path = ROOT) -> bool:
    """Whether root is a checkout (it has setup.py and pyproject.toml), not an installed package."""
    return (root / "setup.py").is_file() and (root / "pyproject.toml").is_file()


def version() -> str:
    """The installed distribution's version (pyproject.toml), or "unknown" when pafp is not installed."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as dist_version

    try:
        return dist_version("pafp")
    except PackageNotFoundError:
        return "unknown (not installed)"


def stale_sources(root: Path = ROOT) -> list[Path]:
    """Compiled sources edited after their extension was built (source trees only): rebuild with ``make install``."""
    if not is_source_tree(root):
        return []
    out = []
    for src in compiled_sources(root):
        ext = _extension_of(src)
        if ext is not None and src.stat().st_mtime > ext.stat().st_mtime:
            out.append(src)
    return out


def describe(root: Path = ROOT) -> str:
    """One line for reports: how many modules run compiled, or that the package is pure Python."""
    n = len(compiled_sources(root))
    if not n:
        return "pure Python (no compiled modules; see setup.py)"
    stale = stale_sources(root)
    note = f", {len(stale)} STALE (older than their source: run make install)" if stale else ""
    return f"{n} hot-path modules compiled with mypyc{note}"


def copy_pure_source(dest: Path, root: Path = ROOT) -> Path:
    """Copy the packages and profiles into dest without their extensions; return dest.

    The copy is the pure-Python build, importable with ``PYTHONPATH=dest``: the two builds side by side.
    """
    for name in (*PACKAGES, "profiles"):
        shutil.copytree(root / name, dest / name, ignore=shutil.ignore_patterns("*.so", "__pycache__"))
    return dest


_PURE_CHECK = 'import rtos.scheduler; assert rtos.scheduler.__file__.endswith(".py"), rtos.scheduler.__file__\n'


def run_pure_python(script: str, dest: Path, timeout_s: float = 600.0) -> str:
    """Run Python ``script`` on a pure-Python copy of the source made in dest; return its stdout.

    The script first checks that it imports the ``.py`` files; a failure raises
    ``subprocess.CalledProcessError`` (its ``stderr`` says why).
    """
    copy_pure_source(dest)
    out = subprocess.run([sys.executable, "-c", _PURE_CHECK + script], cwd=dest, capture_output=True, text=True,
                         timeout=timeout_s, env={"PYTHONPATH": str(dest), "PATH": "/usr/bin:/bin"}, check=True)
    return out.stdout

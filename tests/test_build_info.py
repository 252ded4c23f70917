"""host_tools.build_info: which modules are compiled and whether an extension is older than its source."""

from __future__ import annotations

import os
from importlib.machinery import EXTENSION_SUFFIXES
from pathlib import Path

from host_tools.build_info import compiled_sources, describe, is_source_tree, stale_sources, version


def _tree(root: Path, source_tree: bool = True) -> tuple[Path, Path]:
    if source_tree:  # a checkout; an installed package has neither file
        (root / "setup.py").write_text("")
        (root / "pyproject.toml").write_text("")
    pkg = root / "rtos"
    pkg.mkdir()
    src = pkg / "scheduler.py"
    src.write_text("x = 1\n")
    (pkg / "clock.py").write_text("y = 2\n")  # no extension beside it: interpreted
    ext = pkg / ("scheduler" + EXTENSION_SUFFIXES[0])
    ext.write_bytes(b"")
    return src, ext


def test_a_source_with_an_extension_beside_it_is_compiled(tmp_path: Path) -> None:
    src, _ = _tree(tmp_path)
    assert compiled_sources(tmp_path) == [src]
    assert describe(tmp_path) == "1 hot-path modules compiled with mypyc"
    assert describe(tmp_path / "nothing").startswith("pure Python")


def test_an_edited_source_makes_its_extension_stale(tmp_path: Path) -> None:
    src, ext = _tree(tmp_path)
    os.utime(ext, (1_000_000, 1_000_000))
    os.utime(src, (1_000_000, 1_000_000))
    assert stale_sources(tmp_path) == []
    os.utime(src, (1_000_100, 1_000_100))  # edited after the build
    assert stale_sources(tmp_path) == [src]
    assert "1 STALE" in describe(tmp_path)


def test_an_installed_package_is_never_stale(tmp_path: Path) -> None:
    """Unpacking a wheel gives its files arbitrary times: without a source tree there is nothing to rebuild."""
    src, ext = _tree(tmp_path, source_tree=False)
    os.utime(ext, (1_000_000, 1_000_000))
    os.utime(src, (1_000_100, 1_000_100))
    assert not is_source_tree(tmp_path)
    assert stale_sources(tmp_path) == []
    assert describe(tmp_path) == "1 hot-path modules compiled with mypyc"


def test_version_is_the_installed_distributions() -> None:
    from importlib.metadata import version as dist_version

    assert version() == dist_version("pafp")

"""Collection rules for the compiled build (setup.py): doctests of compiled modules run from their source.

pytest's ``--doctest-modules`` cannot collect a module whose import gives an extension file, so the
compiled modules are left out here and ``tests/test_compiled_doctests.py`` runs their doctests on the
``.py`` source. A compiled module older than its source would test stale code: the run stops.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from host_tools.build_info import compiled_sources, stale_sources

_COMPILED = {p.resolve() for p in compiled_sources()}


def pytest_configure(config: pytest.Config) -> None:
    stale = stale_sources()
    if stale:
        names = ", ".join(str(p.relative_to(Path(__file__).parent)) for p in stale)
        raise pytest.UsageError(f"compiled modules older than their source ({names}): run `make install`")


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    return True if collection_path.resolve() in _COMPILED else None

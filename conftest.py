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
_OSL = Path(__file__).parent / "host_tools" / "osl"
_NEEDS_OPENSOURCELEG = {(_OSL / name).resolve() for name in ("virtual_leg.py", "example_controller.py", "walk_osl.py")}
"""Modules of the osl extra: their doctests are collected only where opensourceleg is installed."""


def pytest_configure(config: pytest.Config) -> None:
    stale = stale_sources()
    if stale:
        names = ", ".join(str(p.relative_to(Path(__file__).parent)) for p in stale)
        raise pytest.UsageError(f"compiled modules older than their source ({names}): run `make install`")


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    path = collection_path.resolve()
    if path in _NEEDS_OPENSOURCELEG:
        import importlib.util

        return True if importlib.util.find_spec("opensourceleg") is None else None
    return True if path in _COMPILED else None


REALTIME = {"test_serial_faults.py", "test_emulate_bursts.py", "test_controller_exit.py", "test_contract_studies.py"}
"""Test files paced by the wall clock (a second process, a busy core of their own, a host watchdog, signals to a
campaign): `make test` runs them after the rest, alone (``-m realtime``), since a second xdist worker beside them
starves what they time (measured on this 2-core machine under -n 2: the first two failed in two runs of two, the
last two once in a fresh clone's run)."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.name in REALTIME:
            item.add_marker(pytest.mark.realtime)

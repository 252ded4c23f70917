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


REALTIME: dict[str, tuple[str, ...] | None] = {
    "test_serial_faults.py": None,  # None: every test of the file
    "test_emulate_bursts.py": None,
    "test_controller_exit.py": ("test_serial_run_over_", "test_blocking_controller_"),
    "test_contract_studies.py": ("test_faults_stopped_by_a_signal", "test_fit_stopped_by_sigterm"),
    "test_safe_serial.py": None,  # serial runs against `pafp emulate bench` in a second process
    "test_design_serial.py": None,
    "test_serial_can.py": ("test_serial_run_on_can_",),
}
"""Tests paced by the wall clock (a second process, a busy core of their own, a host watchdog, signals to a study),
by file and test-name prefix: `make test` runs them one at a time in a run of their own (``-m realtime``) beside the
rest, which runs under ``nice -n 10`` (Makefile), since a second xdist worker at their priority starves what they time
(measured on this 2-core machine under -n 2: the first two files failed in two runs of two, the last two once in a
fresh clone's run, the serial runs against an emulator once each under load). The other tests of those files run
virtual and stay with the rest."""


FIRST = ("test_plant_fit.py", "test_output_failures.py", "test_plant_fit_serial.py", "test_serial_stop.py",
         "test_design_search.py", "test_benchtests.py", "test_serial_run.py", "test_fault_url.py", "test_sweep.py",
         "test_wheel.py", "test_benchtests_tracking.py", "test_vesc_properties.py", "test_controller_exit.py",
         "test_tune.py", "test_run_heat.py", "test_run.py", "test_fault_campaign.py")
"""The longest test files (summed durations of `make test`, slowest first), run before the rest: `make test` deals
whole files to its two workers in this order (``--dist loadfile``), so neither is left alone with a long one at the
end. test_plant_fit.py comes first because it makes the plant fit that other files share (tests/conftest.py): they
come later in the order, when it is made, instead of waiting on its lock beside it. The order is only a schedule:
a wrong one costs time, never a result."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.name in REALTIME:
            prefixes = REALTIME[item.path.name]
            if prefixes is None or item.name.startswith(prefixes):
                item.add_marker(pytest.mark.realtime)
    rank = {name: k for k, name in enumerate(FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(FIRST)))  # stable: the rest keep their order

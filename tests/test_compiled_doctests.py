"""Doctests of the modules compiled by setup.py, run on their ``.py`` source (see conftest.py).

Each source is loaded as a fresh, interpreted module beside the compiled one; with a pure-Python
install there is nothing to do here (``--doctest-modules`` collects those modules itself).
"""

from __future__ import annotations

import doctest
import importlib.util
import sys
from pathlib import Path

import pytest

from host_tools.build_info import ROOT, compiled_sources

SOURCES = compiled_sources()


@pytest.mark.skipif(not SOURCES, reason="pure-Python install: doctests collected by --doctest-modules")
@pytest.mark.parametrize("source", SOURCES, ids=lambda p: str(p.relative_to(ROOT)))
def test_doctests_of_compiled_module(source: Path) -> None:
    dotted = ".".join(source.relative_to(ROOT).with_suffix("").parts)
    spec = importlib.util.spec_from_file_location(f"_source_of_{dotted.replace('.', '_')}", source)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is built
    try:
        spec.loader.exec_module(module)
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS, report=True)
    finally:
        del sys.modules[spec.name]
    assert result.failed == 0, f"{result.failed} of {result.attempted} doctest examples failed in {dotted}"

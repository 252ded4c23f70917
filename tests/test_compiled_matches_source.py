"""The compiled build (setup.py) and the pure-Python source give byte-identical telemetry for one seed.

The source tree is copied without its extension files and run in a subprocess; skipped when this
install is pure Python already (nothing to compare).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from host_tools.build_info import compiled_sources, run_pure_python
from host_tools.runner import RunConfig, run_virtual

SCRIPT = """
import hashlib, sys
from host_tools.runner import RunConfig, run_virtual
r = run_virtual(RunConfig(strides=1, seed=5, trace_capacity=0))
print(hashlib.sha256(r.telemetry).hexdigest(), r.scheduler.stats["control"].jobs)
"""


@pytest.mark.skipif(not compiled_sources(), reason="pure-Python install: nothing compiled to compare")
def test_compiled_run_matches_the_pure_python_source(tmp_path: Path) -> None:
    pure = run_pure_python(SCRIPT, tmp_path, timeout_s=300)
    r = run_virtual(RunConfig(strides=1, seed=5, trace_capacity=0))
    compiled = f"{hashlib.sha256(r.telemetry).hexdigest()} {r.scheduler.stats['control'].jobs}"
    assert pure.strip() == compiled

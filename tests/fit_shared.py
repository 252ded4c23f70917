"""The identification experiments and fits the plant-fit test files share (tests/conftest.py's `handmade_fit` and
`holds_only_run`; the second, a holds-only recording of the nominal plant, is tests/test_plant_fit.py's).

The hand-made plant file (tests/data/plant_handmade.toml: a plant that is not the nominal one) runs the tests' 10 s
experiment (`SHORT`: the default 29 s one's figures are tests/benchmarks/test_bench_fit_coverage.py's), a different
run on the same plant (10 strides of gait tracking, another seed) and `pafp fit --validate` of the first against the
second. Made once a session: under pytest-xdist the first worker to ask makes it in the session's shared temporary
directory while the others wait on its lock and then read it (`made_once`; the holds-only one likewise). (The same
recording fitted under another BLAS set-up with its data nudged by 1e-12 is
tests/benchmarks/test_bench_fit_coverage.py's `test_fit_under_another_kernel`.)
"""

from __future__ import annotations

import json
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

from host_tools.cli import main

ROOT = Path(__file__).resolve().parents[1]
HANDMADE = ROOT / "tests" / "data" / "plant_handmade.toml"
SHORT = ('\n[controller]\nname = "sysid"\nhold_s = 0.5\nsweep_deg = 12.0\nsweep_deg_s = 16.0\nchirp_s = 4.0\n'
         'prbs_s = 2.0\n')
QUIET = ["--quiet", "--no-plot", "--no-trace"]

@contextmanager
def _locked(path: Path):
    """An exclusive lock on `path` across processes (POSIX; elsewhere none: each worker then makes its own copy)."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    with open(path, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _make(d: Path) -> None:
    """The recordings and fits into d (see the module's docstring); `done` written last."""
    (d / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + SHORT)
    plant = ["--plant", str(HANDMADE)]
    assert main(["run", "--experiment", "sysid", "--profile", str(d / "fw.toml"), *plant, *QUIET,
                 "--out", str(d / "sysid")]) == 0
    # a different run: 10 strides of gait tracking on the same plant (another seed: other noise, other offsets)
    gait = ["run", "--strides", "10", "--seed", "5", "--record", *plant, *QUIET, "--out", str(d / "gait")]
    assert main(gait) == 0
    assert main(["fit", str(d / "sysid"), "--validate", str(d / "gait"), "--no-plot", "--out", str(d / "fit")]) == 0
    (d / "done").write_text("")


def made_once(shared: Path, name: str, make: Callable[[Path], None]) -> Path:
    """shared/name, made by `make` (which writes `done` last) once, whichever process asks first."""
    d = shared / name
    with _locked(shared / f"{name}.lock"):
        if not (d / "done").exists():
            d.mkdir(exist_ok=True)
            make(d)
    return d


def handmade_fit(shared: Path) -> dict:
    """{"dir", "run" (the sysid recording), "fit" (its `pafp fit` directory), "gait", "json" (fit.json)}: made under
    `shared` once, whichever process asks first."""
    d = made_once(shared, "handmade_fit", _make)
    return {"dir": d, "run": d / "sysid", "fit": d / "fit", "gait": d / "gait",
            "json": json.loads((d / "fit" / "fit.json").read_text())}


# holds only (no sweep to speak of, no chirp, no PRBS): 0.75 s at the centre, a 1 deg sweep, 0.75 s again
HOLDS_ONLY = ('\n[controller]\nname = "sysid"\nhold_s = 0.75\nsweep_deg = 1.0\nsweep_deg_s = 60.0\nchirp_s = 0.0\n'
              'prbs_s = 0.0\n')


def _make_holds_only(d: Path) -> None:
    """A holds-only recording of the nominal plant and its `pafp fit` (its directory's default `fit`)."""
    (d / "fw.toml").write_text((ROOT / "profiles" / "firmware.toml").read_text() + HOLDS_ONLY)
    assert main(["run", "--experiment", "sysid", "--profile", str(d / "fw.toml"), *QUIET, "--out", str(d / "run")]) == 0
    assert main(["fit", str(d / "run"), "--no-plot"]) == 0
    (d / "done").write_text("")


def holds_only_fit(shared: Path) -> Path:
    """The holds-only recording's run directory (its fit in `fit`): made under `shared` once."""
    return made_once(shared, "holds_only", _make_holds_only) / "run"

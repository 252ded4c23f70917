"""The wheel works anywhere: build it, install it into a fresh virtual environment, run it outside the checkout.

The wheel is the pure-Python one (``PAFP_PURE_PYTHON=1``, about 25 s with the install; the compiled build
takes minutes): what this test is after is the package's contents (profiles, gait data, licences) and that
nothing reaches back into the source tree. Dependencies come from pip's configured index, as for a user.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from host_tools.build_info import ROOT

SOURCE_FILES = ("setup.py", "pyproject.toml", "README.md", "LICENSE")
PACKAGES = ("firmware", "protocol", "hal", "rtos", "host_tools", "profiles")


def _clean_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["PAFP_PURE_PYTHON"] = "1"
    return env


def _run(argv: list[str], cwd: Path, timeout_s: float = 300) -> subprocess.CompletedProcess:
    r = subprocess.run(argv, cwd=cwd, env=_clean_env(), capture_output=True, text=True, timeout=timeout_s)
    assert r.returncode == 0, f"{argv} exited {r.returncode}\nstdout: {r.stdout[-2000:]}\nstderr: {r.stderr[-2000:]}"
    return r


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh virtual environment outside the checkout with the wheel of a copy of the source installed."""
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"  # a copy without extensions or build leftovers: the wheel holds what git would ship
    src.mkdir()
    for name in SOURCE_FILES:
        shutil.copy2(ROOT / name, src / name)
    for name in PACKAGES:
        shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns("*.so", "__pycache__", "*.egg-info"))
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(base / "dist"), str(src)], base)
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], base)  # on the base interpreter, not this one's venv
    (wheel,) = (base / "dist").glob("pafp-*.whl")
    _run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", str(wheel)], base)
    shutil.rmtree(src)  # nothing may reach back into a source tree
    return venv


def test_the_installed_package_runs_outside_the_checkout(installed: Path, tmp_path: Path) -> None:
    pafp = str(installed / "bin" / "pafp")
    r = _run([pafp, "run", "--strides", "1", "--quiet", "--out", str(tmp_path / "run")], Path("/"))
    assert "warning" not in (r.stdout + r.stderr).lower(), r.stdout + r.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["strides"] == 1 and summary["build"].startswith("pure Python")
    assert summary["deadline_misses"] == 0
    r = _run([pafp, "bench", "uncontrolled", "--out", str(tmp_path / "bench")], Path("/"))
    assert "warning" not in r.stderr.lower() and "| uncontrolled [level-com] |" in r.stdout
    assert (tmp_path / "bench" / "uncontrolled.json").is_file()
    r = _run([pafp, "--version"], Path("/"))
    assert r.stdout.startswith("pafp 0.")


def test_the_wheel_holds_profiles_data_and_licences(installed: Path) -> None:
    py = str(installed / "bin" / "python")
    script = ("import importlib.metadata as m, profiles, firmware.data, pathlib, sys;"
              "print(profiles.profile_path('firmware.toml'));"
              "print(pathlib.Path(firmware.data.__file__).with_name('LICENSE').read_text().splitlines()[0]);"
              "print(sorted(str(f) for f in m.files('pafp') if 'licenses' in str(f)));"
              "import json; print(json.dumps(m.requires('pafp')))")
    out = _run([py, "-c", script], Path("/")).stdout.splitlines()
    assert out[0].startswith(str(installed)) and out[0].endswith("profiles/firmware.toml")
    assert "gait data" in out[1]
    assert "LICENSE" in out[2] and "firmware/data/LICENSE" in out[2]
    requires = json.loads(out[3])
    crcmod = [r for r in requires if r.startswith("crcmod")]
    assert any(r.startswith("numpy") for r in requires)
    assert crcmod and all('extra == "dev"' in r for r in crcmod)  # a test oracle, not a run-time dependency
    # a sim:// port from plain pyserial, once hal.serial is listed as a handler package
    script = ("import serial; serial.protocol_handler_packages.append('hal.serial');"
              "p = serial.serial_for_url('sim://ak60-6'); print(p.is_open); p.close()")
    assert _run([py, "-c", script], Path("/")).stdout.strip() == "True"

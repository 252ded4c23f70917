"""The wheel works anywhere: build it, install it into a fresh virtual environment, run it outside the checkout.

The wheel is the pure-Python one (``PAFP_PURE_PYTHON=1``; the compiled build takes minutes): what this test is
after is the package's contents (profiles, gait data, licences) and that nothing reaches back into the source
tree. Only the wheel is installed (``--no-deps``): the new environment sees this interpreter's installed
dependencies through a plain path line in a ``.pth`` file, after its own site-packages. A path line adds the
directory without running its ``.pth`` files, so the editable install of the checkout there stays inert and a
module missing from the wheel fails to import. The declared dependencies are checked against pyproject.toml
instead of being fetched from the index (that took a minute of the test's time). The wheel is built without pip's
build isolation, with this environment's setuptools (the dev extra's, checked against pyproject's build-system
requirement): an isolated build fetched setuptools and mypy from the index, 20-60 s of waiting on the network for
a build that needs neither mypy nor the network (`make install` builds in isolation, from the declared requirements).
"""

from __future__ import annotations

import json
import os
import shutil
import site as site_module
import subprocess
import sys
import tomllib
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest
from packaging.requirements import Requirement

from host_tools.build_info import ROOT

SOURCE_FILES = ("setup.py", "pyproject.toml", "README.md", "LICENSE")
PACKAGES = ("firmware", "protocol", "hal", "rtos", "host_tools", "profiles")
LEFTOVERS = ("*.so", "__pycache__", "*.egg-info")  # build products, not sources


def _clean_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env["PAFP_PURE_PYTHON"] = "1"
    return env


def _run(argv: list[str], cwd: Path, timeout_s: float = 300) -> subprocess.CompletedProcess:
    r = subprocess.run(argv, cwd=cwd, env=_clean_env(), capture_output=True, text=True, timeout=timeout_s)
    assert r.returncode == 0, f"{argv} exited {r.returncode}\nstdout: {r.stdout[-2000:]}\nstderr: {r.stderr[-2000:]}"
    return r


@dataclass(frozen=True)
class Installed:
    venv: Path
    wheel: Path
    sources: tuple[str, ...]  # the package files of the copy the wheel was built from, relative to it


@pytest.fixture(scope="session")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Installed:
    """A fresh virtual environment outside the checkout with the wheel of a copy of the source installed (once a
    session: `make test` deals this file whole to one worker)."""
    return _build_and_install(tmp_path_factory.mktemp("wheel"))


def _build_and_install(base: Path) -> Installed:
    """Build the wheel of a copy of the source in base and install it into a new virtual environment there."""
    import setuptools

    (wants,) = [r for r in map(Requirement, tomllib.loads((ROOT / "pyproject.toml").read_text())["build-system"]
                               ["requires"]) if r.name == "setuptools"]
    assert wants.specifier.contains(setuptools.__version__), f"setuptools {setuptools.__version__}: {wants} builds"
    src = base / "src"  # a copy without extensions or build leftovers: the wheel holds what git would ship
    src.mkdir()
    for name in SOURCE_FILES:
        shutil.copy2(ROOT / name, src / name)
    for name in PACKAGES:
        shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns(*LEFTOVERS))
    sources = tuple(sorted(str(f.relative_to(src)) for p in PACKAGES for f in (src / p).rglob("*") if f.is_file()))
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(base / "dist"),
          str(src)], base)
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], base)  # on the base interpreter
    site_of = "import sysconfig; print(sysconfig.get_path('purelib'))"
    site = Path(_run([str(venv / "bin" / "python"), "-c", site_of], base).stdout.strip())
    (site / "test-dependencies.pth").write_text("".join(f"{p}\n" for p in site_module.getsitepackages()))
    (wheel,) = (base / "dist").glob("pafp-*.whl")
    _run([sys.executable, "-m", "pip", "--python", str(venv / "bin" / "python"), "install", "-q", "--no-deps",
          str(wheel)], base)
    shutil.rmtree(src)  # nothing may reach back into a source tree
    return Installed(venv, wheel, sources)


def test_the_installed_package_runs_outside_the_checkout(installed: Installed, tmp_path: Path) -> None:
    pafp = str(installed.venv / "bin" / "pafp")
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


def test_pafp_is_imported_from_the_wheel_alone(installed: Installed) -> None:
    script = (f"import json, sys, {', '.join(PACKAGES)};"
              f"print(json.dumps([[m.__file__ for m in ({', '.join(PACKAGES)},)], sys.path]))")
    files, path = json.loads(_run([str(installed.venv / "bin" / "python"), "-c", script], Path("/")).stdout)
    assert all(f.startswith(str(installed.venv)) for f in files), files
    elsewhere = [p for p in path if p and not Path(p).is_relative_to(installed.venv)]
    assert not [(p, n) for p in elsewhere for n in PACKAGES if (Path(p) / n).exists()], path  # e.g. the checkout


def test_the_wheel_ships_every_package_file(installed: Installed) -> None:
    """Every file of the packages (code, profiles, gait data and its licence) is in the wheel."""
    assert any(f.endswith(".toml") for f in installed.sources) and "firmware/data/LICENSE" in installed.sources
    missing = set(installed.sources) - set(zipfile.ZipFile(installed.wheel).namelist())
    assert not missing, f"not in {installed.wheel.name}: {sorted(missing)}"


def test_the_wheel_declares_pyprojects_dependencies_and_they_are_met(installed: Installed) -> None:
    """What --no-deps skipped: the wheel's Requires-Dist is pyproject's, and the environment meets each one."""
    py = str(installed.venv / "bin" / "python")
    script = ("import importlib.metadata as m, json; d = m.distribution('pafp');"
              "print(json.dumps([str(d.locate_file('')), d.requires]))")
    location, requires = json.loads(_run([py, "-c", script], Path("/")).stdout)
    assert location.startswith(str(installed.venv))  # the wheel's metadata, not the checkout's editable install
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    expected = {str(Requirement(d)) for d in project["dependencies"]} | {
        str(Requirement(f'{d}; extra == "{extra}"')) for extra, ds in project["optional-dependencies"].items()
        for d in ds}
    declared = [Requirement(r) for r in requires]
    assert {str(r) for r in declared} == expected
    runtime = [r for r in declared if r.marker is None]
    assert "numpy" in {r.name for r in runtime} and "crcmod" not in {r.name for r in runtime}  # crcmod: test oracle
    script = "import importlib.metadata as m, json, sys; print(json.dumps({n: m.version(n) for n in sys.argv[1:]}))"
    versions = json.loads(_run([py, "-c", script, *(r.name for r in runtime)], Path("/")).stdout)
    assert not [r for r in runtime if not r.specifier.contains(versions[r.name], prereleases=True)], versions


def test_the_wheel_holds_profiles_data_and_licences(installed: Installed) -> None:
    py = str(installed.venv / "bin" / "python")
    script = ("import importlib.metadata as m, profiles, firmware.data, pathlib, sys;"
              "print(profiles.profile_path('firmware.toml'));"
              "print(pathlib.Path(firmware.data.__file__).with_name('LICENSE').read_text().splitlines()[0]);"
              "print(sorted(str(f) for f in m.files('pafp') if 'licenses' in str(f)))")
    out = _run([py, "-c", script], Path("/")).stdout.splitlines()
    assert out[0].startswith(str(installed.venv)) and out[0].endswith("profiles/firmware.toml")
    assert "gait data" in out[1]
    assert "LICENSE" in out[2] and "firmware/data/LICENSE" in out[2]
    # a sim:// port from plain pyserial, once hal.serial is listed as a handler package
    script = ("import serial; serial.protocol_handler_packages.append('hal.serial');"
              "p = serial.serial_for_url('sim://ak60-6'); print(p.is_open); p.close()")
    assert _run([py, "-c", script], Path("/")).stdout.strip() == "True"

"""setup.py's parallel build: every C file of every extension compiled on its own thread, with progress lines."""

from __future__ import annotations

import importlib.util
import shutil
import sys
import sysconfig
import threading
from pathlib import Path

import pytest
from setuptools import Distribution, Extension

from host_tools.build_info import ROOT


def _setup_module():
    spec = importlib.util.spec_from_file_location("pafp_setup", ROOT / "setup.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # not __main__: defines the build, runs no setup()
    return module


def _sources(tmp_path: Path, n: int) -> list[str]:
    files = []
    for k in range(n):
        c = tmp_path / f"part{k}.c"
        c.write_text(f"int pafp_part{k}(void) {{ return {k}; }}\n" if k else
                     "#include <Python.h>\nstatic struct PyModuleDef m = {PyModuleDef_HEAD_INIT, \"demo\"};\n"
                     "PyMODINIT_FUNC PyInit_demo(void) { return PyModule_Create(&m); }\n")
        files.append(str(c.relative_to(tmp_path)))
    return files


def _command(module, tmp_path: Path, monkeypatch, n: int):
    monkeypatch.chdir(tmp_path)
    dist = Distribution({"name": "demo", "ext_modules": [Extension("demo", _sources(tmp_path, n))]})
    cmd = module.ParallelBuildExt(dist)
    cmd.build_temp, cmd.build_lib = str(tmp_path / "tmp"), str(tmp_path / "lib")
    cmd.ensure_finalized()
    return cmd


def test_jobs_come_from_the_environment_or_the_cores(monkeypatch):
    module = _setup_module()
    monkeypatch.setenv("PAFP_BUILD_JOBS", "3")
    assert module._jobs() == 3
    monkeypatch.delenv("PAFP_BUILD_JOBS")
    assert module._jobs() >= 1
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv("PAFP_BUILD_JOBS", bad)
        with pytest.raises(SystemExit, match=f"PAFP_BUILD_JOBS={bad!r} .*whole number >= 1"):
            module._jobs()


def test_the_files_of_one_extension_compile_at_the_same_time(tmp_path, monkeypatch, capsys):
    """Two compiles meet at a barrier: a serial build would wait there alone and fail."""
    module = _setup_module()
    monkeypatch.setenv("PAFP_BUILD_JOBS", "2")
    cmd = _command(module, tmp_path, monkeypatch, 4)
    cmd.compiler = None
    meet = threading.Barrier(2, timeout=30)
    compiled = []

    def fake_compile(self, obj, src, ext, cc_args, extra_postargs, pp_opts):
        meet.wait()  # both workers must be inside a compile at once
        compiled.append(src)
        Path(obj).parent.mkdir(parents=True, exist_ok=True)
        Path(obj).write_bytes(b"")

    from distutils.ccompiler import new_compiler  # setuptools' own distutils, the one build_ext uses

    compiler_class = type(new_compiler())
    monkeypatch.setattr(compiler_class, "_compile", fake_compile)
    monkeypatch.setattr(compiler_class, "link_shared_object", lambda self, *a, **k: None)
    cmd.run()
    assert sorted(compiled) == [f"part{k}.c" for k in range(4)]
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "pafp build: compiling 4 C files of 1 extensions, 2 at a time"
    assert sorted(line.split()[2] for line in lines[1:-1]) == ["[1/4]", "[2/4]", "[3/4]", "[4/4]"]
    assert lines[-1] == "pafp build: done"


@pytest.mark.skipif(shutil.which((sysconfig.get_config_var("CC") or "cc").split()[0]) is None,
                    reason="no C compiler")
def test_a_real_extension_builds_and_imports(tmp_path, monkeypatch):
    module = _setup_module()
    monkeypatch.setenv("PAFP_BUILD_JOBS", "2")
    cmd = _command(module, tmp_path, monkeypatch, 3)
    cmd.run()
    built = list((tmp_path / "lib").glob("demo*"))
    assert len(built) == 1
    monkeypatch.syspath_prepend(str(tmp_path / "lib"))
    sys.modules.pop("demo", None)
    import demo  # noqa: F401  (the linked extension loads: every part was compiled and linked)

    assert demo.__name__ == "demo"

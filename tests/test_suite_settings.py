"""The suite's own settings: a hang fails the run (per-test timeout), and a second Hypothesis profile explores."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

from hypothesis import settings

ROOT = Path(__file__).resolve().parents[1]


def test_the_default_profile_is_deterministic_and_the_fuzz_profile_explores():
    default, fuzz = settings.get_profile("pafp"), settings.get_profile("fuzz")
    assert default.derandomize is True
    assert fuzz.derandomize is False and fuzz.max_examples >= 10 * default.max_examples
    assert fuzz.deadline is None and fuzz.database is None


def test_make_fuzz_runs_the_property_tests_under_the_fuzz_profile():
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    rule = text[text.index("\nfuzz:"):].split("\n\n")[0]
    assert "--hypothesis-profile=fuzz" in rule and "grep -l hypothesis tests/test_" in rule


def test_every_test_has_a_generous_timeout_from_pytest_timeout():
    doc = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    ini = doc["tool"]["pytest"]["ini_options"]
    assert ini["timeout"] >= 600 and ini["timeout_method"] == "thread"
    assert any(d.startswith("pytest-timeout") for d in doc["project"]["optional-dependencies"]["dev"])


def test_a_hanging_test_fails_the_run_instead_of_stalling_it(tmp_path: Path):
    hang = "import time\n\n\ndef test_hangs():\n    while True:\n        time.sleep(0.05)\n"
    (tmp_path / "test_hang.py").write_text(hang, encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--timeout", "2",
                        "--timeout-method", "thread", str(tmp_path / "test_hang.py")],
                       cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert r.returncode != 0
    assert "Timeout" in r.stdout + r.stderr

"""docs/compiled.md states the rules of the mypyc build once: every pointer to it names one of its headings,
and the modules no longer explain a rule themselves."""

from __future__ import annotations

import re

from host_tools.build_info import ROOT

DOC = ROOT / "docs" / "compiled.md"
PACKAGES = ("firmware", "protocol", "hal", "rtos", "host_tools", "profiles")


def _sources() -> list:
    files = [ROOT / "setup.py", ROOT / "README.md"]
    for package in PACKAGES:
        files += sorted((ROOT / package).rglob("*.py"))
    return files


def test_every_pointer_names_a_heading_of_the_doc():
    headings = set(re.findall(r"^## (.+)$", DOC.read_text(), re.MULTILINE))
    pointers = {}
    for path in _sources():
        text = " ".join(path.read_text().split())  # a pointer may be wrapped over two lines
        for heading in re.findall(r'docs/compiled\.md, "([^"]+)"', text):
            pointers.setdefault(heading, []).append(path.relative_to(ROOT).as_posix())
    assert pointers, "no module points to docs/compiled.md"
    assert {h: p for h, p in pointers.items() if h not in headings} == {}
    assert len(pointers["Values checked as given"]) >= 8


def test_the_rules_are_not_explained_again_in_the_modules():
    """The bool-at-the-boundary rule was explained in setup.py and in six modules; it is written once now."""
    repeated = [path.relative_to(ROOT).as_posix() for path in _sources()
                if re.search(r"turn(s|ed)? (it|a bool) (passed as ``int`` )?into (a number|0 or 1|an int)",
                             " ".join(path.read_text().split()))]
    assert repeated == []
    assert "arrives as 0 or 1" in DOC.read_text()

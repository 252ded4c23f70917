"""No import circles in the rooms issue 37 touched: host_tools/serial_mode and hal/virtual/devices (with
hal/virtual/ground_sensors.py, which the device registry serves). Every import counts: at module level, inside a
function, or for type checking only; a registry's "module:attr" string is not an import."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ROOMS = ("host_tools/serial_mode", "hal/virtual/devices")
EXTRA = ("hal/virtual/ground_sensors.py",)


def _modules() -> dict[str, Path]:
    files = [p for room in ROOMS for p in (ROOT / room).glob("*.py")] + [ROOT / f for f in EXTRA]
    return {".".join(p.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"): p for p in files}


def _imports(path: Path, names: set[str]) -> set[str]:
    """The modules of ``names`` that the file imports, anywhere in it."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name in names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module in names:
                out.add(node.module)
            out.update(f"{node.module}.{a.name}" for a in node.names if f"{node.module}.{a.name}" in names)
    return out


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module, or a module importing itself (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph[v]:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_checker_finds_a_circle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == [["a", "b", "c"]]


@pytest.mark.parametrize("room", ROOMS)
def test_no_import_circles(room: str) -> None:
    mods = _modules()
    names = set(mods)
    graph = {m: _imports(p, names) - {m} for m, p in mods.items()}
    circles = [c for c in _cycles(graph) if any(m.startswith(room.replace("/", ".")) for m in c)]
    assert circles == []

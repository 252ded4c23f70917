"""docs/design.md's tables of the adult design, from the commands that measure them (issue 38).

Two blocks of docs/design.md are generated, each between ``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->``:

* ``design_search``: the shipped search's table of every point (`pafp design profiles/designs/adult.toml` writes it
  as ``docs_table.md`` into its output directory; host_tools/studies/design_report.py ``docs_search_table``);
* ``design_energy``: the adult design's 20-stride energy ledgers at free and fast speed
  (host_tools/studies/design_energy.py).

``python -m host_tools.studies.design_docs search OUT`` copies a search's table in, ``python -m
host_tools.studies.design_docs energy`` walks and writes the ledgers; `make bench` checks both are current
(tests/benchmarks/test_bench_design.py, test_bench_design_energy.py).
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["DOCS", "block", "write_block"]

DOCS = Path(__file__).resolve().parents[2] / "docs" / "design.md"


def _marks(name: str) -> tuple[str, str]:
    return f"<!-- bench:{name} -->\n", f"<!-- /bench:{name} -->"


def block(name: str, text: str | None = None) -> str | None:
    """The text between docs/design.md's (or ``text``'s) marks of ``name`` (None without them)."""
    text = DOCS.read_text(encoding="utf-8") if text is None else text
    start, end = _marks(name)
    if start not in text or end not in text.split(start, 1)[1]:
        return None
    return text.split(start, 1)[1].split(end, 1)[0]


def write_block(name: str, table: str) -> None:
    """Put ``table`` between docs/design.md's marks of ``name`` (written atomically); ValueError without them."""
    from host_tools.outdir import write_atomic

    text = DOCS.read_text(encoding="utf-8")
    old = block(name, text)
    if old is None:
        raise ValueError(f"{DOCS}: no <!-- bench:{name} --> ... <!-- /bench:{name} --> block")
    start = _marks(name)[0]
    write_atomic(DOCS, text.replace(start + old, start + table, 1))


def main(argv: list[str] | None = None) -> int:
    """`search OUT` (a finished search's output directory) or `energy` (walks the adult design, a few minutes)."""
    args = sys.argv[1:] if argv is None else argv
    try:
        if len(args) == 2 and args[0] == "search":
            write_block("design_search", (Path(args[1]) / "docs_table.md").read_text(encoding="utf-8"))
        elif args == ["energy"]:
            from host_tools.studies.design_energy import ADULT_PROFILE, SPEEDS, TABLE_STRIDES, walk_energy, walk_tables
            from profiles import profile_path

            walks = {s: walk_energy(profile_path(ADULT_PROFILE), s, TABLE_STRIDES) for s in SPEEDS}
            write_block("design_energy", walk_tables(walks))
        else:
            print("usage: python -m host_tools.studies.design_docs search OUT | energy", file=sys.stderr)
            return 2
    except (OSError, ValueError) as e:
        print(f"design_docs: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

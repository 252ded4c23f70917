"""Shared output of the bench tests: result record, comparison table, PNG/CSV/JSON/Markdown writers."""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["BASES", "BenchResult", "Figure", "markdown_table", "write_outputs"]


#: The kinds of basis a compared figure can have (the first word of Figure.basis).
BASES = ("fitted", "predicted", "assumed")


@dataclass(frozen=True)
class Figure:
    """One compared figure: the report's value (text and number), the emulated value, a note, and its basis.

    ``basis`` says how far the emulated figure can be trusted as a prediction: "fitted: <parameter>" (a
    parameter was chosen so that this row matches the report), "predicted" (nothing was fitted to it),
    or "assumed: <what>" (the report gives no setup for it; the assumption is named).
    """

    name: str
    unit: str
    report_text: str
    report_value: float | None
    emulated_value: float | None
    note: str = ""
    basis: str = ""

    def __post_init__(self) -> None:
        """Refuse a row without a basis."""
        kind = self.basis.split(":", 1)[0].strip()
        if kind not in BASES or (kind != "predicted" and ":" not in self.basis):
            raise ValueError(f"figure {self.name!r}: basis {self.basis!r} must be 'predicted', 'fitted: <parameter>' "
                             "or 'assumed: <what>'")

    @property
    def difference(self) -> float | None:
        """Emulated minus report value, when both are numbers."""
        if self.report_value is None or self.emulated_value is None:
            return None
        return self.emulated_value - self.report_value

    def as_dict(self) -> dict[str, object]:
        """The row as a JSON-ready mapping."""
        return {"name": self.name, "unit": self.unit, "report": self.report_text,
                "report_value": self.report_value, "emulated": self.emulated_value,
                "difference": self.difference, "note": self.note, "basis": self.basis}


#: Draws the test's plot onto a fresh matplotlib figure.
Plotter = Callable[[object], None]


@dataclass
class BenchResult:
    """What one bench test produced: compared figures, data columns for the CSV, and a plotter."""

    test: str
    figures: list[Figure]
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    plotter: Plotter | None = None
    parameters: dict[str, object] = field(default_factory=dict)
    #: The readings of the report it ran under (hal.virtual.plant.readings): kind -> name ("n/a": not used).
    readings: dict[str, str] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """The test's name with the geometry it ran under, when it names one."""
        g = self.readings.get("geometry")
        return f"{self.test} [{g}]" if g and g != "n/a" else self.test


def _fmt(value: float | None) -> str:
    """A number for the table (4 significant digits), or a dash."""
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value:.4g}"


def markdown_table(results: list[BenchResult]) -> str:
    """A Markdown table with one row per figure of every result: report, emulated, difference, note."""
    lines = ["| test | figure | unit | report | emulated | difference | basis | readings | note |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        readings = ", ".join(f"{k} {v}" for k, v in r.readings.items())
        for f in r.figures:
            lines.append(f"| {r.label} | {f.name} | {f.unit} | {f.report_text} | {_fmt(f.emulated_value)} | "
                         f"{_fmt(f.difference)} | {f.basis} | {readings} | {f.note} |")
    return "\n".join(lines) + "\n"


def write_outputs(result: BenchResult, out_dir: Path) -> list[Path]:
    """Write <test>.png, <test>.csv, <test>.json and <test>.md into out_dir, each atomically (host_tools/outdir.py);
    return their paths. An OSError names the file that failed; the files written before it stay complete."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from host_tools.outdir import naming, save_figure, write_atomic

    with naming(out_dir):
        out_dir.mkdir(parents=True, exist_ok=True)
    stem = result.test.replace("-", "_")
    paths = [out_dir / f"{stem}.{ext}" for ext in ("png", "csv", "json", "md")]
    fig = plt.figure(figsize=(9, 7), layout="constrained")
    try:
        if result.plotter is not None:
            result.plotter(fig)
        save_figure(fig, paths[0], dpi=110)
    finally:
        plt.close(fig)
    names = list(result.columns)
    n = max((len(v) for v in result.columns.values()), default=0)
    table = io.StringIO(newline="")
    w = csv.writer(table)
    w.writerow(names)
    for k in range(n):
        w.writerow([_cell(result.columns[c], k) for c in names])
    write_atomic(paths[1], table.getvalue())
    doc = {"test": result.test, "readings": result.readings, "parameters": result.parameters,
           "figures": [f.as_dict() for f in result.figures]}
    write_atomic(paths[2], json.dumps(doc, indent=2, default=float) + "\n")
    write_atomic(paths[3], f"# Bench test `{result.test}`\n\n" + markdown_table([result]))
    return paths


def _cell(column: np.ndarray, k: int) -> str:
    """One CSV cell: repr-exact float, int, or empty past the column's end."""
    if k >= len(column):
        return ""
    v = column[k]
    if isinstance(v, (np.integer, int)):
        return str(int(v))
    if isinstance(v, (np.floating, float)):
        return repr(float(v))
    return str(v)

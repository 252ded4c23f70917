"""report.md and plots of a finished sweep: each axis against each figure; Monte Carlo distributions, worst cases."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from host_tools.contract import shell_command
from host_tools.outdir import naming, save_figure, write_atomic
from host_tools.studies.sweep_spec import SweepSpec

__all__ = ["PLOTTED", "rerun_command", "write_report"]

#: Figures plotted against each axis (and "fault", the fraction of points that latched a fault).
PLOTTED = ("rms_error_deg", "rms_measured_deg", "max_error_deg", "deadline_misses", "saturation_fraction",
           "realtime_factor", "fault")
WORST = 5


def _value(row: dict[str, Any], figure: str) -> float:
    if figure == "fault":
        return math.nan if row["status"] in ("error", "timeout") else float(bool(row["faults"]))
    v = row.get(figure)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def _slug(key: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", key).strip("_")


def rerun_command(spec: SweepSpec, point: int) -> str:
    """The command that re-runs one point with the full outputs of `pafp run`."""
    return shell_command("pafp", "sweep", spec.path, "--point", point, "--out", f"runs/{spec.path.stem}-point-{point}")


def _axis_plot(path: Path, rows: list[dict[str, Any]], key: str, values: tuple[Any, ...]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    pos = {v: (float(v) if numeric else i) for i, v in enumerate(values)}
    fig, axes = plt.subplots(len(PLOTTED), 1, sharex=True, figsize=(7, 2.0 * len(PLOTTED)), layout="constrained")
    for ax, figure in zip(axes, PLOTTED, strict=True):
        x = np.array([pos[r[key]] for r in rows], dtype=float)
        y = np.array([_value(r, figure) for r in rows])
        ax.plot(x, y, ".", alpha=0.4, color="tab:blue")
        med = [np.nanmedian(y[x == pos[v]]) if np.any(np.isfinite(y[x == pos[v]])) else np.nan for v in values]
        ax.plot([pos[v] for v in values], med, "-o", color="tab:red", ms=3, label="median")
        ax.set_ylabel("fault fraction" if figure == "fault" else figure, fontsize=8)
    if numeric and min(values) > 0 and max(values) / min(values) > 20:
        axes[-1].set_xscale("log")
    if not numeric:
        axes[-1].set_xticks(list(pos.values()), [str(v) for v in values])
    axes[0].legend(fontsize=7)
    axes[-1].set_xlabel(key)
    save_figure(fig, path, dpi=90)
    plt.close(fig)


def _mc_plot(path: Path, rows: list[dict[str, Any]], samples: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures = ("rms_error_deg", "rms_measured_deg", "max_error_deg", "saturation_fraction")
    fig, axes = plt.subplots(2, 2, figsize=(9, 6), layout="constrained")
    for ax, figure in zip(axes.flat, figures, strict=True):
        y = np.array([_value(r, figure) for r in rows])
        y = y[np.isfinite(y)]
        if len(y):
            ax.hist(y, bins=min(40, max(5, len(y) // 5)), color="tab:blue", alpha=0.8)
            ax.axvline(float(np.median(y)), color="k", lw=1, label=f"median {np.median(y):.4g}")
            ax.axvline(float(np.max(y)), color="tab:red", lw=1, label=f"worst {np.max(y):.4g}")
            ax.legend(fontsize=7)
        ax.set_xlabel(figure)
        ax.set_ylabel("points")
    fig.suptitle(f"Monte Carlo: {len(rows)} points ({samples} plant draws per grid point)")
    save_figure(fig, path, dpi=90)
    plt.close(fig)


def _fmt(v: float) -> str:
    return "n/a" if not math.isfinite(v) else f"{v:.4g}"


def write_report(spec: SweepSpec, rows: list[dict[str, Any]], out: Path, *, wall_time_s: float | None = None,
                 where: str = "", interrupted: str | None = None) -> Path:
    """Write out/report.md and out/plots/*.png from the rows (sorted by point); return the report's path.

    ``interrupted``: the signal that stopped the sweep early (the report says so and how to finish it).
    """
    plots = out / "plots"
    with naming(plots):
        plots.mkdir(parents=True, exist_ok=True)
    status = {s: sum(r["status"] == s for r in rows) for s in ("ok", "fault", "error", "timeout")}
    ran = [r for r in rows if r["status"] in ("ok", "fault")]
    lines = [f"# pafp sweep report: {spec.path.name}", "",
             f"Spec `{spec.path}`, profile `{spec.profile}`, scenario {spec.scenario}, controller {spec.controller}, "
             f"{spec.run['strides']} strides per point; {len(rows)} of {spec.n_points} points finished"
             + (f" in {wall_time_s:.1f} s" if wall_time_s is not None else "") + (f" ({where})" if where else "")
             + ".", "",
             *([f"**Interrupted** by {interrupted}: {len(rows)} of {spec.n_points} points finished; "
                f"`{shell_command('pafp', 'sweep', spec.path, '--out', out, '--resume')}` runs the rest.",
                ""] if interrupted else []),
             "| status | points |", "|---|---|", *(f"| {s} | {n} |" for s, n in status.items()), "",
             "Figures over the points that ran (ok or fault):", "",
             "| figure | median | worst (max) | min |", "|---|---|---|---|"]
    for figure in PLOTTED:
        y = np.array([_value(r, figure) for r in ran])
        y = y[np.isfinite(y)]
        if len(y):
            lines.append(f"| {'fault fraction' if figure == 'fault' else figure} | {_fmt(float(np.median(y)))} | "
                         f"{_fmt(float(np.max(y)))} | {_fmt(float(np.min(y)))} |")
    if ran:
        fault = sum(bool(r["faults"]) for r in ran) / len(ran)
        lines += ["", f"Fraction of points with a fault: {fault:.1%} ({sum(bool(r['faults']) for r in ran)} of "
                  f"{len(ran)}); with a deadline miss: {sum(r['deadline_misses'] > 0 for r in ran) / len(ran):.1%}."]
    for axis in spec.grid:
        name = f"axis_{_slug(axis.key)}.png"
        _axis_plot(plots / name, [r for r in rows if axis.key in r], axis.key, axis.values)
        lines += ["", f"## {axis.key}", "", f"Each figure against {axis.key} (dots: points; red: median per value).",
                  "", f"![{axis.key}](plots/{name})"]
    if spec.samples:
        _mc_plot(plots / "monte_carlo.png", ran, spec.samples)
        lines += ["", "## Monte Carlo", "",
                  f"{spec.samples} plant draws per grid point (plant seeds from SeedSequence([{spec.mc_seed}, k])).",
                  "", "![Monte Carlo distributions](plots/monte_carlo.png)"]
    worst = sorted(ran, key=lambda r: (-_value(r, "rms_error_deg") if math.isfinite(_value(r, "rms_error_deg"))
                                       else math.inf, r["point"]))[:WORST]
    if worst:
        lines += ["", "## Worst points (RMS tracking error)", "",
                  "| point | parameters | plant seed | RMS [deg] | max [deg] | faults | re-run |",
                  "|---|---|---|---|---|---|---|"]
        for r in worst:
            params = ", ".join(f"{a.key} = {r[a.key]}" for a in spec.grid) or "base"
            lines.append(f"| {r['point']} | {params} | {r['plant_seed'] if r['plant_seed'] is not None else '-'} | "
                         f"{_fmt(_value(r, 'rms_error_deg'))} | {_fmt(_value(r, 'max_error_deg'))} | "
                         f"{r['faults'] or 'none'} | `{rerun_command(spec, r['point'])}` |")
    failed = [r for r in rows if r["status"] in ("error", "timeout")]
    if failed:
        lines += ["", f"## Failed points ({len(failed)})", "", "| point | status | error |", "|---|---|---|"]
        lines += [f"| {r['point']} | {r['status']} | {str(r['error']).replace('|', '/')[:200]} |" for r in failed[:50]]
    lines += ["", "Files: `results.parquet` and `results.csv` (one row per point, sorted by point), `rows.jsonl` "
              "(the journal written as points finish), `sweep.json`, `plots/`.", ""]
    path = out / "report.md"
    write_atomic(path, "\n".join(lines))
    return path

"""design.md and pareto.png of a design search: the non-dominated designs, the lightest design that walks each
body mass and speed (with the `pafp run` command that runs it) or by how much the best falls short, the
report's AK60-6 transmission with its limit, and the table of every point (docs/design.md, "Reading the search").

A point **walks** the person when its run completed without a fault, the winding stays within its thermal
limit (the steady state of continuous walking when summary.json has it, else the hottest the run saw), it
delivered at least the spec's ``min_moment_share`` of the stance moment and tracked the gait within its
``max_tracking_rms_deg`` (the encoder's RMS error), its steady winding with the housing resistance at the
pessimistic end stays ``min_thermal_margin_c`` below the firmware's derating start, and its belt's peak tension is
within the belt's rated working tension (``belt_within_rating``). The Pareto front of each body mass and
speed is taken among the points that walk, on actuator mass (lower), moment share (higher) and energy per stride
at the battery (lower; left out where no point has it).
"""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

from host_tools.outdir import write_atomic
from host_tools.studies.design_spec import DesignPoint, DesignSpec, WalkCriteria
from host_tools.studies.sweep_table import status_counts

__all__ = ["REPORT_RATIO", "docs_search_table", "groups", "is_report_design", "lightest", "pareto", "walks",
           "write_design_report"]

REPORT_RATIO = 14.0 / 3.0  # the report's belt (docs/plant.md: 12/56 HTD 5M or 6/28 HTD 10 mm, 14:3)


def _num(v: object) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def walks(row: dict[str, Any], c: WalkCriteria) -> bool:
    """Whether the point walks the person (module docstring)."""
    share, rms = _num(row.get("moment_share")), _num(row.get("tracking_rms_deg"))
    margin = _num(row.get("thermal_margin_c"))
    tension, rated = _num(row.get("belt_tension_n")), _num(row.get("belt_rated_n"))
    belt_ok = not c.belt_within_rating or (not math.isnan(rated) and tension <= rated)
    return row.get("status") == "ok" and bool(row.get("within_thermal")) and not math.isnan(share) \
        and share >= c.min_moment_share and not math.isnan(rms) and rms <= c.max_tracking_rms_deg \
        and not math.isnan(margin) and margin >= c.min_thermal_margin_c and belt_ok


def groups(rows: list[dict[str, Any]]) -> list[tuple[float, str]]:
    """(body mass, speed) of the rows, in row order."""
    return list(dict.fromkeys((float(r["body_mass_kg"]), str(r["speed"])) for r in rows))


def _objectives(r: dict[str, Any], energy: bool) -> tuple[float, ...]:
    base = (_num(r["actuator_kg"]), -_num(r["moment_share"]))
    return (*base, _num(r["energy_per_stride_j"])) if energy else base


def pareto(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows no other row dominates (actuator mass, moment share, energy per stride where every row has it).

    >>> a = {"actuator_kg": 1.0, "moment_share": 0.9, "energy_per_stride_j": math.nan}
    >>> b = {"actuator_kg": 2.0, "moment_share": 0.95, "energy_per_stride_j": math.nan}
    >>> c = {"actuator_kg": 2.0, "moment_share": 0.9, "energy_per_stride_j": math.nan}
    >>> [r["actuator_kg"] for r in pareto([a, b, c])], pareto([a, b, c])[1] is b
    ([1.0, 2.0], True)
    """
    energy = bool(rows) and all(not math.isnan(_num(r.get("energy_per_stride_j"))) for r in rows)
    objs = [_objectives(r, energy) for r in rows]

    def dominated(i: int) -> bool:
        return any(all(a <= b for a, b in zip(objs[j], objs[i], strict=True)) and objs[j] != objs[i]
                   for j in range(len(rows)) if j != i)
    return [r for i, r in enumerate(rows) if not dominated(i)]


def lightest(rows: list[dict[str, Any]], c: WalkCriteria) -> dict[str, Any] | None:
    """The lightest row that walks (ties: the higher moment share, then the lower point)."""
    ok = [r for r in rows if walks(r, c)]
    return min(ok, key=lambda r: (_num(r["actuator_kg"]), -_num(r["moment_share"]), r["point"])) if ok else None


def is_report_design(r: dict[str, Any]) -> bool:
    """The report's actuator: the AK60-6, the 14:3 belt, no spring."""
    return r["motor"] == "ak60_6" and abs(_num(r["ratio"]) - REPORT_RATIO) < 1e-3 and r["spring"] == "none"


def _fmt(v: object, digits: str = ".2f") -> str:
    x = _num(v)
    return "n/a" if math.isnan(x) else format(x, digits)


def _shortfall(rows: list[dict[str, Any]], mass: float, c: WalkCriteria) -> str:
    """Why the best design of a group does not walk it, and by how much."""
    ran = [r for r in rows if r["status"] in ("ok", "fault")]
    if not ran:
        return "no point of it ran (errors: results.csv)"
    best = max(ran, key=lambda r: (_num(r["moment_share"]) if not math.isnan(_num(r["moment_share"])) else -1.0,
                                   -_num(r["actuator_kg"])))
    why = []
    if best["fault"]:
        why.append(f"latched {best['fault']} at {_fmt(best['fault_at_s'])} s after {best['strides_walked']} strides")
    share = _num(best["moment_share"])
    if math.isnan(share) or share < c.min_moment_share:
        why.append(f"delivered {_fmt(share, '.1%')} of the stance moment ({_fmt(c.min_moment_share - share, '.1%')} "
                   f"short of {c.min_moment_share:.0%})")
    rms = _num(best["tracking_rms_deg"])
    if not best["fault"] and (math.isnan(rms) or rms > c.max_tracking_rms_deg):
        why.append(f"tracked the gait at {_fmt(rms, '.1f')}° RMS (limit {c.max_tracking_rms_deg:g}°)")
    if not best["within_thermal"] and not best["fault"]:
        why.append(f"winding {_fmt(best['steady_state_c'], '.0f')} °C steady (limit "
                   f"{_fmt(best['thermal_limit_c'], '.0f')} °C)")
    margin = _num(best.get("thermal_margin_c"))
    if not best["fault"] and (math.isnan(margin) or margin < c.min_thermal_margin_c):
        why.append(f"winding {_fmt(best.get('steady_state_pessimistic_c'), '.0f')} °C steady with the housing "
                   f"resistance at its pessimistic end, {_fmt(margin, '.0f')} °C below the derating start (needs "
                   f"{c.min_thermal_margin_c:g})")
    tension, rated = _num(best.get("belt_tension_n")), _num(best.get("belt_rated_n"))
    if c.belt_within_rating and not (tension <= rated):
        why.append(f"belt tension {_fmt(tension, '.0f')} N at its peak current against {_fmt(rated, '.0f')} N rated")
    keeps = _num(best["keeps_up_to_kg"])
    if not math.isnan(keeps) and keeps < mass:
        why.append(f"its envelope keeps up to {keeps:g} kg at peak current, {mass - keeps:.1f} kg short")
    return (f"none in the catalogue walks it; the best, point {best['point']} ({_label(best)}, "
            f"{_fmt(best['actuator_kg'], '.3f')} kg), {'; '.join(why) or 'see its row'}")


def _label(r: dict[str, Any]) -> str:
    return (f"{r['motor']}, belt {r['driver_teeth']}/{r['driven_teeth']} x {_fmt(r['pitch_mm'], 'g')} mm "
            f"({_fmt(r['ratio'], '.2f')}:1), spring {r['spring']}, {r['battery']}")


def docs_search_table(spec: DesignSpec, rows: list[dict[str, Any]]) -> str:
    """docs/design.md's table of a search (tests/benchmarks/test_bench_design.py checks it against the rows): every
    point with the gait data and the thermal bound its figures used."""
    from hal.virtual.plant.motors import load_motor
    from host_tools.walk import population_for

    c = spec.criteria
    head = ("| point | design | speed | gait data | moment share | RMS ° | peak A | belt N / rated (SDP/SI Table 3) "
            "| steady °C: nominal / pessimistic R_ha (margin to derating) | J/stride | km/charge | walks |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in sorted(rows, key=lambda r: r["point"]):
        gait = "adult-shaped" if population_for(float(r["body_mass_kg"])) == "adult" else "children's"
        r_ha = load_motor(r["motor"]).housing_to_ambient_max_k_per_w
        status = "yes" if walks(r, c) else "no" + (f" ({r['fault']})" if r.get("fault") else "")
        lines.append(
            f"| {r['point']} | {r['motor']}, {r['driver_teeth']}/{r['driven_teeth']} x {_fmt(r['pitch_mm'], 'g')} mm "
            f"({_fmt(r['ratio'], '.2f')}:1), spring {r['spring']} | {r['speed']} | {gait}, "
            f"{_fmt(r['body_mass_kg'], 'g')} kg | {_fmt(r['moment_share'], '.3f')} | "
            f"{_fmt(r['tracking_rms_deg'], '.2f')} | {_fmt(r['peak_current_a'], '.1f')} | "
            f"{_fmt(r.get('belt_tension_n'), '.0f')} / {_fmt(r.get('belt_rated_n'), '.0f')} | "
            f"{_fmt(r['steady_state_c'], '.1f')} / {_fmt(r.get('steady_state_pessimistic_c'), '.1f')} at "
            f"{r_ha:g} K/W ({_fmt(r.get('thermal_margin_c'), '.1f')}) | {_fmt(r['energy_per_stride_j'], '.1f')} | "
            f"{_fmt(r['distance_per_charge_km'], '.1f')} | {status} |")
    return "\n".join(lines) + "\n"


def _plot(path: Path, rows: list[dict[str, Any]], c: WalkCriteria) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    gs = groups(rows)
    fig, axes = plt.subplots(1, len(gs), figsize=(4.2 * len(gs) + 1.0, 4.2), squeeze=False, sharey=True,
                             layout="constrained")
    energies = [_num(r["energy_per_stride_j"]) for r in rows]
    finite = [e for e in energies if not math.isnan(e)]
    norm = matplotlib.colors.Normalize(min(finite), max(finite)) if finite else None
    sc = None
    for ax, (mass, speed) in zip(axes[0], gs, strict=True):
        mine = [r for r in rows if (float(r["body_mass_kg"]), r["speed"]) == (mass, speed)
                and not math.isnan(_num(r["moment_share"]))]
        ok = [r for r in mine if walks(r, c)]
        front = pareto(ok)
        x = np.array([_num(r["actuator_kg"]) for r in mine])
        y = np.array([_num(r["moment_share"]) for r in mine])
        e = np.array([_num(r["energy_per_stride_j"]) for r in mine])
        fault = np.array([r["status"] != "ok" or not r["within_thermal"] for r in mine], dtype=bool)
        loose = np.array([not walks(r, c) for r in mine], dtype=bool) & ~fault
        if len(mine):
            ax.scatter(x[fault], y[fault], marker="x", color="tab:red", s=18, label="fault or too hot")
            ax.scatter(x[loose], y[loose], marker="+", color="tab:orange", s=22,
                       label=f"tracks worse than {c.max_tracking_rms_deg:g}° RMS" + " or share below")
            ok_ = ~fault & ~loose
            kw = {"c": e[ok_], "cmap": "viridis", "norm": norm} if norm is not None else {"color": "tab:blue"}
            sc = ax.scatter(x[ok_], y[ok_], s=22, label="walks", **kw)
        if front:
            f = sorted(front, key=lambda r: _num(r["actuator_kg"]))
            ax.plot([_num(r["actuator_kg"]) for r in f], [_num(r["moment_share"]) for r in f], "k-o", mfc="none",
                    ms=9, lw=0.8, label="non-dominated (walks)")
        ax.axhline(c.min_moment_share, color="grey", ls="--", lw=0.8, label=f"share ≥ {c.min_moment_share:.0%}")
        ax.set_title(f"{mass:g} kg, {speed}", fontsize=9)
        ax.set_xlabel("actuator mass [kg] (estimate)")
        ax.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("share of the stance moment delivered (bench)")
    axes[0][0].legend(fontsize=7, loc="lower right")
    if sc is not None and norm is not None:
        fig.colorbar(sc, ax=axes[0].tolist(), label="energy per stride at the battery [J]")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    write_atomic(path, buf.getvalue())


def write_design_report(spec: DesignSpec, points: list[DesignPoint], rows: list[dict[str, Any]], out: Path,
                        wall_time_s: float, where: str) -> Path:
    """Write design.md and pareto.png into out; return design.md's path."""
    from host_tools.studies.design_point import rerun_command

    by_index = {p.index: p for p in points}
    c = spec.criteria
    md = [f"# Design search {spec.path.name}", "",
          f"{len(rows)} points ({status_counts(rows)}) on {where} in "
          f"{_fmt(wall_time_s, '.1f')} s; {spec.strides} strides each, controller {spec.controller}, seed {spec.seed}. "
          f"A design walks the person when its run has no fault, its winding stays within the thermal limit (the "
          "firmware's over-temperature threshold or the insulation's or magnets', the steady state of continuous "
          "walking), "
          f"it delivers at least {c.min_moment_share:.0%} of the stance moment (measured as a bench does: the "
          "motor's reported current x the drive's N·m per A, plus the plant's spring at the firmware's angle) and "
          f"the encoder measures at most {c.max_tracking_rms_deg:g}° RMS tracking error, its steady winding with the "
          f"housing resistance at its pessimistic end stays {c.min_thermal_margin_c:g} °C below the firmware's "
          "derating start" + (" and its belt's peak tension is within the belt's rated working tension"
                              if c.belt_within_rating else "") + ". Winding "
          "temperatures are the thermal model's (emulation only); the actuator mass is an estimate "
          "(docs/design.md). n/a: the run's summary has no such figure.", ""]
    md += ["## The lightest design that walks each body mass and speed", ""]
    for mass, speed in groups(rows):
        mine = [r for r in rows if (float(r["body_mass_kg"]), r["speed"]) == (mass, speed)]
        best = lightest(mine, c)
        if best is None:
            md.append(f"- **{mass:g} kg, {speed}**: {_shortfall(mine, mass, c)}.")
        else:
            md.append(f"- **{mass:g} kg, {speed}**: point {best['point']}, {_label(best)}: "
                      f"{_fmt(best['actuator_kg'], '.3f')} kg, moment share {_fmt(best['moment_share'], '.1%')}, "
                      f"peak {_fmt(best['peak_current_a'], '.1f')} A, winding {_fmt(best['winding_c_end'], '.1f')} °C "
                      f"after {spec.strides} strides ({_fmt(best['steady_state_c'], '.1f')} °C steady, "
                      f"{_fmt(best.get('steady_state_pessimistic_c'), '.1f')} °C with R_ha pessimistic, limit "
                      f"{_fmt(best['thermal_limit_c'], '.0f')} °C), belt {_fmt(best.get('belt_tension_n'), '.0f')} N "
                      f"of {_fmt(best.get('belt_rated_n'), '.0f')} N rated, "
                      f"{_fmt(best['energy_per_stride_j'], '.1f')} J per "
                      f"stride, {_fmt(best['distance_per_charge_km'], '.1f')} km per charge; "
                      f"`{rerun_command(by_index[best['point']])}`")
    md += ["", "## The report's actuator (AK60-6, 14:3 belt, no spring)", ""]
    mine = [r for r in rows if is_report_design(r)]
    if not mine:
        md.append("Not in this search.")
    for r in mine:
        state = "walks" if walks(r, c) else (f"latched {r['fault']} at {_fmt(r['fault_at_s'])} s"
                                                    if r["fault"] else r["status"] if r["status"] != "ok"
                                                    else "does not walk")
        md.append(f"- point {r['point']}, {float(r['body_mass_kg']):g} kg, {r['speed']}, {r['battery']}: {state}; "
                  "moment share "
                  f"{_fmt(r['moment_share'], '.1%')}; its envelope keeps up to {_fmt(r['keeps_up_to_kg'], 'g')} kg at "
                  f"peak current ({_fmt(r['keeps_up_to_kg_limit'], 'g')} kg at the firmware's current limit).")
    md += ["", "## Non-dominated designs", "",
           "Per body mass and speed, among the designs that walk: no other is lighter, delivers more of the moment "
           "and spends less energy per stride all at once (energy left out where a run has no battery figure). "
           "Plot: `pareto.png` (x: actuator mass, y: moment share, colour: energy per stride; red crosses: a fault "
           "or too hot; orange pluses: tracks or delivers too little; circled: non-dominated).", "",
           "| body mass kg | speed | point | design | actuator kg | moment share | energy/stride J | km/charge | "
           "winding °C (end / steady) |", "|---|---|---|---|---|---|---|---|---|"]
    for mass, speed in groups(rows):
        ok = [r for r in rows if (float(r["body_mass_kg"]), r["speed"]) == (mass, speed) and walks(r, c)]
        for r in sorted(pareto(ok), key=lambda r: _num(r["actuator_kg"])):
            md.append(f"| {mass:g} | {speed} | {r['point']} | {_label(r)} | {_fmt(r['actuator_kg'], '.3f')} | "
                      f"{_fmt(r['moment_share'], '.3f')} | {_fmt(r['energy_per_stride_j'], '.1f')} | "
                      f"{_fmt(r['distance_per_charge_km'], '.1f')} | {_fmt(r['winding_c_end'], '.1f')} / "
                      f"{_fmt(r['steady_state_c'], '.1f')} |")
    md += ["", "## Every point", "",
           "| point | motor | belt | ratio | spring | battery | kg | speed | status | moment share | peak A | peak W "
           "| winding °C end / steady / reported | steady, R_ha pessimistic °C | belt N peak / rated "
           "| energy/stride J | km/charge | actuator kg | keeps up to kg |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        st = r["status"] if not r["fault"] else f"fault {r['fault']} at {_fmt(r['fault_at_s'])} s"
        if r["status"] in ("error", "timeout"):
            st = f"{r['status']}: {r['error']}"[:120]
        md.append(f"| {r['point']} | {r['motor']} | {r['driver_teeth']}/{r['driven_teeth']} x "
                  f"{_fmt(r['pitch_mm'], 'g')} mm | {_fmt(r['ratio'], '.2f')} | {r['spring']} | {r['battery']} | "
                  f"{float(r['body_mass_kg']):g} | "
                  f"{r['speed']} | {st} | {_fmt(r['moment_share'], '.3f')} | {_fmt(r['peak_current_a'], '.1f')} | "
                  f"{_fmt(r['peak_electrical_w'], '.0f')} | {_fmt(r['winding_c_end'], '.1f')} / "
                  f"{_fmt(r['steady_state_c'], '.1f')} / {_fmt(r['motor_reported_c_max'], '.1f')} | "
                  f"{_fmt(r.get('steady_state_pessimistic_c'), '.1f')} | {_fmt(r.get('belt_tension_n'), '.0f')} / "
                  f"{_fmt(r.get('belt_rated_n'), '.0f')} | "
                  f"{_fmt(r['energy_per_stride_j'], '.1f')} | {_fmt(r['distance_per_charge_km'], '.1f')} | "
                  f"{_fmt(r['actuator_kg'], '.3f')} | {_fmt(r['keeps_up_to_kg'], 'g')} |")
    md += ["", "Files: `results.parquet`, `results.csv` (every column), `pareto.png`, `docs_table.md` (the table of "
           "docs/design.md: `python -m host_tools.studies.design_docs search OUT` puts it there), `points/NNNN/` (each "
           "point's design profile, summary.json and report.md).", ""]
    _plot(out / "pareto.png", rows, c)
    write_atomic(out / "docs_table.md", docs_search_table(spec, rows))
    path = out / "design.md"
    write_atomic(path, "\n".join(md) + "\n")
    return path

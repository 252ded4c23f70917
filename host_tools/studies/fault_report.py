"""The acceptance criteria of a fault campaign, its hazard table, and report.md with the heat map and the traces.

Criteria come from a TOML (profiles/faults/criteria.toml, argued in docs/safety.md): ``[default]`` for every
fault, ``[fault.<name>]`` overriding keys for one. Each criterion is judged on a fault's worst point; a failure
is one line naming the fault, the criterion, the worst value and the point, with the command that re-runs it.
"""

from __future__ import annotations

import io
import logging
import math
import shlex
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hal.virtual.faults import INJECTORS, injector_class
from host_tools.contract import shell_command
from host_tools.outdir import write_atomic
from host_tools.studies.fault_spec import FaultSpec
from host_tools.studies.sweep_table import status_counts

__all__ = ["CRITERIA", "Failure", "check_criteria", "hazard_rows", "hazard_table", "judged", "load_criteria",
           "rerun_command", "safe_state_rows", "safe_states_table", "write_fault_report"]

#: criterion -> (the row's figure, unit, what it bounds)
CRITERIA: dict[str, tuple[str, str, str]] = {
    "excursion_deg": ("excursion_deg", "deg", "unintended ankle excursion, onset to safe command"),
    "velocity_dps": ("velocity_dps", "deg/s", "unintended ankle velocity, onset to safe command"),
    "torque_nm": ("torque_nm", "N m", "unintended output torque, onset to safe command"),
    "torque_share": ("torque_share", "x rated", "unintended output torque over the design's rated output torque"),
    "time_to_safe_ms": ("safe_ms", "ms", "onset to the safe command on the wire (detected points)"),
    "impact_dps": ("impact_dps", "deg/s", "speed entering a mechanical stop"),
    "safe_excursion_deg": ("safe_excursion_deg", "deg", "the safe state's own excursion, from the safe command on"),
    "safe_impact_dps": ("safe_impact_dps", "deg/s", "speed entering a mechanical stop in the safe state"),
}
#: The supervisor check behind each fault reason: the risk control, named after its hazard.
CONTROLS: dict[str, str] = {
    "IMU_TIMEOUT": "stale IMU data: no frame for imu_timeout_s",
    "MOTOR_TIMEOUT": "stale motor feedback: no reply for motor_timeout_s",
    "COMMAND_STALE": "stale command: none taken by the port for command_timeout_s",
    "SENSOR_DISAGREEMENT": "encoder/IMU disagreement above disagreement_rad",
    "MOTOR_FAULT": "the motor's fault code",
    "DEADLINE_MISSES": "a streak of deadline misses",
    "CONTROLLER_ERROR": "the controller raised or returned a non-finite command",
    "ANGLE_LIMIT": "angle outside the angle limits",
    "CURRENT_LIMIT": "measured current beyond the current limit",
    "LINK_LOST": "a port failed",
    "WATCHDOG": "the watchdog was starved",
    "TASK_OVERRUN": "a task overran its budget",
    "MOTOR_ENCODER_DISAGREEMENT": "implausible encoder: its motion against the motor's position through the belt",
    "ESTOP": "the e-stop",
    "OVER_TEMPERATURE": "the motor's reported winding temperature above [thermal] fault_c",
    "IMU_FROZEN": "IMU frames bit-identical for imu_timeout_s while the encoder moved",
    "MOTOR_JAM": "current near its limit, no motion, the reference moving, for jam_time_s (stance: dorsiflexing); "
                 "or a moment the torque balance does not explain on a slow foot (with the load cell healthy)",
}
HEAT_FIGURE = "excursion_deg"
TRACES = 3


def load_criteria(path: Path) -> dict[str, dict[str, float]]:
    """{fault name: {criterion: limit}} for every injector; ValueError naming the file, the key and the range."""
    try:
        doc = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
        raise ValueError(f"criteria {path}: cannot be read as TOML ({type(e).__name__}: {e})") from None

    def table(t: object, where: str) -> dict[str, float]:
        if not isinstance(t, dict):
            raise ValueError(f"criteria {path}: {where} must be a table")
        out = {}
        for k, v in t.items():
            if k not in CRITERIA:
                raise ValueError(f"criteria {path}: {where} key {k!r} unknown: one of {', '.join(CRITERIA)}")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < math.inf:
                raise ValueError(f"criteria {path}: {where} {k} = {v!r} out of range: a finite number >= 0")
            out[k] = float(v)
        return out

    extra = sorted(set(doc) - {"default", "fault"})
    if extra:
        raise ValueError(f"criteria {path}: table {extra[0]!r} unknown: [default] and [fault.<name>]")
    default = table(doc.get("default", {}), "[default]")
    per = doc.get("fault", {})
    if not isinstance(per, dict):
        raise ValueError(f"criteria {path}: key 'fault' must be tables [fault.<name>], not {type(per).__name__}")
    for name in per:
        if name not in INJECTORS:
            raise ValueError(f"criteria {path}: [fault.{name}] names no injector: one of {', '.join(INJECTORS)}")
    out = {name: {**default, **table(per.get(name, {}), f"[fault.{name}]")} for name in INJECTORS}
    unjudged = [name for name, limits in out.items() if not limits]
    if unjudged:  # an empty file would pass every campaign without judging anything
        raise ValueError(f"criteria {path}: no criterion for {', '.join(unjudged[:3])}"
                         f"{' ...' if len(unjudged) > 3 else ''}: give [default] (or [fault.<name>]) at least one of "
                         f"{', '.join(CRITERIA)}")
    return out


def rerun_command(spec: FaultSpec, point: int) -> str:
    """The command that re-runs one point with the full outputs of `pafp run`."""
    return shell_command("pafp", "faults", spec.path, "--point", point, "--out", f"runs/{spec.path.stem}-point-{point}")


def _num(v: object) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


@dataclass(frozen=True)
class Failure:
    """A criterion one fault did not meet, at its worst point; ``safe_state`` names the safe state when the campaign
    compares several, and ``judged`` is False for a compared one that its profile does not ship."""

    fault: str
    criterion: str
    limit: float
    value: float
    point: int
    safe_state: str = ""
    judged: bool = True

    def line(self, spec: FaultSpec) -> str:
        """One line for stderr and report.md."""
        figure, unit, _ = CRITERIA[self.criterion]
        value = "never" if math.isinf(self.value) else f"{self.value:.3g} {unit}"
        who = f"{self.fault} ({self.safe_state})" if self.safe_state else self.fault
        return (f"criterion {self.criterion} <= {self.limit:g} {unit} not met by {who}: {value} at point "
                f"{self.point} (re-run: {rerun_command(spec, self.point)})")


def _worst(rows: list[dict[str, Any]], criterion: str) -> tuple[float, int] | None:
    figure = CRITERIA[criterion][0]
    best: tuple[float, int] | None = None
    for r in rows:
        if r["status"] != "ok":
            continue
        if criterion == "time_to_safe_ms":
            if not r["detected"]:
                continue
            v = _num(r[figure])
            v = math.inf if math.isnan(v) else v  # caught, but the safe command never reached the motor
        else:
            v = _num(r[figure])
        if not math.isnan(v) and (best is None or v > best[0]):
            best = (v, int(r["point"]))
    return best


def judged(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows the verdict covers: those that ran the safe state their profile ships. A campaign that compares
    other safe states beside it shows them, unjudged; one that runs none of the shipped ones is judged whole."""
    shipped = [r for r in rows if _safe_state(r) == str(r.get("profile_safe_state", _safe_state(r)))]
    return shipped or rows


def check_criteria(rows: list[dict[str, Any]], criteria: dict[str, dict[str, float]]) -> list[Failure]:
    """Every (fault, safe state, criterion) whose worst point exceeds its limit, in fault, safe state then criterion
    order; a safe state outside the verdict (``judged``) gives failures with ``judged`` False."""
    failures = []
    verdict = {id(r) for r in judged(rows)}
    several = len({_safe_state(r) for r in rows}) > 1
    for fault, safe, in_verdict in dict.fromkeys((r["fault"], _safe_state(r), id(r) in verdict) for r in rows):
        mine = [r for r in rows if r["fault"] == fault and _safe_state(r) == safe and (id(r) in verdict) == in_verdict]
        for criterion, limit in criteria[fault].items():
            worst = _worst(mine, criterion)
            if worst is not None and worst[0] > limit:
                failures.append(Failure(fault, criterion, limit, worst[0], worst[1], safe if several else "",
                                        in_verdict))
    return failures


def _safe_state(r: dict[str, Any]) -> str:
    return str(r.get("safe_state", ""))


def hazard_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per fault (and safe state, when the campaign compares several): hazard, detection (reasons and counts),
    control, worst detect / safe times and residuals."""
    out = []
    for fault, safe in dict.fromkeys((r["fault"], _safe_state(r)) for r in rows):
        mine = [r for r in rows if r["fault"] == fault and _safe_state(r) == safe and r["status"] == "ok"]
        cls = injector_class(fault)
        reasons: dict[str, int] = {}
        for r in mine:
            key = r["reason"] if r["detected"] else "undetected"
            reasons[key] = reasons.get(key, 0) + 1
        detection = ", ".join(f"{k} {v}/{len(mine)}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1]))
        controls = "; ".join(CONTROLS.get(k, k) for k in reasons if k != "undetected") or "none: no check catches it"
        ex = _worst(mine, "excursion_deg")
        out.append({
            "fault": fault, "safe_state": safe, "hazard": cls.HAZARD, "where": cls.WHERE, "points": len(mine),
            "detection": detection,
            "control": controls,
            "detect_ms": max((_num(r["detect_ms"]) for r in mine if r["detected"]), default=math.nan),
            "safe_ms": (_worst(mine, "time_to_safe_ms") or (math.nan, -1))[0],
            "excursion_deg": ex[0] if ex else math.nan, "worst_point": ex[1] if ex else -1,
            "settle_excursion_deg": max((_num(r["settle_excursion_deg"]) for r in mine
                                         if not math.isnan(_num(r["settle_excursion_deg"]))), default=math.nan),
            "safe_excursion_deg": (_worst(mine, "safe_excursion_deg") or (math.nan, -1))[0],
            "safe_impact_dps": (_worst(mine, "safe_impact_dps") or (math.nan, -1))[0],
            "impact_dps": (_worst(mine, "impact_dps") or (math.nan, -1))[0],
            "torque_nm": (_worst(mine, "torque_nm") or (math.nan, -1))[0],
        })
    return out


def safe_state_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per scenario and design, per safe state: what the safe state itself does, over every fault's points."""
    out = []
    keys = dict.fromkeys((r["scenario"], r["body_mass_kg"], str(r.get("design", "")), _safe_state(r)) for r in rows)
    for scenario, mass, design, safe in keys:
        mine = [r for r in rows if r["status"] == "ok" and r["scenario"] == scenario and r["body_mass_kg"] == mass
                and str(r.get("design", "")) == design and _safe_state(r) == safe]

        def worst(figure: str, of: list[dict[str, Any]] = mine) -> float:
            return max((v for v in (_num(r[figure]) for r in of) if not math.isnan(v)), default=math.nan)
        caught = [r for r in mine if r["detected"]]
        out.append({"scenario": scenario if scenario == "suspended" else f"walk {mass:g} kg", "design": design,
                    "safe_state": safe, "points": len(mine), "caught": len(caught),
                    "safe_excursion_deg": worst("safe_excursion_deg", caught),
                    "safe_impact_dps": worst("safe_impact_dps", caught),
                    "stop_entries": sum(1 for r in caught if _num(r["safe_impact_dps"]) > 0),
                    "excursion_deg": worst("excursion_deg"), "impact_dps": worst("impact_dps"),
                    "torque_share": worst("torque_share")})
    return out


def _savefig(fig: Any, path: Path) -> None:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    write_atomic(path, buf.getvalue())


def _heat_map(path: Path, rows: list[dict[str, Any]], spec: FaultSpec) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    faults = list(dict.fromkeys(r["fault"] for r in rows))
    onsets = list(spec.onsets)
    grid = np.full((len(faults), len(onsets)), np.nan)
    for r in rows:
        v = _num(r.get(HEAT_FIGURE))
        if r["status"] == "ok" and not math.isnan(v):
            i, j = faults.index(r["fault"]), onsets.index(r["onset_phase"])
            grid[i, j] = v if math.isnan(grid[i, j]) else max(grid[i, j], v)
    fig, ax = plt.subplots(figsize=(1.2 + 0.7 * len(onsets), 1.0 + 0.35 * len(faults)), layout="constrained")
    im = ax.imshow(grid, aspect="auto", cmap="magma_r")
    ax.set_xticks(range(len(onsets)), [f"{o:g}" for o in onsets])
    ax.set_yticks(range(len(faults)), faults, fontsize=8)
    for i in range(len(faults)):
        for j in range(len(onsets)):
            if not math.isnan(grid[i, j]):
                ax.text(j, i, f"{grid[i, j]:.1f}", ha="center", va="center", fontsize=7,
                        color="white" if grid[i, j] > np.nanmax(grid) / 2 else "black")
    ax.set_xlabel("onset (gait phase)")
    fig.colorbar(im, ax=ax, label="worst unintended excursion [deg]")
    _savefig(fig, path)
    plt.close(fig)


def _trace(path: Path, spec: FaultSpec, index: int) -> None:
    """Re-run one point here (its fault-free pair too) and plot angle, torque and commands around the onset; its
    Perfetto trace (with the injector's acts and the safe command) goes beside the plot as .pftrace."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from host_tools.reports.timeline import write_trace
    from host_tools.studies.fault_point import fault_free_arrays, faulted_run

    logging.getLogger("firmware.safety").setLevel(logging.ERROR)  # the trip is in the plot, not on the console
    p = spec.points()[index]
    r, fault, obs, onset_s = faulted_run(p, trace=True)
    write_trace(r, path.with_suffix(".pftrace"), r.telemetry)
    base = fault_free_arrays(p)
    a = obs.arrays()
    n = min(len(a["t_s"]), len(base["t_s"]))
    t = a["t_s"][:n]
    sup = r.firmware.supervisor
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, sharex=True, figsize=(8, 6.5), layout="constrained")
    ax1.plot(t, np.degrees(base["angle_rad"][:n]), label="fault-free", color="tab:gray")
    ax1.plot(t, np.degrees(a["angle_rad"][:n]), label="with the fault", color="tab:red")
    ax1.set_ylabel("ankle (true) [deg]")
    ax2.plot(t, base["torque_nm"][:n], color="tab:gray")
    ax2.plot(t, a["torque_nm"][:n], color="tab:red")
    ax2.set_ylabel("output torque [N m]")
    ax3.step(a["cmd_t_s"], a["cmd_a"], where="post", color="tab:blue", label="current commands at the motor")
    ax3.set_ylabel("command [A]")
    ax3.set_xlabel("time [s]")
    for ax in (ax1, ax2, ax3):
        ax.axvspan(onset_s, min(fault.end_s, t[-1]), color="tab:orange", alpha=0.15)
        if sup.tripped_at_s is not None:
            ax.axvline(sup.tripped_at_s, color="k", ls="--", lw=0.8)
        ax.set_xlim(max(t[0], onset_s - 0.2), t[-1])
    ax1.legend(fontsize=7)
    ax1.set_title(f"point {index}: {p.label()}; {sup.reason.name if sup.tripped_at_s is not None else 'undetected'}",
                  fontsize=8)
    _savefig(fig, path)
    plt.close(fig)


def hazard_table(spec: FaultSpec, rows: list[dict[str, Any]], rerun: bool = True) -> list[str]:
    """The hazard table's Markdown lines: one row per fault (and safe state, when the spec compares several);
    ``rerun``: the worst point with the command that re-runs it (else its number only)."""
    md = ["| fault | hazard | where | detection (points) | risk control | worst detect [ms] | worst time to safe "
          "[ms] | worst excursion to safe [deg] | excursion after safe [deg] | safe state's own excursion [deg] | "
          "own stop impact [deg/s] | worst torque [N m] | stop impact [deg/s] | worst point |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for h in hazard_rows(rows):
        point = h["worst_point"]
        cmd = f": `{rerun_command(spec, point)}`" if rerun and point >= 0 else ""
        name = f"{h['fault']} ({h['safe_state']})" if len(spec.safe_states) > 1 else h["fault"]
        md.append(f"| {name} | {h['hazard']} | {h['where']} | {h['detection']} | {h['control']} | "
                  f"{_fmt(h['detect_ms'])} | {_fmt(h['safe_ms'])} | {_fmt(h['excursion_deg'], '.2f')} | "
                  f"{_fmt(h['settle_excursion_deg'], '.2f')} | {_fmt(h['safe_excursion_deg'])} | "
                  f"{_fmt(h['safe_impact_dps'], '.0f')} | {_fmt(h['torque_nm'], '.2f')} | "
                  f"{_fmt(h['impact_dps'], '.0f')} | {point}{cmd} |")
    return md


def safe_states_table(rows: list[dict[str, Any]]) -> list[str]:
    """The safe states side by side (safe_state_rows) as Markdown lines."""
    md = ["| scenario | design | safe state | points (caught) | own excursion [deg] | own stop impact [deg/s] "
          "(points) | excursion to safe [deg] | stop impact [deg/s] | torque / rated |",
          "|---|---|---|---|---|---|---|---|---|"]
    for s in safe_state_rows(rows):
        md.append(f"| {s['scenario']} | {s['design']} | {s['safe_state']} | {s['points']} ({s['caught']}) | "
                  f"{_fmt(s['safe_excursion_deg'])} | {_fmt(s['safe_impact_dps'], '.0f')} ({s['stop_entries']}) | "
                  f"{_fmt(s['excursion_deg'], '.2f')} | {_fmt(s['impact_dps'], '.0f')} | "
                  f"{_fmt(s['torque_share'], '.2f')} |")
    return md


def _fmt(v: float, digits: str = ".1f") -> str:
    return "–" if math.isnan(v) else ("never" if math.isinf(v) else format(v, digits))


def write_fault_report(spec: FaultSpec, rows: list[dict[str, Any]], out: Path, failures: list[Failure],
                       criteria: dict[str, dict[str, float]], wall_time_s: float, where: str,
                       traces: bool = True, interrupted: tuple[str, int] | None = None) -> Path:
    """Write report.md, plots/heatmap.png and the traces of the worst points into out; return report.md's path.

    ``interrupted``: (the stop signal, the campaign's number of points) when it stopped before its end."""
    plots = out / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    md = [f"# Fault campaign {spec.path.name}", ""]
    if interrupted is not None:
        md += [f"**Interrupted** by {interrupted[0]}: {len(rows)} of {interrupted[1]} points finished; the criteria "
               f"below judge those only; `pafp faults {shlex.quote(str(spec.path))} --resume` runs the rest.", ""]
    md += [f"{len(rows)} points ({status_counts(rows)}) on {where} in "
           f"{wall_time_s:.1f} s; seed {spec.seed}; faults act from a gait phase of the first whole stride; figures "
           "against the fault-free run of the same seeds (docs/safety.md). Angles, velocities and torques are the "
           "plant's truth (emulation only).", ""]
    md += ["## Criteria", ""]
    verdict, compared = [f for f in failures if f.judged], [f for f in failures if not f.judged]
    shipped = sorted({_safe_state(r) for r in judged(rows)})
    if len(shipped) < len({_safe_state(r) for r in rows}):
        md += [f"The verdict judges the safe state the profiles ship ({', '.join(shipped)}); the others run beside it "
               "are compared, not judged.", ""]
    if verdict:
        md += [f"- **not met**: {f.line(spec)}" for f in verdict]
    else:
        md += ["Every criterion is met on every fault's worst point."]
    if compared:
        md += ["", "Not met by the compared safe states (not judged):", ""]
        md += [f"- {f.line(spec)}" for f in compared]
    md += ["", "Limits (criteria " + str(spec.criteria) + "): " + ", ".join(
        f"{k} <= {v:g} {CRITERIA[k][1]}" for k, v in criteria[next(iter(criteria))].items()) + " (defaults; "
        "per-fault overrides in the file).", ""]
    md += ["## Hazard table", "", *hazard_table(spec, rows)]
    md += ["", "## Safe states side by side", "",
           "Over every caught point of a scenario: the safe state's own travel from where it took over and its "
           "speed into a stop (with how many caught points entered one), and over every point the worst excursion "
           "to the safe command, stop impact and unintended torque over the design's rated output.", "",
           *safe_states_table(rows)]
    ok = [r for r in rows if r["status"] == "ok"]
    md += ["", "## Worst unintended excursion by fault and onset", "", "![heat map](plots/heatmap.png)", ""]
    if ok:
        _heat_map(plots / "heatmap.png", ok, spec)
    worst = sorted(ok, key=lambda r: -_num(r["excursion_deg"]) if not math.isnan(_num(r["excursion_deg"])) else 0)
    if traces and worst:
        md += ["## Traces of the worst points", ""]
        for r in worst[:TRACES]:
            name = f"trace_point_{r['point']}.png"
            _trace(plots / name, spec, int(r["point"]))
            md += [f"- point {r['point']} ({r['fault']}, excursion {_num(r['excursion_deg']):.2f} deg): "
                   f"`{rerun_command(spec, int(r['point']))}`", f"  ![point {r['point']}](plots/{name}); "
                   f"Perfetto trace `plots/{Path(name).with_suffix('.pftrace')}` (docs/telemetry.md)"]
        md.append("")
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        md += ["## Points without figures (errors: a fault that never fired is one)", ""]
        md += [f"- point {r['point']} ({r['fault']}): {r['status']}: {r['error']}" for r in bad[:50]]
        if len(bad) > 50:
            md.append(f"- ... and {len(bad) - 50} more (results.csv)")
    path = out / "report.md"
    write_atomic(path, "\n".join(md) + "\n")
    return path

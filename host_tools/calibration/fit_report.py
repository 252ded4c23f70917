"""`pafp fit`'s outputs: the fitted plant profile (TOML), fit.json, fit.md and the plots.

The TOML is the base profile's text with each fitted key's line replaced by its value, the 95 % interval
and the run it was fitted from (every other key, and any key another tool adds, passes through as it was).
Parameters judged not identifiable keep the base value, with a comment saying so.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from hal.virtual.plant import PlantParams
from host_tools.calibration.fit_data import Experiment
from host_tools.calibration.fit_model import PARAMS, fit_percentages, plant_with, simulate
from host_tools.calibration.plant_fit import HELD_OUT_EVERY, FitResult
from host_tools.outdir import write_atomic

__all__ = ["adequacy_lines", "figure", "fit_figure", "fit_json", "validate", "verdict", "write_fit_outputs"]

# fit parameter -> the profile keys it sets
_KEYS = {"output_inertia_kg_m2": ("foot_inertia_kg_m2",), "foot_damping_nm_s_per_rad": ("foot_damping_nm_s_per_rad",),
         "coulomb_friction_nm": ("coulomb_friction_nm",), "static_friction_nm": ("actuator_backdrive_torque_nm",),
         "gravity_moment_nm": ("foot_com_distance_m", "foot_inertia_kg_m2"),
         "torque_constant_scale": ("kt_nm_per_a", "ke_v_s_per_rad"),
         "current_time_constant_s": ("current_time_constant_s",), "backlash_deg": ("backlash_deg",),
         "rotor_accel_scale": ("rotor_inertia_kg_m2", "foot_inertia_kg_m2")}
_TABLE = {"backlash_deg": "transmission"}  # optional keys a base profile may lack: written into this table


def used_values(r: FitResult) -> dict[str, float]:
    """The values that go into the profile: fitted where identifiable, the start value elsewhere."""
    return {n: (r.values[n] if r.identifiable.get(n, False) else r.start[n]) for n in r.values}


def profile_text(base_text: str, base: PlantParams, r: FitResult, run_dir: str) -> str:
    """The base profile's text with the fitted keys' lines replaced (values, intervals, source)."""
    fitted = plant_with(base, used_values(r))
    notes: dict[str, list[str]] = {}
    for name, keys in _KEYS.items():
        if name not in r.names:
            continue
        verdict = (f"{name} {r.values[name]:.6g} ± {r.ci95[name]:.3g} (95 %)" if r.identifiable.get(name, False)
                   else f"{name} not identifiable (kept)")
        for key in keys:
            notes.setdefault(key, []).append(verdict)
    text = base_text
    for key, verdicts in notes.items():
        value = getattr(fitted, key)
        line = f"{key} = {value!r}  # fitted from {run_dir}: {'; '.join(verdicts)}"
        text, n = re.subn(rf"^{re.escape(key)}\s*=[^\n]*", line.replace("\\", "\\\\"), text, count=1, flags=re.M)
        if n == 0 and key in _TABLE:  # an optional key: it goes at the top of its table
            head = re.search(rf"^\[{_TABLE[key]}\][^\n]*\n", text, flags=re.M)
            if head is not None:
                text, n = text[:head.end()] + line + "\n" + text[head.end():], 1
        if n != 1:
            raise ValueError(f"base plant profile has no line for {key}")
    extra = [f"# {n} = {r.values[n]:.6g} ± {r.ci95[n]:.3g} ({PARAMS[n].meaning}; not a plant-profile key)"
             if r.identifiable[n] else f"# {n}: not identifiable from this recording"
             for n in r.names if n not in _KEYS]
    return f"# Plant fitted by `pafp fit` from {run_dir} (fit.json beside this file has the details).\n" + \
        "\n".join(extra) + "\n" + text


def _num(x: float) -> float | None:
    """A figure for JSON: rounded, a non-finite one as null."""
    return round(x, 9) if math.isfinite(x) else None


def fit_json(r: FitResult, exp: Experiment, extra: dict | None = None) -> dict:
    """Every figure of the fit, JSON-ready (non-finite numbers as null)."""
    num = _num
    params = {n: {"value": num(r.values[n]), "ci95_half_width": num(r.ci95[n]),
                  # the part of ci95_half_width that is the rotor side's (Kt/J_m) interval
                  "ci95_rotor_side": num(r.rotor_ci95.get(n, 0.0)),
                  # the part that is the writes' arrival the record leaves unknown (serial mode; 0 when exact)
                  "ci95_timing": num(r.timing_ci95.get(n, 0.0)),
                  # the part that is the encoder's count at the windows that start stuck (where the foot sits in it)
                  "ci95_stuck_starts": num(r.stuck_ci95.get(n, 0.0)), "start": num(r.start[n]),
                  "collinearity": num(r.collinearity[n]), "identifiable": r.identifiable[n],
                  "unit": PARAMS[n].unit, "meaning": PARAMS[n].meaning, "bounds": [PARAMS[n].lo, PARAMS[n].hi]}
              for n in r.names}
    fixed = {n: {"collinearity_if_fitted": num(c), "identifiable": False,
                 "why": "its column is a near-combination of the fitted ones: the current is the only torque "
                        "measure, so a torque scale moves inertia, damping, friction and gravity together"}
             for n, c in r.fixed_checks.items()}
    return {"run": exp.source, "params": params, "fixed": fixed,
            "fit_percent": {k: {s: num(v) for s, v in d.items()} for k, d in r.fit_pct.items()},
            "span_s": [num(r.span_s[0]), num(r.span_s[1])], "samples": len(exp.t), "commands": len(exp.t_cmd),
            "evaluations": r.nfev, "cost": num(r.cost), "wall_time_s": round(r.wall_s, 3), "solver": r.message,
            # the residual scales the signals were weighed by (each one's RMS at the first solution)
            "noise_scales": {"angle_deg": num(math.degrees(r.noise_scales.get("angle", math.nan))),
                             "current_a": num(r.noise_scales.get("current", math.nan)),
                             "imu_deg": num(math.degrees(r.noise_scales.get("imu", math.nan)))},
            # used samples whose reply answers a request with no simulated counterpart: out of the current's errors
            "current_samples_without_simulation": dict(r.unheard),
            # the tolerance table's relative spread of the rotor side (Kt/J_m): its profile's prior (`rotor_side_sd`)
            "rotor_side_sd": num(r.rotor_sd),
            # the median window the record leaves a write's arrival (ms; 0: the timing is exact, the virtual bench)
            "arrival_window_ms": num(r.arrival_window_ms),
            # used samples in windows of a stall (their writes' arrival windows over stall_bound_ms on average):
            # out of the fit and of the fit percentages (serial mode; 0 when the timing is exact)
            "stalled_samples_left_out": dict(r.stalled), "stall_bound_ms": num(r.stall_bound_ms),
            "adequacy": r.adequacy, **(extra or {})}


def validate(base: PlantParams, r: FitResult, other: Experiment) -> dict:
    """The fitted plant on another recording, fit.json's ``validation``: its fit percentages (windowed simulation,
    as the fit), with that recording's stall windows (`Experiment.stalled`) left out and counted as the fit leaves
    out and counts its own; its percentages are null when nothing else is left."""
    stalled = other.stalled()
    _, used = other.interleave(1, drop=stalled)  # every stretch is the "held-out" one: all but the stall's windows
    pct, unheard = (fit_percentages(base, used_values(r), used) if len(used.t) else
                    ({"angle": math.nan, "current": math.nan, "imu": math.nan}, 0))
    return {"run": other.source, "fit_percent": {k: _num(v) for k, v in pct.items()}, "samples": len(used.t),
            "stalled_samples_left_out": int(np.count_nonzero(stalled)), "current_samples_without_simulation": unheard}


def _spans(t: np.ndarray) -> list[tuple[float, float]]:
    """(first, last) time of each run of samples `t` whose steps stay under twice the median step."""
    if len(t) == 0:
        return []
    cut = np.flatnonzero(np.diff(t) > 2.0 * float(np.median(np.diff(t)))) if len(t) > 1 else np.zeros(0, int)
    return [(float(t[a]), float(t[b])) for a, b in zip(np.r_[0, cut + 1], np.r_[cut, len(t) - 1], strict=True)]


def fit_figure(base: PlantParams, r: FitResult, exp: Experiment):
    """fit.png's figure: measured and simulated on the fitting and the held-out stretches and their residuals, as
    the fit used them: a stall's windows (`Experiment.stalled`) are left out of both and shaded, labelled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stalled = exp.stalled()
    parts = exp.interleave(HELD_OUT_EVERY, drop=stalled)  # what the fit used
    stalls = exp.interleave(HELD_OUT_EVERY, drop=~stalled)  # what it left out, by the same stretches
    fig, axes = plt.subplots(3, 2, figsize=(13, 9), sharex="col")
    for col, (label, part, stall) in enumerate(zip(("fitting", "held out"), parts, stalls, strict=True)):
        a, c, _, mask = simulate(base, r.values, part)
        t = part.t
        ax = axes[0, col]
        ax.plot(t, np.degrees(part.angle), ".", ms=1, label="encoder (measured)")
        ax.plot(t[mask], np.degrees(a[mask]), ".", ms=1, label="simulated")
        ax.set_ylabel("angle (deg)")
        ax.set_title(f"{label}: angle fit {r.fit_pct['fit' if col == 0 else 'held_out']['angle']:.1f} %")
        ax = axes[1, col]
        ax.plot(t, part.current, ".", ms=1, label="motor reply (measured)")
        ax.plot(t[mask], c[mask], ".", ms=1, label="simulated")
        ax.set_ylabel("current (A)")
        ax = axes[2, col]
        ax.plot(t[mask], np.degrees(part.angle - a)[mask], ".", ms=1, label="angle residual (deg)")
        ax.plot(t[mask], (part.current - c)[mask], ".", ms=1, label="current residual (A)")
        ax.set_xlabel("time (s)")
        for ax in axes[:, col]:
            for k, (t0, t1) in enumerate(_spans(stall.t)):
                ax.axvspan(t0, t1, color="0.85", zorder=0,
                           label=f"stall: left out ({len(stall.t)} samples)" if k == 0 else None)
            ax.legend(markerscale=8, fontsize=8)
    fig.tight_layout()
    return fig


def _plots(out: Path, base: PlantParams, r: FitResult, exp: Experiment) -> None:
    import matplotlib.pyplot as plt

    fig = fit_figure(base, r, exp)
    tmp = out / ".fit.tmp.png"
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    tmp.replace(out / "fit.png")
    fig, ax = plt.subplots(figsize=(7, 6))
    im = ax.imshow(r.correlations, vmin=-1, vmax=1, cmap="coolwarm")
    names = r.jac_names or r.names
    ax.set_xticks(range(len(names)), names, rotation=90, fontsize=7)
    ax.set_yticks(range(len(names)), names, fontsize=7)
    ax.set_title("parameter correlations (normalised Jacobian)")
    fig.colorbar(im)
    fig.tight_layout()
    tmp = out / ".correlations.tmp.png"
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    tmp.replace(out / "correlations.png")


def figure(value: float | None, spec: str) -> str:
    """A figure, or n/a for one that is not a number (a signal that never moved has no fit percentage)."""
    return "n/a" if value is None else format(value, spec)


_g = figure


def verdict(p: dict) -> str:
    """A fitted parameter's verdict (fit.json's entry): identified, or not, with the start value the outputs keep
    (the value the solver ended at is shown beside it but is not one to use)."""
    if p["identifiable"]:
        return "identified"
    return f"NOT IDENTIFIABLE: kept at its start, {_g(p['start'], '.6g')}; the value shown is not to be used"


def _markdown(s: dict) -> str:
    lines = ["# Plant fit", "", f"Recording `{s['run']}`: {s['samples']} samples, {s['commands']} current commands, "
             f"fitted in {s['wall_time_s']} s ({s['evaluations']} evaluations of the cost by the solver; each "
             "Jacobian it took simulated the recording once more per parameter).", "",
             "| parameter | value | 95 % ± | of which rotor side | of which timing | of which stuck starts | "
             "collinearity | verdict |", "|---|---|---|---|---|---|---|---|"]
    for n, p in s["params"].items():
        lines.append(f"| {n} ({p['unit']}) | {_g(p['value'], '.6g')} | {_g(p['ci95_half_width'], '.3g')} | "
                     f"{_g(p['ci95_rotor_side'], '.2g')} | {_g(p['ci95_timing'], '.2g')} | "
                     f"{_g(p['ci95_stuck_starts'], '.2g')} | "
                     f"{_g(p['collinearity'], '.2f')} | {verdict(p)} |")
    for n, p in s["fixed"].items():
        lines.append(f"| {n} | fixed | | | | | {p['collinearity_if_fitted']} | **not identifiable**: {p['why']} |")
    lines += ["", "95 % ± is each parameter's interval on its own. It includes the rotor side's: the rotor's Kt/J_m "
              "(`rotor_accel_scale`), which alone carries it across the backlash at each reversal, is fitted by its "
              "profile (the tolerance table's relative spread of Kt and rotor inertia, "
              f"{_g(s['rotor_side_sd'], '.3f')}, as its prior), and the others' shift across its interval is added "
              "to their covariance; that part is in its own column. "
              + ("The timing's column: the record bounds each write's arrival at the motor only to a window (median "
                 f"{_g(s['arrival_window_ms'], '.3f')} ms); the shift of the fit over writes drawn within it is "
                 "added likewise." if s["arrival_window_ms"] else
                 "The timing's column is 0: the virtual bench's writes arrive when the fit takes them to.")
              + " The stuck starts' column: a window that starts stuck starts at its encoder reading, which places "
              "the foot only to its count; the shift of the fit over starts drawn within the count is added likewise."]
    lines += ["", *adequacy_lines(s["adequacy"])]
    lines += ["", "Fit percentage, 100 (1 − ‖y − ŷ‖ / ‖y − mean y‖) (MATLAB `compare`), windowed simulation:", "",
              "| segment | angle | current | IMU |", "|---|---|---|---|"]
    for seg, d in s["fit_percent"].items():
        lines.append(f"| {seg} | {d['angle']} | {d['current']} | {d['imu']} |")
    ns, unheard = s["noise_scales"], s["current_samples_without_simulation"]
    lines += ["", "Residuals weighed by each signal's own RMS at the first solution: angle "
              f"{_g(ns['angle_deg'], '.3g')} deg, current {_g(ns['current_a'], '.3g')} A, IMU "
              f"{_g(ns['imu_deg'], '.3g')} deg. Samples whose current has no simulated counterpart, left out of "
              f"the current: {unheard.get('fit', 0)} (fit), "
              f"{unheard.get('held_out', 0)} (held out)."]
    if s.get("stall_bound_ms"):
        stalled = s["stalled_samples_left_out"]
        lines += ["", "Samples in windows of a stall (their writes' arrivals at the motor unknown by more than "
                  f"{_g(s['stall_bound_ms'], 'g')} ms on average), left out of the fit and of the fit percentages: "
                  f"{stalled.get('fit', 0)} (fit), {stalled.get('held_out', 0)} (held out)."]
    if "validation" in s:
        v = s["validation"]
        pct = v["fit_percent"]
        lines += ["", f"On another recording, `{v['run']}` ({v['samples']} samples used): fit percentage angle "
                  f"{_g(pct['angle'], '.1f')}, current {_g(pct['current'], '.1f')}, IMU {_g(pct['imu'], '.1f')}; "
                  f"left out as the fit's own: {v['stalled_samples_left_out']} samples in windows of a stall, "
                  f"{v['current_samples_without_simulation']} currents without a simulated counterpart."]
    lines += ["", "Plots: `fit.png` (measured and simulated, fitting and held-out stretches, residuals; a stall's "
              "windows shaded, left out), "
              "`correlations.png`. The fitted profile is `plant_fitted.toml`: `pafp run --plant` takes it."]
    return "\n".join(lines) + "\n"


def adequacy_lines(a: dict) -> list[str]:
    """fit.md's paragraph on the model-adequacy check (fit.json's ``adequacy``)."""
    if not a:
        return []
    if not a["tests"]:
        return [f"**Model adequacy: {a['verdict']}.** The intervals hold only for the model."]
    against = a.get("against", ["command"])
    closed = against == ["command"]
    inputs = "the command" if closed else "the experiment's " + " and ".join(against)
    res = a.get("resolution")
    correlation = (f"the residuals of angle, current and IMU pitch against {inputs} at lags 0-{a['max_lag_ms']:g} ms "
                   f"(cross-correlation, its bound corrected for colored residuals; |z| bound {a['z_bound']:g}, "
                   f"{100 * a['family_alpha']:g} % shared over the {a.get('tests_in_family', '')} lags"
                   + ("; the command carries the closed loop's feedback of the measured angle, so a correct model can "
                      "fail: docs/calibration.md, Limits)" if closed else ")"))
    if res:
        head = (f"**Model adequacy: {a['verdict']}.** The encoder angle's residual against the encoder's count "
                f"({res['count_deg']:g} deg): {100 * res['share_beyond_one_count']:.2f} % of the samples more than one "
                f"count from the model's (limit {100 * res['limit']:g} %). Reported beside it, not deciding (correct "
                f"models exceed their bound too: docs/calibration.md, Limits): {correlation}: "
                + ("; ".join(a.get("correlation_beyond", [])) or "none beyond") + ".")
    else:
        head = f"**Model adequacy: {a['verdict']}.** The encoder never moved; decided by {correlation}."
    if not a["failing"]:
        return [head + " The intervals hold for this model; an effect it lacks that keeps the angle within a count "
                "is not excluded."]
    return [head + " The model likely lacks an effect the bench has. **The 95 % intervals above are conditional on "
            "the model**: they bound the noise's part of the error, not the bias from what it lacks. Failing:", "",
            *(f"- {f}" for f in a["failing"])]


def write_fit_outputs(out: Path, base: PlantParams, base_text: str, r: FitResult, exp: Experiment,
                      extra: dict | None = None, plot: bool = True) -> dict:
    """Write plant_fitted.toml, fit.json, fit.md, summary.json and (plot) fit.png and correlations.png into out."""
    s = fit_json(r, exp, extra)
    write_atomic(out / "plant_fitted.toml", profile_text(base_text, base, r, exp.source))
    write_atomic(out / "fit.json", json.dumps(s, indent=2) + "\n")
    write_atomic(out / "fit.md", _markdown(s))
    # the short summary every pafp output directory has (and by which --out knows it may be replaced)
    write_atomic(out / "summary.json", json.dumps({"command": "fit", "run": exp.source, "details": "fit.json",
                                                   "fit_percent": s["fit_percent"]}, indent=2) + "\n")
    if plot:
        _plots(out, base, r, exp)
    return s

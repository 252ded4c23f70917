"""Gait-event detection latency: the firmware's heel strikes and toe offs against the scenario's true ones.

An emulation-only figure: the true events are the walking scenario's contact times (hal/virtual/plant/
ground.py), which no bench measures. For each true event the latency is the time to the first detection of
the same kind from ``EARLY_S`` before it to half a stride after it (negative: detected early); a true
event with none is missed. Both detectors are scored on the same run: the ground sensors' (load cell and
FSRs, firmware/control/ground_events.py) and the motor-load estimate (firmware/control/gait_events.py);
``used`` scores what drove the controller: the ground sensors until a sensor check fired, then the
motor-load estimate.
"""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from typing import Any

__all__ = ["EARLY_S", "event_summary", "gait_event_lines", "latencies"]

EARLY_S = 0.1
"""How long before a true event a detection still counts as that event's (an early one)."""


def latencies(true_s: Sequence[float], detected_s: Sequence[float], window_s: float) -> tuple[list[float], int]:
    """(latency in s of each true event that was detected, number missed).

    >>> found, missed = latencies([1.0, 2.0], [1.004, 2.9], 0.5); [round(x, 9) for x in found], missed
    ([0.004], 1)
    """
    found, missed = [], 0
    for t in true_s:
        hits = [d for d in detected_s if t - EARLY_S <= d <= t + window_s]
        if hits:
            found.append(min(hits) - t)
        else:
            missed += 1
    return found, missed


def _figures(true_s: Sequence[float], detected_s: Sequence[float], window_s: float) -> dict[str, Any]:
    lat, missed = latencies(true_s, detected_s, window_s)
    ms = [x * 1000.0 for x in lat]
    return {"median_ms": round(statistics.median(ms), 2) if ms else None,
            "max_ms": round(max(ms), 2) if ms else None,
            "min_ms": round(min(ms), 2) if ms else None,
            "detected": len(ms), "missed": missed}


def _detector(strikes: Sequence[float], offs: Sequence[float], true: tuple[list[float], list[float]],
              window_s: float) -> dict[str, Any]:
    return {"heel_strike": _figures(true[0], strikes, window_s), "toe_off": _figures(true[1], offs, window_s)}


def event_summary(r: Any) -> dict[str, Any] | None:
    """summary.json's "gait_events" of a virtual run with ground under the foot (None without)."""
    true_events = getattr(getattr(getattr(r, "bench", None), "ground", None), "true_events", None)
    if true_events is None:
        return None
    true = true_events(r.sim_time_s)
    stride_s = r.firmware.config.stride_s
    window = stride_s / 2
    old = r.firmware.load_detector
    out: dict[str, Any] = {
        "note": "emulation only: latency of each detection after the scenario's true event (negative: early)",
        "true_events": {"heel_strike": len(true[0]), "toe_off": len(true[1])},
        "motor_load": _detector(old.heel_strike_s, old.toe_off_s, true, window),
    }
    new = r.firmware.ground_events
    if new is None:
        out["detector"] = "motor_load"
        out["fallback"] = None
        out["used"] = out["motor_load"]
        return out
    out["ground_sensors"] = _detector(new.heel_strike_s, new.toe_off_s, true, window)
    out["ground_sensors"]["foot_flats"] = new.foot_flats
    out["ground_sensors"]["heel_offs"] = new.heel_offs
    if new.healthy:
        out["detector"] = "ground_sensors"
        out["fallback"] = None
        out["used"] = {k: out["ground_sensors"][k] for k in ("heel_strike", "toe_off")}
        return out
    cut = new.fault_s
    out["detector"] = "motor_load"
    out["fallback"] = {"reason": new.fault, "t_s": round(cut, 4)}
    strikes = [t for t in new.heel_strike_s if t <= cut] + [t for t in old.heel_strike_s if t > cut]
    offs = [t for t in new.toe_off_s if t <= cut] + [t for t in old.toe_off_s if t > cut]
    out["used"] = _detector(strikes, offs, true, window)
    return out


def _cell(fig: dict[str, Any]) -> str:
    if fig["median_ms"] is None:
        return f"none detected ({fig['missed']} missed)"
    missed = f", {fig['missed']} missed" if fig["missed"] else ""
    return f"{fig['median_ms']:.1f} ms (max {fig['max_ms']:.1f}{missed})"


def gait_event_lines(g: dict[str, Any]) -> list[str]:
    """The report.md section of summary.json's "gait_events"."""
    lines = ["", "## Gait events (detection latency, emulation only)", "",
             f"Median over {g['true_events']['heel_strike']} heel strikes and {g['true_events']['toe_off']} toe offs "
             "of the scenario's true contact times; negative = early.", "",
             "| detector | heel strike | toe off |", "|---|---|---|"]
    rows = [("ground sensors (load cell + FSRs)", g.get("ground_sensors")),
            ("motor load (today's; in this run)", g["motor_load"])]
    for name, d in rows:
        if d is not None:
            lines.append(f"| {name} | {_cell(d['heel_strike'])} | {_cell(d['toe_off'])} |")
    used = {"ground_sensors": "the ground sensors", "motor_load": "the motor-load estimate"}[g["detector"]]
    fb = g["fallback"]
    lines += ["", f"Detector in use at the end: {used}"
              + (f" (fallback after: {fb['reason']}, at {fb['t_s']:.3f} s)." if fb else ".")]
    return lines

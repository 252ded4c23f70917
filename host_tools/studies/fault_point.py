"""One point of a fault campaign, run where Dask puts it: `run_fault_point(point)` returns its row (never raises).

A point is two virtual runs with the same seeds and the same instruments (hal/virtual/faults/observer.py): the
fault-free run (made once per worker for each scenario, controller, link, duration and safe state, and reused) and
the run with the fault. The fault's onset is a gait phase of the first whole stride, placed on the fault-free
run's gait clock (the two runs are the same until the onset). The faulted run ends ``settle_s`` after the fault's
end. Figures are taken from the onset to the end of the faulted run, against the fault-free run:

* ``excursion_deg``, ``velocity_dps``, ``torque_nm``: the largest unintended ankle angle, velocity and output
  torque (faulted minus fault-free), from the onset until the safe command reached the motor (to the run's end
  when none did), from the plant's truth (emulation only);
* ``settle_excursion_deg``: the same excursion over the settle time after the safe command;
* ``safe_excursion_deg``, ``safe_impact_dps``: the safe state's own motion, from where the foot was when the safe
  command reached the motor to the run's end, and its speed entering a mechanical stop in that time;
* ``torque_share``: ``torque_nm`` as a share of the design's rated output torque (the motor's rated current x
  Kt x the transmission's ratio and efficiency of the plant the point ran), so one criterion fits every design;
* ``detected``, ``reason``, ``detect_ms``: the supervisor's latched reason and its delay after the onset;
* ``safe_ms``: when the first safe command (zero current or the brake) reached the motor, after the onset;
* ``stop_hit``, ``impact_dps``: whether the foot went past a mechanical stop, and its speed on entering it;
* ``cmd_peak_a``, ``cmd_last_a``: the largest current command the motor received between the onset and the
  safe command, and the last one before it (what the motor held).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
import tomllib
from typing import Any

import numpy as np

from host_tools.studies.fault_spec import FaultPoint

__all__ = ["FIGURES", "GAIT_START_MAX_S", "IDENTITY", "fault_error_row", "fault_free_arrays", "faulted_config",
           "faulted_run", "figures", "onset_of", "point_run_config", "run_fault_point"]

GAIT_START_MAX_S = 1.5  # the fault-free run covers a gait start up to this late (sensors up, start-up ramp)
#: What names a point in every row (errors too): its axes, and the plant and safe state it ran with.
IDENTITY = ("point", "fault", "params", "scenario", "body_mass_kg", "design", "safe_state", "profile_safe_state",
            "controller", "link", "onset_phase", "duration_s", "seed")
FIGURES = ("onset_s", "fired", "fired_first_s", "fired_count", "fired_what", "detected", "reason",
           "detect_ms", "safe_ms", "excursion_deg", "velocity_dps", "torque_nm", "torque_share", "settle_excursion_deg",
           "safe_excursion_deg", "safe_impact_dps", "stop_hit", "impact_dps", "cmd_peak_a", "cmd_last_a",
           "sim_time_s", "wall_time_s")


def _base_row(p: FaultPoint) -> dict[str, Any]:
    """The point's IDENTITY columns."""
    return dict(zip(IDENTITY, (p.index, p.fault, ", ".join(f"{k}={v}" for k, v in p.params), p.scenario,
                               p.body_mass_kg, _design_name(p), _firmware(p).safety.safe_state,
                               _profile_firmware(p).safety.safe_state, p.controller, p.link,
                               p.onset_phase, p.duration_s, p.seed), strict=True))


def fault_error_row(p: FaultPoint, status: str, error: str, wall_time_s: float = math.nan) -> dict[str, Any]:
    """The row of a point without figures (status error, timeout or not_fired)."""
    row = _base_row(p)
    row.update({"status": status, "error": error})
    row.update({f: math.nan for f in FIGURES})
    row.update({"fired": False, "fired_count": 0, "fired_what": "", "detected": False, "reason": "",
                "stop_hit": False, "wall_time_s": wall_time_s})
    return row


def _profile_firmware(p: FaultPoint) -> Any:
    """The firmware configuration the point's profile ships (its own safe state, link and controller)."""
    from host_tools.studies.sweep_point import firmware_config_of

    return firmware_config_of(p.profile_text, {}, p.profile_name)


def _firmware(p: FaultPoint) -> Any:
    fw = _profile_firmware(p)
    changes: dict[str, Any] = {}
    if p.link != fw.motor_link:
        changes["motor_link"] = p.link
    if p.controller != fw.controller:
        changes.update(controller=p.controller, controller_params={})
    if p.safe_state and p.safe_state != fw.safety.safe_state:
        changes["safety"] = dataclasses.replace(fw.safety, safe_state=p.safe_state)
    return fw.with_changes(**changes) if changes else fw


@functools.lru_cache(maxsize=16)
def _design_of(profile_text: str, profile_name: str) -> Any:
    """The profile's [design] (its plant: motor, belt, spring), or None: the campaign runs the plant it names."""
    from hal.virtual.plant.design import design_from_mapping

    doc = tomllib.loads(profile_text)
    return design_from_mapping(doc["design"], profile_name) if "design" in doc else None


def _design_name(p: FaultPoint) -> str:
    d = _design_of(p.profile_text, p.profile_name)
    return "ak60_6" if d is None else f"{d.motor} {d.belt_driven_teeth}/{d.belt_driver_teeth}"


def plant_params_of(p: FaultPoint) -> Any:
    """The nominal plant parameters the point's runs use (the design's when its profile has one)."""
    from hal.virtual.plant import load_plant_params
    from hal.virtual.plant.design import plant_params_for

    design = _design_of(p.profile_text, p.profile_name)
    base = load_plant_params()
    return base if design is None else plant_params_for(design, base)


def point_run_config(p: FaultPoint, faults: tuple[Any, ...], duration_s: float, trace: bool = False) -> Any:
    """The RunConfig of one of the point's runs: its scenario, controller, link and seed, with `faults` armed
    (``trace``: the scheduler's trace as `pafp run` keeps it)."""
    from host_tools.commands.run import controller_for
    from host_tools.runner import RunConfig

    fw = _firmware(p)
    traced = {} if trace else {"trace_capacity": 0}
    return RunConfig(strides=1, seed=p.seed, firmware=fw, **traced, scenario=p.scenario,
                     body_mass_kg=p.body_mass_kg, controller=controller_for(fw, p.scenario, p.body_mass_kg),
                     faults=faults, duration_s=duration_s, design=_design_of(p.profile_text, p.profile_name))


# One fault-free run per scenario, controller, link, duration and safe state, kept for the worker's whole share:
# points run fault by fault, so a cache smaller than a spec's combinations would make each run again per point
# (150 kB each for a 3-s run).
@functools.lru_cache(maxsize=256)
def _fault_free(p: FaultPoint, duration_s: float) -> tuple[float, float, dict[str, np.ndarray], str]:
    from hal.virtual.faults.observer import Observer
    from host_tools.runner import run_virtual

    obs = Observer()
    r = run_virtual(point_run_config(p, (obs,), duration_s))
    if r.gait_start_s is None or r.gait_start_s > GAIT_START_MAX_S:
        raise ValueError(f"the fault-free run's gait started at {r.gait_start_s} s, not by {GAIT_START_MAX_S} s")
    return r.gait_start_s, r.firmware.config.stride_s, obs.arrays(), r.firmware.supervisor.reason.name


def _key(p: FaultPoint) -> FaultPoint:
    """The point as the fault-free run's cache key: only what the fault-free run depends on."""
    return FaultPoint(0, "", (), p.scenario, p.body_mass_kg, p.controller, p.link, 0.0, 0.0, p.seed, 0.0, 0.0,
                      p.profile_name, p.profile_text, p.safe_state)


def onset_of(p: FaultPoint) -> tuple[float, float]:
    """(the onset in seconds, the fault-free run's length) of a point."""
    base_s = GAIT_START_MAX_S + _stride_of(p) + p.duration_s + p.settle_s  # covers every onset of the stride
    gait_start, stride, _, _ = _fault_free(_key(p), base_s)
    return gait_start + p.onset_phase * stride, base_s


def _stride_of(p: FaultPoint) -> float:
    return float(_firmware(p).stride_s)


def figures(onset_s: float, faulted: dict[str, np.ndarray], base: dict[str, np.ndarray], trip_s: float | None,
            reason: str, safe_s: float | None, params: Any = None, rated_output_nm: float = math.nan) -> dict[str, Any]:
    """A point's figures from the two runs' observer arrays (see the module docstring); params: the plant's (its
    stops; default the shipped AK60-6 plant), rated_output_nm: the design's rated output torque."""
    from hal.virtual.plant import load_plant_params

    n = min(len(faulted["t_s"]), len(base["t_s"]))
    t = faulted["t_s"][:n]
    until = safe_s if safe_s is not None else math.inf
    pre = (t >= onset_s) & (t <= until)  # onset to the safe command on the wire (or the run's end)
    post = t > until  # the safe state's own motion, over the settle time
    d_angle = np.abs(faulted["angle_rad"][:n] - base["angle_rad"][:n])
    d_vel = np.abs(faulted["velocity_rad_s"][:n] - base["velocity_rad_s"][:n])
    d_tq = np.abs(faulted["torque_nm"][:n] - base["torque_nm"][:n])
    params = load_plant_params() if params is None else params
    w = t >= onset_s
    angle, vel = faulted["angle_rad"][:n][w], faulted["velocity_rad_s"][:n][w]
    impact, hit = _impact(angle, vel, params)
    after = t > until  # the safe state's own motion: from where the foot was when it took over
    own = faulted["angle_rad"][:n][after]
    safe_excursion = float(np.max(np.abs(own - own[0]))) if len(own) else math.nan
    safe_impact = _impact(own, faulted["velocity_rad_s"][:n][after], params)[0] if len(own) else math.nan
    ct, ci, safe = faulted["cmd_t_s"], faulted["cmd_a"], faulted["cmd_safe"]
    between = (ct >= onset_s) & (ct < until) & ~safe

    def peak(x: np.ndarray, where: np.ndarray) -> float:
        return float(x[where].max()) if where.any() else math.nan
    return {
        "detected": trip_s is not None, "reason": reason,
        "detect_ms": (trip_s - onset_s) * 1e3 if trip_s is not None else math.nan,
        "safe_ms": (safe_s - onset_s) * 1e3 if safe_s is not None else math.nan,
        "excursion_deg": math.degrees(peak(d_angle, pre)), "velocity_dps": math.degrees(peak(d_vel, pre)),
        "torque_nm": peak(d_tq, pre), "torque_share": peak(d_tq, pre) / rated_output_nm,
        "settle_excursion_deg": math.degrees(peak(d_angle, post)),
        "safe_excursion_deg": math.degrees(safe_excursion), "safe_impact_dps": math.degrees(safe_impact),
        "stop_hit": hit, "impact_dps": math.degrees(impact),
        "cmd_peak_a": float(np.max(np.abs(ci[between]))) if between.any() else 0.0,
        "cmd_last_a": float(ci[between][-1]) if between.any() else math.nan,
    }


def _impact(angle: np.ndarray, vel: np.ndarray, params: Any) -> tuple[float, bool]:
    """(the largest speed entering a mechanical stop, whether any stop was entered) along angle and vel."""
    beyond = (angle > params.stop_max_rad) | (angle < params.stop_min_rad)
    entries = np.flatnonzero(beyond & ~np.concatenate([[False], beyond[:-1]]))
    return (float(np.max(np.abs(vel[entries]))) if len(entries) else 0.0), bool(len(entries))


def rated_output_nm(p: FaultPoint) -> float:
    """The design's rated output torque at the ankle: the motor's rated current x the plant's torque per ampere."""
    return float(_firmware(p).motor.rated_current_a * plant_params_of(p).output_torque_per_amp_nm)


def faulted_config(p: FaultPoint, trace: bool = False) -> tuple[Any, Any, Any, float]:
    """(RunConfig, injector, observer, onset_s) of the point's faulted run, not yet run."""
    from hal.virtual.faults import make_injector
    from hal.virtual.faults.observer import Observer

    onset_s, _ = onset_of(p)
    fault, obs = make_injector(p.fault, onset_s, p.duration_s, p.seed, **dict(p.params)), Observer()
    cfg = point_run_config(p, (obs, fault), onset_s + p.duration_s + p.settle_s, trace)
    return cfg, fault, obs, onset_s


def faulted_run(p: FaultPoint, progress: Any = None, trace: bool = False) -> tuple[Any, Any, Any, float]:
    """(RunResult, injector, observer, onset_s) of the point's faulted run (``trace``: with the run's trace)."""
    from host_tools.runner import run_virtual

    cfg, fault, obs, onset_s = faulted_config(p, trace)
    return run_virtual(cfg, progress=progress), fault, obs, onset_s


def fault_free_arrays(p: FaultPoint) -> dict[str, np.ndarray]:
    """The observer's arrays of the point's fault-free run (from the worker's cache)."""
    _, base_s = onset_of(p)
    return _fault_free(_key(p), base_s)[2]


def run_fault_point(p: FaultPoint) -> dict[str, Any]:
    """Run one point (its fault-free pair from the worker's cache) and return its row; failures are its error."""
    from host_tools.studies.sweep_point import (  # the sweep's per-point wall-time limit
        _deadline,
        _PointTimeout,
        failure_text,
    )

    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    t0 = time.perf_counter()
    try:
        onset_s, base_s = onset_of(p)
        _, _, base, base_reason = _fault_free(_key(p), base_s)
        if base_reason != "NONE":
            return fault_error_row(p, "error", f"the fault-free run latched {base_reason}: no pair to compare with",
                                   time.perf_counter() - t0)
        r, fault, obs, onset_s = faulted_run(p, _deadline(p.timeout_s))
    except _PointTimeout:
        return fault_error_row(p, "timeout", f"timeout: no result within {p.timeout_s:g} s", time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - any failure of a point is its row, not the campaign's end
        return fault_error_row(p, "error", failure_text(e), time.perf_counter() - t0)
    rec = fault.record
    if not rec.fired:
        return fault_error_row(p, "not_fired", f"fault {p.fault} never fired ({fault.describe()})",
                               time.perf_counter() - t0)
    sup = r.firmware.supervisor
    trip_s = sup.tripped_at_s
    safe_s = obs.safe_on_wire_s(trip_s) if trip_s is not None else None
    row = _base_row(p)
    row.update({"status": "ok", "error": "", "onset_s": round(onset_s, 6), "fired": True,
                "fired_first_s": rec.first_s, "fired_count": rec.count, "fired_what": rec.what})
    row.update(figures(onset_s, obs.arrays(), base, trip_s, sup.reason.name if trip_s is not None else "", safe_s,
                       plant_params_of(p), rated_output_nm(p)))
    row.update({"sim_time_s": round(r.sim_time_s, 6), "wall_time_s": round(time.perf_counter() - t0, 4)})
    return row

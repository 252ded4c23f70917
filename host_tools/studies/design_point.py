"""One point of a design search, run where Dask puts it: `run_design_point(point)` returns its row (never raises).

A point is `pafp run --scenario walk --profile <its design profile> --body-mass M --speed S --strides N
--controller C --seed K` in-process: the firmware on the virtual bench whose plant the design builds
(hal/virtual/plant/design.py), with summary.json and report.md written into the point's directory beside its
design profile. Its figures (docs/design.md, "Reading the search"):

* ``status``: ok, fault (the reason and when in ``fault`` / ``fault_at_s``), error or timeout;
* ``moment_share``: the share of the normative stance moment the actuator delivered, as a bench measures it:
  the motor's current from its status replies x the drive's ankle N·m per A (Kt x ratio x efficiency driving,
  Kt x ratio / backdriven efficiency where the current opposes the ankle's measured motion), plus the
  parallel spring's moment at the firmware's ankle angle (the spring of the plant the run had), against body
  mass x the normative moment at the same gait phase; per sample the part delivered in the demand's direction,
  capped at the demand, summed over the stance of every stride asked for (a run that latched a fault delivers
  nothing after it);
* ``tracking_rms_deg``: the RMS tracking error the encoder measured over the time in RUN (summary.json);
* ``peak_current_a``: the largest current the motor reported; ``peak_electrical_w``: the largest
  ``0.75 I² R + Kt w I`` (the q current's copper loss and the power the rotor converts) with the reported current
  and the motor speed from the firmware's ankle velocity;
* from summary.json's ``thermal`` and ``battery`` (NaN where the run has none): the winding temperature after the
  strides and its steady state (emulation only), the temperature the motor reported, energy per stride at the
  battery and distance per charge; ``thermal_limit_c``: the firmware's over-temperature threshold ([thermal]
  fault_c) or the winding's insulation or magnet limit, whichever is lower; ``steady_state_pessimistic_c``: the
  steady state with the housing-to-ambient resistance at the upper end of its range, ``thermal_margin_c`` how far it
  stays below [thermal] derate_start_c;
* ``belt_tension_n``: the belt's peak effective tension, the largest reported current x Kt x gearbox ratio over the
  driver pulley's pitch radius, taken backdriven (divided by the gearbox's backdriven efficiency, the larger of the
  two directions); ``belt_rated_n``: the belt's rated working tension (hal/virtual/plant/transmission.py, SDP/SI);
* ``actuator_kg``: host_tools/studies/design_mass.py; ``keeps_up_to_kg``: summary.json's actuator design check
  (host_tools/reports/actuator.py, on the plant the bench ran), at peak current (``_limit``: the firmware's limit).
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from hal.virtual.plant.thermal import COPPER_LOSS_FACTOR
from host_tools.contract import shell_command
from host_tools.reports.actuator import moment_share
from host_tools.studies.design_spec import DesignPoint

__all__ = ["AXES", "FIGURES", "design_error_row", "moment_share", "point_run_config", "rerun_command",
           "run_design_point"]

AXES = ("motor", "driver_teeth", "driven_teeth", "pitch_mm", "ratio", "spring", "battery", "body_mass_kg", "speed")
FIGURES = ("fault", "fault_at_s", "strides_walked", "moment_share", "tracking_rms_deg", "peak_current_a",
           "peak_electrical_w", "winding_c_end", "winding_c_max", "steady_state_c", "motor_reported_c_max",
           "thermal_limit_c", "within_thermal", "over_temperature_at_s", "energy_per_stride_j",
           "distance_per_charge_km", "motor_kg", "transmission_kg", "spring_kg", "actuator_kg", "keeps_up_to_kg",
           "keeps_up_to_kg_limit", "steady_state_pessimistic_c", "thermal_margin_c", "belt_tension_n",
           "belt_rated_n", "sim_time_s", "wall_time_s")
KEPT = ("summary.json", "report.md", "actuator.png")  # of a point's outputs, beside its design profile


def _base_row(p: DesignPoint) -> dict[str, Any]:
    return {"point": p.index, "motor": p.motor, "driver_teeth": p.driver_teeth, "driven_teeth": p.driven_teeth,
            "pitch_mm": p.pitch_mm, "ratio": round(p.ratio, 4), "spring": p.spring_label,
            "battery": p.battery or "none", "body_mass_kg": p.body_mass_kg, "speed": p.speed}


def design_error_row(p: DesignPoint, status: str, error: str, wall_time_s: float = math.nan) -> dict[str, Any]:
    """The row of a point without figures (status error or timeout)."""
    row = _base_row(p)
    row.update({"status": status, "error": error})
    row.update({f: math.nan for f in FIGURES})
    row.update({"fault": "", "within_thermal": False, "wall_time_s": wall_time_s})
    return row


def rerun_command(p: DesignPoint) -> str:
    """The `pafp run` command that runs the point as it ran here."""
    return shell_command("pafp", "run", "--scenario", "walk", "--profile", p.profile_name, "--body-mass",
                         f"{p.body_mass_kg:g}", "--speed", p.speed, "--strides", p.strides, "--controller",
                         p.controller, "--seed", p.seed,
                         *(["--ambient-c", f"{p.ambient_c:g}"] if p.ambient_c != 25.0 else []))


def point_run_config(p: DesignPoint, trace: bool = False) -> Any:
    """The RunConfig of the point, as `pafp run` builds it from rerun_command's options."""
    from firmware.config import load_firmware_config
    from hal.virtual.plant.design import load_design
    from host_tools.commands.run import controller_for
    from host_tools.runner import RunConfig

    path = Path(p.profile_name)
    fw = load_firmware_config(path)
    if fw.controller != p.controller:
        fw = fw.with_changes(controller=p.controller, controller_params={})
    extra: dict[str, Any] = {} if trace else {"trace_capacity": 0}
    return RunConfig(strides=p.strides, seed=p.seed, firmware=fw, scenario="walk", body_mass_kg=p.body_mass_kg,
                     speed=p.speed, controller=controller_for(fw, "walk", p.body_mass_kg), ambient_c=p.ambient_c,
                     design=load_design(path), **extra)


def spring_moment_nm(params: Any, angle_rad: np.ndarray) -> np.ndarray:
    """The parallel spring's moment on the ankle (positive dorsiflexing) at the ankle angles, as the plant the run
    had holds it (PlantParams.parallel_spring_torque_nm; none where the plant has no spring)."""
    if not getattr(params, "parallel_stiffness_nm_per_rad", 0.0):
        return np.zeros_like(angle_rad)
    return np.array([params.parallel_spring_torque_nm(float(a)) for a in angle_rad])


def _demand(p: DesignPoint, r: Any, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the moment the actuator must apply, stance) at the probe times over the strides asked for."""
    from host_tools.walk import walking_load

    stride_s = float(r.firmware.config.stride_s)
    load = walking_load(p.body_mass_kg, stride_s, None, p.speed)
    start = r.gait_start_s
    if start is None:  # the gait never started: every stride asked for is demanded from the settle time on
        start = float(r.config.settle_s)
    phase = (t_s - start) / stride_s
    within = (phase >= 0.0) & (phase < p.strides)
    pct = (phase % 1.0) * 100.0
    demand = np.array([load.moment_nm(x) for x in pct]) * within
    stance = within & (pct < load.toe_off_pct)
    return -demand, stance  # the ground dorsiflexes; the actuator must plantarflex


def _whole_run(p: DesignPoint, r: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(probe times, the delivered moment, the probe's reported current) padded with zero delivery over the strides
    asked for but not run (a fault ended the run early)."""
    a = r.probe.arrays()
    t, i = a["t_s"].astype(float), a["current_meas_a"].astype(float)
    angle = a["fused_angle_rad"].astype(float)
    params = _drive(p)
    # the transmission's gain by power direction: backdriven where the current opposes the ankle's motion
    moving = np.sign(np.gradient(angle, t)) if len(t) > 1 else np.zeros_like(t)
    nm_per_a = np.where(i * moving < 0.0, params.backdriven_torque_per_amp_nm, params.output_torque_per_amp_nm)
    state = a["supervisor_state"]
    from firmware.safety import SupervisorState

    running = state == int(SupervisorState.RUN)
    delivered = np.where(running, i * nm_per_a + spring_moment_nm(params, angle), 0.0)
    stride_s = float(r.firmware.config.stride_s)
    start = r.gait_start_s if r.gait_start_s is not None else float(r.config.settle_s)
    end = start + p.strides * stride_s
    if len(t) and t[-1] < end:
        dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.002
        extra = np.arange(t[-1] + dt, end, dt)
        t = np.concatenate([t, extra])
        delivered = np.concatenate([delivered, np.zeros_like(extra)])
    return t, delivered, i


def _drive(p: DesignPoint) -> Any:
    """The design's plant parameters (motor + belt + the nominal foot)."""
    from hal.virtual.plant import load_plant_params
    from hal.virtual.plant.design import load_design, plant_params_for

    design = load_design(Path(p.profile_name))
    base = load_plant_params()
    return base if design is None else plant_params_for(design, base)


def _num(d: dict[str, Any] | None, key: str) -> float:
    v = (d or {}).get(key)
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else math.nan


def figures(p: DesignPoint, r: Any, s: dict[str, Any]) -> dict[str, Any]:
    """The point's figures from its run and summary (module docstring)."""
    from hal.virtual.plant.motors import load_motor
    from host_tools.studies.design_mass import actuator_mass

    t, delivered, i_meas = _whole_run(p, r)
    demand, stance = _demand(p, r, t)
    share = moment_share(t, delivered, demand, stance)
    a = r.probe.arrays()
    params = _drive(p)
    w_motor = np.abs(np.gradient(a["fused_angle_rad"].astype(float), a["t_s"].astype(float))) * params.total_ratio \
        if len(a["t_s"]) > 1 else np.zeros(len(a["t_s"]))
    i = np.abs(i_meas)
    power = (COPPER_LOSS_FACTOR * i ** 2 * params.phase_resistance_ohm  # the q current's copper loss
             + params.kt_nm_per_a * w_motor * i)  # the rotor converts Kt i w
    motor = load_motor(p.motor)
    sup = r.firmware.supervisor
    fault = ",".join(s["faults"])
    thermal, battery = s.get("thermal"), s.get("battery")
    thermal_limits = getattr(r.firmware.config, "thermal", None)  # [thermal]: where the firmware latches
    limit = min(motor.max_temperature_c, getattr(thermal_limits, "fault_c", math.inf))
    steady = _num(thermal, "steady_state_c")
    hottest = steady if not math.isnan(steady) else _num(thermal, "winding_c_max")
    over = _num(thermal, "over_temperature_at_s")
    within = (not fault) and (math.isnan(hottest) or hottest < limit) and math.isnan(over)
    stride_s = float(r.firmware.config.stride_s)
    walked = 0 if r.gait_start_s is None else int(min(p.strides, max(0.0, (
        (sup.tripped_at_s if sup.tripped_at_s is not None else r.sim_time_s) - r.gait_start_s) / stride_s)))
    keeps = (s.get("actuator") or {}).get("keeps_up_to_body_mass_kg")  # the design check on the bench's plant
    mass = actuator_mass(motor.mass_kg, p.driver_teeth, p.driven_teeth, p.pitch_mm, p.spring_nm_per_rad,
                         p.spring_engage_deg, p.spring_sided, params.stop_min_rad, params.stop_max_rad)
    from hal.virtual.plant.design import belt_tension_per_amp_n, load_design

    hot = _num(thermal, "steady_state_pessimistic_c")
    derate = getattr(thermal_limits, "derate_start_c", math.nan)
    design = load_design(Path(p.profile_name))
    rated = design.rated_tension_n if design is not None else math.nan
    tension = float(i.max()) * belt_tension_per_amp_n(params) if len(i) else math.nan
    return {"fault": fault, "fault_at_s": round(sup.tripped_at_s, 4) if sup.tripped_at_s is not None else math.nan,
            "strides_walked": walked, "moment_share": round(share, 4),
            "tracking_rms_deg": _num(s, "encoder_rms_error_deg"),
            "peak_current_a": round(float(i.max()), 3) if len(i) else math.nan,
            "peak_electrical_w": round(float(power.max()), 1) if len(power) else math.nan,
            "winding_c_end": _num(thermal, "winding_c_end"), "winding_c_max": _num(thermal, "winding_c_max"),
            "steady_state_c": steady, "motor_reported_c_max": _num(thermal, "motor_reported_c_max"),
            "thermal_limit_c": limit, "within_thermal": bool(within), "over_temperature_at_s": over,
            "energy_per_stride_j": _num(battery, "energy_per_stride_j"),
            "distance_per_charge_km": _num(battery, "distance_per_charge_km"),
            **mass, "keeps_up_to_kg": _num(keeps, "peak"), "keeps_up_to_kg_limit": _num(keeps, "control_limit"),
            "steady_state_pessimistic_c": hot, "thermal_margin_c": round(derate - hot, 1),
            "belt_tension_n": round(tension, 1), "belt_rated_n": rated}


def _write_summary(r: Any, out: Path) -> dict[str, Any]:
    """The run's outputs as `pafp run` writes them, of which summary.json, report.md and actuator.png are kept in
    out (the telemetry, 3 MB a point, is left out: the row's `pafp run` command writes it again)."""
    import shutil
    import tempfile

    from host_tools.reports.report import write_outputs

    with tempfile.TemporaryDirectory(prefix="pafp-design-point-") as tmp:
        s = write_outputs(r, Path(tmp), plot=False, trace=False)
        out.mkdir(parents=True, exist_ok=True)
        for name in KEPT:
            if (Path(tmp) / name).is_file():
                shutil.copyfile(Path(tmp) / name, out / f".{name}.tmp")
                (out / f".{name}.tmp").replace(out / name)
    return s


def run_design_point(p: DesignPoint) -> dict[str, Any]:
    """Run one point, write its summary.json and report.md beside its design profile, return its row; a failure
    is the row's error."""
    from host_tools.runner import run_virtual
    from host_tools.studies.sweep_point import (  # the sweep's per-point wall-time limit
        _deadline,
        _PointTimeout,
        failure_text,
    )

    logging.getLogger("firmware.safety").setLevel(logging.ERROR)  # a fault is in the row, not on the console
    t0 = time.perf_counter()
    try:
        r = run_virtual(point_run_config(p), progress=_deadline(p.timeout_s))
        s = _write_summary(r, Path(p.profile_name).parent)
        row = _base_row(p)
        row.update(figures(p, r, s))
    except _PointTimeout:
        return design_error_row(p, "timeout", f"timeout: no result within {p.timeout_s:g} s",
                                time.perf_counter() - t0)
    except Exception as e:  # noqa: BLE001 - any failure of a point is its row, not the search's end
        return design_error_row(p, "error", failure_text(e), time.perf_counter() - t0)
    row.update({"status": "fault" if row["fault"] else "ok", "error": f"fault {row['fault']}" if row["fault"] else "",
                "sim_time_s": round(r.sim_time_s, 4), "wall_time_s": round(time.perf_counter() - t0, 3)})
    return row

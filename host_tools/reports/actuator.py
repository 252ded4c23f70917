"""The actuator design check of the walking scenario: what walking demands at the ankle against what the
AK60-6 + 6:1 gearbox + belt can deliver (continuous and peak), and the body mass where it stops keeping up.

Demand over one stride: torque = body mass x the normative ankle moment per kg (zero in swing, as the
walking load, hal/virtual/plant/walking.py); speed = the gait reference's angular velocity. Deliverable
torque at an ankle speed w: ``min(I x Kt N eta, (V - Ke w N) / R x Kt N eta)`` for I = the peak
(22.7 A) or rated (6.5 A, maker) current, or the firmware's control limit -- the current limit or the
back-EMF limit of the 24 V supply, whichever is lower. Power: mechanical ``|torque w|``, electrical
``0.75 I^2 R + Kt w N I`` for the motor current the torque needs (the rotor's torque times its speed plus the
q current's copper loss, hal/virtual/plant/thermal.py COPPER_LOSS_FACTOR on the line-to-line R).

"Keeps up to": the largest body mass whose demand torque stays within the deliverable torque at every
torque-bearing instant of the stride whose demanded speed is below the no-load speed. The instants at or above
it (the demand's speed does not scale with mass, and the motor gives no torque there at any current) bound no
mass: they are counted apart (``speed_envelope``), and the figure is None when no instant is left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware.control.reference import GaitReference
from hal.virtual.plant import PlantParams
from hal.virtual.plant.design import Design, belt_tension_per_amp_n
from hal.virtual.plant.thermal import COPPER_LOSS_FACTOR
from hal.virtual.plant.walking import WalkingLoad
from host_tools.outdir import save_figure

__all__ = ["DESIGN_POINT", "RATED_CURRENT_A", "Drive", "design_check", "plot_design_check"]

RATED_CURRENT_A = 6.5  # maker's rated current of the AK60-6 (shared/PROTOCOLS.md, section C)
DESIGN_POINT = (14.0, 55.0)  # N m and rpm at the ankle: the report's transmission design point
_RPM = 60.0 / (2.0 * math.pi)


@dataclass(frozen=True)
class Drive:
    """The motor + gearbox + belt as seen from the ankle."""

    nm_per_a: float  # ankle torque per motor ampere, Kt N eta
    ratio: float
    supply_v: float
    ke_v_s_per_rad: float
    resistance_ohm: float
    peak_current_a: float
    rated_current_a: float
    control_limit_a: float
    kt_nm_per_a: float  # motor side: the rotor converts Kt i w (Ke is the voltage constant)

    @classmethod
    def from_params(cls, p: PlantParams, control_limit_a: float, rated_current_a: float = RATED_CURRENT_A) -> Drive:
        """From the plant profile, the firmware's current limit and the motor's rated current."""
        return cls(p.output_torque_per_amp_nm, p.total_ratio, p.supply_voltage_v, p.ke_v_s_per_rad,
                   p.phase_resistance_ohm, p.peak_current_a, rated_current_a, control_limit_a, p.kt_nm_per_a)

    def torque_nm(self, speed_rad_s: np.ndarray | float, current_a: float) -> np.ndarray:
        """Deliverable ankle torque at the ankle speed with at most current_a in the motor."""
        w_motor = np.abs(np.asarray(speed_rad_s, dtype=float)) * self.ratio
        i_voltage = np.maximum((self.supply_v - self.ke_v_s_per_rad * w_motor) / self.resistance_ohm, 0.0)
        return np.minimum(current_a, i_voltage) * self.nm_per_a

    @property
    def no_load_speed_rad_s(self) -> float:
        """Ankle speed at which the back-EMF equals the supply."""
        return self.supply_v / self.ke_v_s_per_rad / self.ratio


def _demand(load: WalkingLoad, reference: GaitReference, mass_kg: float, points: int = 1000):
    pct = np.linspace(0.0, 100.0, points, endpoint=False)
    torque = np.array([load.moment_nm(x) for x in pct]) * (mass_kg / load.body_mass_kg)
    speed = np.array([reference.sample(x / 100.0 * load.stride_s)[1] for x in pct])
    return pct, torque, speed


def _one_mass(drive: Drive, load: WalkingLoad, reference: GaitReference, mass_kg: float) -> dict:
    _, torque, speed = _demand(load, reference, mass_kg)
    need_a = np.abs(torque) / drive.nm_per_a
    w_motor = np.abs(speed) * drive.ratio
    p_mech = np.abs(torque * speed)
    p_elec = COPPER_LOSS_FACTOR * need_a ** 2 * drive.resistance_ohm + drive.kt_nm_per_a * w_motor * need_a
    mag = np.abs(torque)
    return {
        "body_mass_kg": mass_kg,
        "peak_torque_nm": round(float(mag.max()), 2),
        "peak_speed_rpm": round(float(np.abs(speed).max() * _RPM), 1),
        "peak_mechanical_power_w": round(float(p_mech.max()), 1),
        "peak_electrical_power_w": round(float(p_elec.max()), 1),
        "peak_current_needed_a": round(float(need_a.max()), 2),
        "saturated_fraction_peak": round(float(np.mean(mag > drive.torque_nm(speed, drive.peak_current_a))), 4),
        "saturated_fraction_control_limit": round(
            float(np.mean(mag > drive.torque_nm(speed, drive.control_limit_a))), 4),
        "above_continuous_fraction": round(float(np.mean(mag > drive.torque_nm(speed, drive.rated_current_a))), 4),
    }


def _keeps_up_to_kg(drive: Drive, load: WalkingLoad, reference: GaitReference, current_a: float) -> float | None:
    """The largest body mass whose demand stays within the envelope at current_a over the instants the motor can
    reach (demand torque scales with mass, speed does not): the instants at or above the no-load speed bound no mass
    (no torque there at any current) and are counted apart (`_speed_envelope`). None when no torque-bearing
    instant is below the no-load speed."""
    _, torque, speed = _demand(load, reference, 1.0)
    per_kg = np.abs(torque)
    ok = (per_kg > 0) & (np.abs(speed) < drive.no_load_speed_rad_s)
    if not ok.any():
        return None
    return round(float(np.min(drive.torque_nm(speed[ok], current_a) / per_kg[ok])), 1)


def _speed_envelope(drive: Drive, load: WalkingLoad, reference: GaitReference) -> dict:
    """The instants whose demanded ankle speed is at or above the no-load speed: shares of the stride and of its
    torque-bearing (stance) instants, and the demand's peak speed against the no-load speed."""
    _, torque, speed = _demand(load, reference, 1.0)
    above = np.abs(speed) >= drive.no_load_speed_rad_s
    stance = np.abs(torque) > 0
    return {"no_load_speed_rpm": round(drive.no_load_speed_rad_s * _RPM, 1),
            "peak_demand_speed_rpm": round(float(np.abs(speed).max() * _RPM), 1),
            "stride_fraction_above_no_load": round(float(above.mean()), 4),
            "stance_fraction_above_no_load": round(float(above[stance].mean()), 4) if stance.any() else 0.0}


def design_check(params: PlantParams, control_limit_a: float, load: WalkingLoad, reference: GaitReference,
                 masses_kg: tuple[float, ...] = (20.0, 40.0, 60.0, 80.0, 100.0),
                 rated_current_a: float = RATED_CURRENT_A) -> dict:
    """The check for the load's body mass and a table over masses_kg (JSON-able)."""
    drive = Drive.from_params(params, control_limit_a, rated_current_a)
    zero = np.zeros(1)
    return {
        "drive": {"ankle_nm_per_motor_a": round(drive.nm_per_a, 4), "ratio": round(drive.ratio, 3),
                  "peak_torque_nm": round(float(drive.torque_nm(zero, drive.peak_current_a)[0]), 2),
                  "continuous_torque_nm": round(float(drive.torque_nm(zero, drive.rated_current_a)[0]), 2),
                  "control_limit_torque_nm": round(float(drive.torque_nm(zero, control_limit_a)[0]), 2),
                  "no_load_speed_rpm": round(drive.no_load_speed_rad_s * _RPM, 1),
                  "peak_current_a": drive.peak_current_a, "rated_current_a": drive.rated_current_a,
                  "control_limit_a": control_limit_a},
        "design_point": {"torque_nm": DESIGN_POINT[0], "speed_rpm": DESIGN_POINT[1]},
        "demand": _one_mass(drive, load, reference, load.body_mass_kg),
        "keeps_up_to_body_mass_kg": {
            "peak": _keeps_up_to_kg(drive, load, reference, drive.peak_current_a),
            "continuous": _keeps_up_to_kg(drive, load, reference, drive.rated_current_a),
            "control_limit": _keeps_up_to_kg(drive, load, reference, control_limit_a)},
        "speed_envelope": _speed_envelope(drive, load, reference),
        "by_body_mass": [_one_mass(drive, load, reference, m) for m in masses_kg],
    }


def plot_design_check(path, check: dict, params: PlantParams, load: WalkingLoad, reference: GaitReference) -> None:
    """Demand (|torque| against |speed| over the stride) on the deliverable envelope, with the design point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = check["drive"]
    drive = Drive.from_params(params, d["control_limit_a"], d["rated_current_a"])
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    w = np.linspace(0.0, drive.no_load_speed_rad_s, 300)
    for current, label, style in ((drive.peak_current_a, f"peak ({drive.peak_current_a:g} A)", "-"),
                                  (drive.control_limit_a, f"firmware limit ({drive.control_limit_a:g} A)", "-."),
                                  (drive.rated_current_a, f"continuous ({drive.rated_current_a:g} A)", "--")):
        ax.plot(w * _RPM, drive.torque_nm(w, current), "k" + style, label=label)
    for row in check["by_body_mass"]:
        m = row["body_mass_kg"]
        _, torque, speed = _demand(load, reference, m)
        strong = m == load.body_mass_kg
        ax.plot(np.abs(speed) * _RPM, np.abs(torque), ".", ms=2 if strong else 1, alpha=1.0 if strong else 0.35,
                label=f"walking demand, {m:g} kg")
    if all(row["body_mass_kg"] != load.body_mass_kg for row in check["by_body_mass"]):
        _, torque, speed = _demand(load, reference, load.body_mass_kg)
        ax.plot(np.abs(speed) * _RPM, np.abs(torque), ".", ms=2, label=f"walking demand, {load.body_mass_kg:g} kg")
    ax.plot([DESIGN_POINT[1]], [DESIGN_POINT[0]], "r*", ms=14, label="report's design point (14 N·m, 55 rpm)")
    ax.set_xlabel("ankle speed |ω| (rpm)")
    ax.set_ylabel("ankle torque |τ| (N·m)")
    ax.set_title("Actuator envelope (AK60-6, 6:1, belt 4.67:1, 24 V) and walking demand")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def moment_share(t_s: np.ndarray, delivered_nm: np.ndarray, demand_nm: np.ndarray, stance: np.ndarray) -> float:
    """The share of the stance demand delivered: each stance sample's delivered moment counted in the demand's
    direction and capped at the demand (an overshoot at one instant does not make up for a shortfall at another),
    over the whole demand; NaN without stance samples. The design check's motor share and the design search's
    actuator share (motor + parallel spring, docs/design.md) are this one figure of different deliveries.

    >>> t = np.arange(4.0)
    >>> moment_share(t, np.array([1.0, 3.0, -1.0, 0.0]), np.array([2.0, 2.0, 2.0, 5.0]), np.ones(4, bool)) * 11
    3.0
    """
    if not stance.any():
        return math.nan
    d = demand_nm[stance]
    got = np.clip(delivered_nm[stance] * np.sign(d), 0.0, np.abs(d))
    total = float(np.sum(np.abs(d)))
    return float(np.sum(got)) / total if total > 0 else math.nan


def stance_moment_share(t_s: np.ndarray, current_meas_a: np.ndarray, nm_per_a: float, load: WalkingLoad,
                        start_s: float, end_s: float) -> dict:
    """How much of the stance moment the motor gave, from the current it reported (a bench figure): its
    plantarflexing moment (Kt N eta x current) against the demand, as ``moment_share`` counts it, and the ratio of
    the peaks (not capped). A parallel spring's part is not counted here (the design search adds it)."""
    t = np.asarray(t_s, dtype=float)
    sel = (t >= start_s) & (t < end_s)
    pct = ((t[sel] - start_s) / load.stride_s % 1.0) * 100.0
    demand = np.array([load.moment_nm(float(x)) for x in pct])
    stance = demand > 0.0
    if not stance.any():
        return {"motor_stance_moment_share": None, "motor_stance_peak_moment_share": None}
    given = -nm_per_a * np.asarray(current_meas_a, dtype=float)[sel]  # plantarflexing positive
    return {"motor_stance_moment_share": round(moment_share(t[sel], given, demand, stance), 4),
            "motor_stance_peak_moment_share": round(float(given[stance].max() / demand[stance].max()), 4)}


def belt_check(params: PlantParams, spec: Design | None, control_limit_a: float, peak_a: float,
               run_peak_a: float | None) -> dict:
    """The belt's effective tension at the run's peak current, the firmware limit and peak current, and its rating
    (a design profile's belt; None otherwise)."""
    per_a = belt_tension_per_amp_n(params)
    return {"n_per_motor_a": round(per_a, 1),
            "at_run_peak_n": None if run_peak_a is None else round(per_a * run_peak_a, 0),
            "at_control_limit_n": round(per_a * control_limit_a, 0), "at_peak_current_n": round(per_a * peak_a, 0),
            "belt": None if spec is None else f"{spec.belt_pitch_mm:g} mm pitch, {spec.width_mm:g} mm wide",
            "rated_working_tension_n": None if spec is None else round(spec.rated_tension_n, 1),
            "within_rating": None if spec is None or run_peak_a is None else per_a * run_peak_a <= spec.rated_tension_n}


def walk_outputs(r, out, t_s: np.ndarray, current_cmd_a: np.ndarray,
                 current_meas_a: np.ndarray | None = None) -> tuple[dict, list[str]]:
    """The design check of a walking run (RunResult r, directory out, the run's command and measured current over
    time): summary entry (with the run's measured saturation and stance moment), plot, report lines."""
    from host_tools.walk import population_for, walking_load

    cfg, fw = r.config, r.firmware
    params = cfg.bench_setup()[0]["plant_params"]  # the plant the bench ran (a design's, a drawn one, --plant)
    load = walking_load(cfg.body_mass_kg, fw.config.stride_s, cfg.moment_csv, cfg.speed, cfg.population)
    check = design_check(params, fw.config.current_limit_a, load, fw.reference,
                         rated_current_a=fw.config.motor.rated_current_a)
    start = r.gait_start_s if r.gait_start_s is not None else math.inf
    end = fw.supervisor.tripped_at_s if fw.supervisor.tripped_at_s is not None else math.inf
    t_s, current_cmd_a = np.asarray(t_s, dtype=float), np.asarray(current_cmd_a, dtype=float)
    sel = (t_s >= start) & (t_s < end)
    command = np.abs(current_cmd_a[sel])
    at_limit = command >= fw.config.current_limit_a * (1 - 1e-9)  # clamped by the firmware
    near_limit = command >= 0.95 * fw.config.current_limit_a  # also a controller saturating inside (cascade: its
    # velocity loop at +-1 plus a feed-forward of the other sign stays just below the clamp)
    walked_s = round(float(t_s[sel][-1] - t_s[sel][0]), 3) if sel.any() else 0.0
    check["run"] = {"controller": fw.config.controller, "seconds_walked": walked_s,
                    "saturated_fraction": round(float(at_limit.mean()), 4) if sel.any() else None,
                    "near_limit_fraction": round(float(near_limit.mean()), 4) if sel.any() else None,
                    "heel_strikes_sensed": fw.load_detector.heel_strikes, "toe_offs_sensed": fw.load_detector.toe_offs}
    population = population_for(cfg.body_mass_kg, cfg.population)
    check["gait_data"] = {"population": population, "speed": cfg.speed or "free",
                          "moment": str(cfg.moment_csv) if cfg.moment_csv is not None else
                          "Schwartz et al. 2008 (children)" + (", adult-shaped (assumed 1.5 N·m/kg free-speed peak, "
                                                               "host_tools/walk.py)" if population == "adult" else "")}
    run_peak = (float(np.abs(np.asarray(current_meas_a, dtype=float)[sel]).max())
                if current_meas_a is not None and sel.any() else None)
    # a drawn or --plant plant keeps the design's belt only when it is the design's plant (cfg.plant_file unset)
    check["belt"] = belt_check(params, cfg.design if cfg.plant_file is None else None, fw.config.current_limit_a,
                               check["drive"]["peak_current_a"], run_peak)
    if current_meas_a is not None and math.isfinite(start):
        ff = fw.config.feedforward_params
        check["run"].update(stance_moment_share(t_s, current_meas_a, ff.torque_constant_nm_per_a * ff.gear_ratio
                                                * ff.efficiency, load, start, end))
    plot_design_check(out / "actuator.png", check, params, load, fw.reference)
    d, dm, k, se = check["drive"], check["demand"], check["keeps_up_to_body_mass_kg"], check["speed_envelope"]
    beyond = (f" (not counting the {se['stance_fraction_above_no_load']} of the stance that asks for the no-load "
              f"speed {se['no_load_speed_rpm']} rpm or more, up to {se['peak_demand_speed_rpm']} rpm: no torque "
              "there at any mass)" if se["stance_fraction_above_no_load"] > 0 else "")
    b = check["belt"]
    rated = (f" against {b['rated_working_tension_n']} N rated ({b['belt']}, rating: SDP/SI Table 3, "
             "hal/virtual/plant/transmission.py)" if b["rated_working_tension_n"] is not None else
             " (no design profile: the belt's pitch and width, hence its rating, unknown)")
    g = check["gait_data"]
    lines = ["", f"## Actuator design check (walking, {cfg.body_mass_kg:g} kg)", "",
             f"Gait data: {g['population']}, {g['speed']} speed; moment: {g['moment']}.", "",
             f"Belt tension (backdriven, the larger direction): {b['n_per_motor_a']} N per motor A; "
             f"{b['at_run_peak_n']} N at this run's peak reported current, {b['at_control_limit_n']} N at the "
             f"firmware limit, {b['at_peak_current_n']} N at peak current{rated}.", "",
             f"Deliverable at the ankle: peak {d['peak_torque_nm']} N·m ({d['peak_current_a']} A), continuous "
             f"{d['continuous_torque_nm']} N·m ({d['rated_current_a']} A), firmware limit "
             f"{d['control_limit_torque_nm']} N·m ({d['control_limit_a']} A), no-load speed "
             f"{d['no_load_speed_rpm']} rpm; "
             f"the report's design point {DESIGN_POINT[0]} N·m at {DESIGN_POINT[1]} rpm. Demand: peak "
             f"{dm['peak_torque_nm']} N·m, {dm['peak_speed_rpm']} rpm, mechanical "
             f"{dm['peak_mechanical_power_w']} W, "
             f"electrical {dm['peak_electrical_power_w']} W. It keeps up to {k['peak']} kg at peak current, "
             f"{k['control_limit']} kg at the firmware limit, {k['continuous']} kg continuously{beyond}. In this run "
             f"the "
             f"command sat at the current limit {check['run']['saturated_fraction']} (within 5 % of it "
             f"{check['run']['near_limit_fraction']}) of the "
             f"{check['run']['seconds_walked']} s walked (until a fault, if any). Plot: `actuator.png`.", "",
             "| body mass kg | peak torque N·m | peak speed rpm | peak mech. W | peak elec. W | stride saturated "
             "(peak) | (firmware limit) | above continuous |", "|---|---|---|---|---|---|---|---|"]
    for row in check["by_body_mass"]:
        lines.append(f"| {row['body_mass_kg']:g} | {row['peak_torque_nm']} | {row['peak_speed_rpm']} | "
                     f"{row['peak_mechanical_power_w']} | {row['peak_electrical_power_w']} | "
                     f"{row['saturated_fraction_peak']} | {row['saturated_fraction_control_limit']} | "
                     f"{row['above_continuous_fraction']} |")
    return check, lines

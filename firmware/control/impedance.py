"""Impedance control with a gait state machine: piecewise stiffness, damping and equilibrium angle per phase.

The standard approach for powered ankles: the ankle behaves as a spring-damper,
``torque = -k (theta - theta_eq) - b theta_dot``, whose parameters change with the phase of the gait,
and the phase changes on events the firmware senses. Followed:

- F. Sup, A. Bohara, M. Goldfarb, "Design and control of a powered transfemoral prosthesis",
  Int. J. Robotics Research 27(2):263-273, 2008: the finite-state impedance law, four phases of the
  stride, transitions on sensed angle, velocity and load.
- S. K. Au, J. Weber, H. Herr, "Powered ankle-foot prosthesis improves walking metabolic economy",
  IEEE Trans. Robotics 25(1):51-66, 2009: the ankle's stance sub-phases (controlled plantarflexion,
  controlled dorsiflexion, powered plantarflexion) and swing, entered on heel strike, foot flat, an
  ankle moment threshold and toe off.

Phases and the events that switch them (``stance``/``load_torque_nm`` from the firmware's load detector,
firmware/control/gait_events.py):

- SWING -> EARLY_STANCE on heel strike (``obs.stance`` becomes true);
- EARLY_STANCE (controlled plantarflexion) -> MID_STANCE (controlled dorsiflexion) when the ankle starts
  to dorsiflex (velocity above ``flat_velocity_rad_s``: the foot is flat, the shank rolls over it);
- MID_STANCE -> LATE_STANCE (powered plantarflexion) when the sensed ankle moment exceeds
  ``push_moment_nm_per_kg`` times the body mass, or the angle passes ``push_angle_deg``;
- any stance phase -> SWING on toe off (``obs.stance`` becomes false).

With the ground sensors fitted and healthy (``obs.ground_sensors_ok``: the load cell and the heel/toe FSRs,
firmware/control/ground_events.py), ``obs.stance`` comes from them, EARLY -> MID is foot flat (the toe FSR
comes on) and MID -> LATE is heel off (the heel FSR goes off) or the load cell's sagittal moment passing
the push threshold; otherwise the transitions above.

Stance parameters are per kg of body mass, from the quasi-stiffness of the normative ankle
(firmware/data/ankle_normative.csv, the moment-angle slope of each sub-phase): early stance
2 N m/rad/kg about -2 deg; mid stance 5.2 N m/rad/kg about -1 deg; late stance 2.65 N m/rad/kg about
-15 deg. In swing the equilibrium is the gait reference (a moving equilibrium, with the foot's weight
compensated), so the suspended foot follows the gait as with the cascade; with a one-sided parallel spring the swing
equilibrium stops at the spring's engagement (the motor does not load the spring in swing only to take its energy
back). With a parallel spring in the profile's [feedforward], the spring's moment at the measured angle is taken off
the law's moment: the motor gives the rest. Compiled (setup.py).
"""

from __future__ import annotations

import math
from typing import Any

from firmware.control.observation import Observation
from firmware.control.pid import backdriven_current_a, parallel_spring_torque_nm
from firmware.control.validation import check_range

__all__ = ["PHASES", "Impedance", "ImpedanceParams", "impedance_from_config"]

SWING, EARLY_STANCE, MID_STANCE, LATE_STANCE = 0, 1, 2, 3
PHASES = ("SWING", "EARLY_STANCE", "MID_STANCE", "LATE_STANCE")

# name: (default, low, high, unit) -- the [controller] parameters of `impedance`
DEFAULTS: dict[str, tuple[float, float, float, str]] = {
    "body_mass_kg": (80.0, 20.0, 200.0, "kg"),
    "early_k_nm_per_rad_kg": (2.0, 0.0, 20.0, "N m/rad/kg"),
    "early_b_nm_s_per_rad_kg": (0.01, 0.0, 1.0, "N m s/rad/kg"),
    "early_eq_deg": (-2.0, -30.0, 30.0, "deg"),
    "mid_k_nm_per_rad_kg": (5.2, 0.0, 20.0, "N m/rad/kg"),
    "mid_b_nm_s_per_rad_kg": (0.01, 0.0, 1.0, "N m s/rad/kg"),
    "mid_eq_deg": (-1.0, -30.0, 30.0, "deg"),
    "late_k_nm_per_rad_kg": (2.65, 0.0, 20.0, "N m/rad/kg"),
    "late_b_nm_s_per_rad_kg": (0.005, 0.0, 1.0, "N m s/rad/kg"),
    "late_eq_deg": (-15.0, -30.0, 30.0, "deg"),
    "swing_k_nm_per_rad": (100.0, 0.0, 1000.0, "N m/rad"),
    "swing_b_nm_s_per_rad": (2.0, 0.0, 100.0, "N m s/rad"),
    "flat_velocity_rad_s": (0.05, 0.0, 10.0, "rad/s"),
    "push_moment_nm_per_kg": (0.9, 0.0, 5.0, "N m/kg"),
    "push_angle_deg": (10.0, -30.0, 40.0, "deg"),
}


class ImpedanceParams:
    """The checked parameters (see DEFAULTS) and the drive constants the controller needs."""

    def __init__(self, values: dict[str, Any], nm_per_a: float, gravity_moment_nm: float, com_angle_rad: float,
                 inertia_kg_m2: float, spring: tuple[float, float, bool] = (0.0, 0.0, False),
                 backdriven_share: float = 1.0) -> None:
        """ValueError naming an unknown key or a value out of its range."""
        unknown = sorted(set(values) - set(DEFAULTS))
        if unknown:
            raise ValueError(f"controller impedance has no parameter {unknown[0]!r}: known {sorted(DEFAULTS)}")
        v = {}
        for name, (default, lo, hi, unit) in DEFAULTS.items():
            v[name] = check_range(f"[controller] {name}", values.get(name, default), lo, hi, unit=unit)
        self.values = v
        self.nm_per_a = nm_per_a
        self.gravity_moment_nm = gravity_moment_nm
        self.com_angle_rad = com_angle_rad
        self.inertia_kg_m2 = inertia_kg_m2
        self.spring = spring  # the parallel spring: (stiffness N m/rad, engagement rad, two-sided)
        self.backdriven_share = backdriven_share  # FeedforwardParams.backdriven_share


class Impedance:
    """Finite-state impedance controller of the ankle (module docstring); publishes its phase and law."""

    def __init__(self, p: ImpedanceParams) -> None:
        """Start in SWING."""
        v = p.values
        m = v["body_mass_kg"]
        d = math.radians
        # per phase: stiffness N m/rad, damping N m s/rad, equilibrium rad (swing: the reference)
        self.k = [v["swing_k_nm_per_rad"], v["early_k_nm_per_rad_kg"] * m, v["mid_k_nm_per_rad_kg"] * m,
                  v["late_k_nm_per_rad_kg"] * m]
        self.b = [v["swing_b_nm_s_per_rad"], v["early_b_nm_s_per_rad_kg"] * m, v["mid_b_nm_s_per_rad_kg"] * m,
                  v["late_b_nm_s_per_rad_kg"] * m]
        self.eq = [0.0, d(v["early_eq_deg"]), d(v["mid_eq_deg"]), d(v["late_eq_deg"])]
        self.flat_velocity_rad_s = v["flat_velocity_rad_s"]
        self.push_moment_nm = v["push_moment_nm_per_kg"] * m
        self.push_angle_rad = d(v["push_angle_deg"])
        self.nm_per_a = p.nm_per_a
        self.gravity_moment_nm = p.gravity_moment_nm
        self.com_angle_rad = p.com_angle_rad
        self.inertia_kg_m2 = p.inertia_kg_m2
        self.spring_k, self.spring_engage_rad, self.spring_two_sided = p.spring
        self.backdriven_share = p.backdriven_share
        self.phase = SWING
        self.transitions = 0
        self.published: dict[str, float] = {"phase": 0.0, "stiffness_nm_per_rad": 0.0, "equilibrium_deg": 0.0,
                                            "torque_nm": 0.0}

    def reset(self) -> None:
        """Back to SWING (the foot unloaded)."""
        self.phase = SWING

    def _next_phase(self, obs: Observation) -> int:
        """The phase after this period's events."""
        phase = self.phase
        if phase == SWING:
            return EARLY_STANCE if obs.stance else SWING
        if not obs.stance:
            return SWING  # toe off
        if obs.ground_sensors_ok:  # the foot's own sensors: foot flat when the toes touch, push-off at heel off
            if phase == EARLY_STANCE and obs.toe_contact:
                return MID_STANCE
            if phase == MID_STANCE and (not obs.heel_contact or obs.sagittal_moment_nm > self.push_moment_nm):
                return LATE_STANCE
            return phase
        if phase == EARLY_STANCE and obs.velocity_rad_s > self.flat_velocity_rad_s:
            return MID_STANCE
        if phase == MID_STANCE and (obs.load_torque_nm > self.push_moment_nm or obs.angle_rad > self.push_angle_rad):
            return LATE_STANCE
        return phase

    def update(self, obs: Observation) -> float:
        """The motor current in A: the phase's spring-damper, plus the foot's weight and inertia in swing."""
        phase = self._next_phase(obs)
        if phase != self.phase:
            self.phase = phase
            self.transitions += 1
        k, b = self.k[phase], self.b[phase]
        if phase == SWING:
            eq = obs.reference_rad
            eq_velocity = obs.reference_velocity_rad_s
            eq_acceleration = obs.reference_acceleration_rad_s2
            if self.spring_k != 0.0 and not self.spring_two_sided and eq > self.spring_engage_rad:
                # not into a one-sided spring in swing: the motor would load it and take its energy back
                eq, eq_velocity, eq_acceleration = self.spring_engage_rad, 0.0, 0.0
            torque = (-k * (obs.angle_rad - eq) - b * (obs.velocity_rad_s - eq_velocity)
                      + self.gravity_moment_nm * math.sin(eq + self.com_angle_rad)
                      + self.inertia_kg_m2 * eq_acceleration)
        else:
            eq = self.eq[phase]
            torque = -k * (obs.angle_rad - eq) - b * obs.velocity_rad_s
        pub = self.published
        pub["phase"] = float(phase)
        pub["stiffness_nm_per_rad"] = k
        pub["equilibrium_deg"] = math.degrees(eq)
        pub["torque_nm"] = torque
        if self.spring_k != 0.0:  # a parallel spring gives part of the law's moment: the motor gives the rest
            torque -= parallel_spring_torque_nm(self.spring_k, self.spring_engage_rad, self.spring_two_sided,
                                                obs.angle_rad)
        return backdriven_current_a(torque / self.nm_per_a, obs.velocity_rad_s, self.backdriven_share)


def impedance_from_config(config: Any, params: dict[str, Any]) -> Impedance:
    """The impedance controller with the profile's [controller] parameters and the firmware's drive model."""
    ff = config.feedforward_params
    nm_per_a = ff.torque_constant_nm_per_a * ff.gear_ratio * ff.efficiency
    spring = (ff.parallel_stiffness_nm_per_rad, math.radians(ff.parallel_engage_deg), ff.parallel_two_sided)
    return Impedance(ImpedanceParams(params, nm_per_a, ff.mass_kg * ff.gravity_m_s2 * ff.lever_m, config.com_angle_rad,
                                     ff.inertia_kg_m2, spring, ff.backdriven_share))

"""An ankle impedance state machine over the gait phases, written against opensourceleg's API only (no pafp import):
the way OSL users write them (their tutorials' finite-state impedance control), here for the ankle alone.

Four phases, each a joint impedance ``tau = k (theta_eq - theta) - b theta_dot`` that the actuator's drive runs:

============  ============================  ===========================================================
phase         k, b, theta_eq                leaves when
============  ============================  ===========================================================
early stance  150 N m/rad, 3, -3 deg        dorsiflexed past 10 deg, 0.38 s after heel strike -> late
late stance   250 N m/rad, 2, -20 deg       the load cell unloads (|fz| < 60 N) -> early swing
early swing   120 N m/rad, 2, -5 deg        0.08 s in swing -> late swing
late swing    120 N m/rad, 2, -2 deg        the load cell loads (|fz| > 120 N) -> early stance
============  ============================  ===========================================================

The gains are this example's own choice (tuned by hand on the virtual leg against the normative ankle curve, see
docs/osl.md), not values from a publication. Sensors: the load cell's axial force and the joint encoder.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from opensourceleg.actuators.base import CONTROL_MODES

__all__ = ["PHASES", "AnkleStateMachine", "Phase"]


@dataclass(frozen=True)
class Phase:
    """One phase's joint impedance: stiffness N m/rad, damping N m s/rad, equilibrium angle deg."""

    k: float
    b: float
    theta_eq_deg: float


PHASES = {
    "early_stance": Phase(150.0, 3.0, -3.0),
    "late_stance": Phase(250.0, 2.0, -20.0),
    "early_swing": Phase(120.0, 2.0, -5.0),
    "late_swing": Phase(120.0, 2.0, -2.0),
}
LATE_STANCE_DEG = 10.0
LATE_STANCE_AFTER_S = 0.38
UNLOADED_N = 60.0
LOADED_N = 120.0
EARLY_SWING_S = 0.08


class AnkleStateMachine:
    """The state machine on an OSL actuator, joint encoder and load cell (anything with their interfaces)."""

    def __init__(self, actuator: Any, encoder: Any, loadcell: Any) -> None:
        """Start in late swing (the foot in the air), the actuator in impedance mode."""
        self.actuator, self.encoder, self.loadcell = actuator, encoder, loadcell
        self.phase = "late_swing"
        self.time_in_phase_s = 0.0
        self.transitions = 0
        actuator.set_control_mode(CONTROL_MODES.IMPEDANCE)
        self._apply()

    def _apply(self) -> None:
        p = PHASES[self.phase]
        self.actuator.set_output_impedance(k=p.k, b=p.b)
        self.actuator.set_output_position(math.radians(p.theta_eq_deg))

    def step(self, dt_s: float) -> str:
        """One loop, after the devices' update(): change phase if its condition holds; return the phase."""
        force = abs(self.loadcell.fz)
        angle_deg = math.degrees(self.encoder.position)
        self.time_in_phase_s += dt_s
        nxt = {"early_stance": angle_deg > LATE_STANCE_DEG and self.time_in_phase_s > LATE_STANCE_AFTER_S,
               "late_stance": force < UNLOADED_N,
               "early_swing": self.time_in_phase_s > EARLY_SWING_S,
               "late_swing": force > LOADED_N}[self.phase]
        if nxt:
            order = list(PHASES)
            self.phase = order[(order.index(self.phase) + 1) % len(order)]
            self.time_in_phase_s = 0.0
            self.transitions += 1
        self._apply()
        return self.phase

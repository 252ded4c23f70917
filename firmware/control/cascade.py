"""The report's cascade (position PID -> velocity PI -> current, plus feed-forward) behind the controller
interface: `update(obs)` returns the motor current in amperes.

Compiled (setup.py): the default controller runs every control period.
"""

from __future__ import annotations

from firmware.control.gains import PidGains
from firmware.control.observation import Observation
from firmware.control.pid import CascadeController, Feedforward

__all__ = ["Cascade"]


class Cascade:
    """`CascadeController` fed from an `Observation`; the feed-forward (if given) on the reference."""

    def __init__(self, position_gains: PidGains, velocity_gains: PidGains, ts_s: float, current_limit_a: float,
                 velocity_limit_rad_s: float, feedforward: Feedforward | None, com_angle_rad: float) -> None:
        """Build both loops (see CascadeController) and keep the feed-forward of the foot model."""
        self.loops = CascadeController(position_gains, velocity_gains, ts_s, current_limit_a, velocity_limit_rad_s)
        self.feedforward = feedforward
        self.com_angle_rad = com_angle_rad

    def reset(self) -> None:
        """Clear both loops; the next update starts bumplessly."""
        self.loops.reset()

    def update(self, obs: Observation) -> float:
        """The motor current command in A for this period (within +-current_limit_a)."""
        feedforward = self.feedforward
        ref = obs.reference_rad
        ff = 0.0
        if feedforward is not None:  # the foot's model at the reference, less what a parallel spring gives there
            ff = feedforward.by_direction(feedforward.current_a(ref + self.com_angle_rad,
                                                                obs.reference_acceleration_rad_s2)
                                          - feedforward.spring_current_a(ref), obs.reference_velocity_rad_s)
        return self.loops.update(ref, obs.reference_velocity_rad_s, obs.angle_rad, obs.velocity_rad_s, ff)

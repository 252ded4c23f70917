"""Quadrature encoder driver: the timer's CNT, read as the C firmware would, to angle and velocity."""

from __future__ import annotations

from firmware.control.estimation import VelocityEstimator
from hal.interfaces import EncoderTimer

__all__ = ["EncoderDriver"]


class EncoderDriver:
    """Samples CNT each period; wrap-safe deltas (`(int16_t)(cnt - prev)`), 4000 counts/rev."""

    def __init__(self, timer: EncoderTimer, ts_s: float, counts_per_rev: int = 4000,
                 velocity_cutoff_hz: float = 80.0, direction: int = 1) -> None:
        """Bind the timer; the angle is 0 where the output pulley was at the first sample."""
        self.timer = timer
        self.estimator = VelocityEstimator(
            ts_s, velocity_cutoff_hz=velocity_cutoff_hz, counts_per_rev=counts_per_rev,
            counter_modulus=timer.arr + 1, direction=direction,
        )
        self.angle_rad = 0.0
        self.velocity_rad_s = 0.0

    def sample(self) -> tuple[float, float]:
        """Read CNT now; return (angle_rad, velocity_rad_s)."""
        self.angle_rad, self.velocity_rad_s = self.estimator.update(self.timer.cnt())
        return self.angle_rad, self.velocity_rad_s

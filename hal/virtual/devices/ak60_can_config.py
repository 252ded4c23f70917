"""The CAN side of the AK60-6 over CAN: driver id, mode, status rate, MIT ranges.

Interpreted on purpose (docs/compiled.md, "Values checked as given").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from protocol import can_mit, can_servo

__all__ = ["MODES", "Ak60CanConfig"]

MODES = ("servo", "mit")


@dataclass(frozen=True)
class Ak60CanConfig:
    """The CAN side: driver id, mode, status rate (servo mode), the model's MIT ranges."""

    driver_id: int = 1
    mode: str = "servo"
    status_period_s: float = 0.002  # 500 Hz: the drive's highest upload rate (1..500 Hz, set in the maker's tool)
    limits: can_mit.MitLimits = can_mit.AK60_6

    def __post_init__(self) -> None:
        """Check the id, the mode and the status period."""
        if isinstance(self.driver_id, bool) or not isinstance(self.driver_id, int) or not 0 <= self.driver_id <= 127:
            raise ValueError(f"driver_id {self.driver_id!r} out of range: an int in 0..127")
        if self.mode not in MODES:
            raise ValueError(f"CAN mode {self.mode!r} invalid: one of {MODES}")
        lo, hi = 1.0 / can_servo.STATUS_HZ_MAX, 1.0 / can_servo.STATUS_HZ_MIN
        if not (math.isfinite(self.status_period_s) and lo <= self.status_period_s <= hi):
            raise ValueError(f"status_period_s {self.status_period_s!r} out of range [{lo}, {hi}] s (the drive's "
                             f"{can_servo.STATUS_HZ_MIN}..{can_servo.STATUS_HZ_MAX} Hz, manual 5.2.1)")

"""The safety supervisor's thresholds as given in a profile.

Interpreted on purpose (docs/compiled.md, "Values checked as given"); the compiled
:class:`~firmware.safety.Supervisor` reads them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from firmware.control.validation import is_number

__all__ = ["SafetyLimits"]


@dataclass(frozen=True)
class SafetyLimits:
    """Thresholds of the supervisor (SI units); defaults follow the firmware's requirements."""

    angle_min_rad: float = math.radians(-33.0)
    angle_max_rad: float = math.radians(38.0)
    current_limit_a: float = 20.0
    motor_timeout_s: float = 0.020
    command_timeout_s: float = 0.020
    imu_timeout_s: float = 0.050
    disagreement_rad: float = math.radians(6.0)
    deadline_miss_streak: int = 3
    startup_grace_s: float = 0.5
    brake_delay_s: float = 0.010
    brake_current_a: float = 2.0

    def __post_init__(self) -> None:
        """Reject limits that cannot describe a working supervisor."""
        if not self.angle_min_rad < self.angle_max_rad:
            raise ValueError(
                f"angle limits ({self.angle_min_rad}, {self.angle_max_rad}) rad: min must be below max"
            )
        for name in ("current_limit_a", "motor_timeout_s", "command_timeout_s", "imu_timeout_s", "disagreement_rad",
                     "startup_grace_s", "brake_current_a"):
            value = getattr(self, name)
            if not (is_number(value) and value > 0):
                raise ValueError(f"{name} {value!r} out of range: a finite number > 0")
        if not 0 <= self.brake_delay_s <= 1.0:
            raise ValueError(f"brake_delay_s {self.brake_delay_s!r} out of range: 0..1 s")
        if self.deadline_miss_streak < 1:
            raise ValueError(f"deadline_miss_streak {self.deadline_miss_streak!r} out of range: >= 1")

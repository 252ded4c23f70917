"""The motor's figures the firmware follows: its limits' hardware bounds and its drivers' scalings.

A profile's ``[motor]`` table may state them beside ``link`` and ``can_id`` (a design profile does:
host_tools/design_profile.py writes them from the motor catalogue); without them they are the AK60-6's,
the report's motor. The firmware reads only this, never the catalogue (docs/design.md, "How the firmware
follows the motor"). Interpreted on purpose (docs/compiled.md, "Values checked as given").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from firmware.control.validation import check_int_range, check_range

__all__ = ["RATING_KEYS", "MotorRatings"]


@dataclass(frozen=True)
class MotorRatings:
    """One motor's ratings (output side after its planetary, SI); the defaults are the AK60-6's."""

    model: str = "ak60_6"  # the catalogue name it came from (profiles/motors/), for the reader
    peak_current_a: float = 22.7  # report Table B2; maker 22.7 A
    rated_current_a: float = 6.5  # maker, PROTOCOLS.md section C
    torque_constant_nm_per_a: float = 0.078  # Kt, motor side (report Table B2)
    gear_ratio: float = 6.0  # the actuator's planetary (maker 6:1)
    pole_pairs: int = 14  # maker: ERPM = 14 x rotor rpm
    no_load_speed_rpm: float = 560.0  # at the actuator's output, at its supply (maker, PROTOCOLS.md section C)
    mit_p_max_rad: float = 12.5  # MIT mode's field ranges (PROTOCOLS.md G; TMotorCANControl MIT_Params)
    mit_v_max_rad_s: float = 50.0
    mit_t_max_nm: float = 15.0

    def __post_init__(self) -> None:
        """Check each figure is a plausible motor's (the catalogue's plausibility ranges)."""
        if not isinstance(self.model, str) or not self.model:
            raise ValueError(f"model = {self.model!r} is not allowed: a motor's name")
        check_range("peak_current_a", self.peak_current_a, 0.1, 500.0, unit="A")
        check_range("rated_current_a", self.rated_current_a, 0.1, self.peak_current_a,
                    unit="A (at most peak_current_a)")
        check_range("torque_constant_nm_per_a", self.torque_constant_nm_per_a, 0.005, 2.0, unit="N m/A")
        check_range("gear_ratio", self.gear_ratio, 1.0, 200.0)
        check_int_range("pole_pairs", self.pole_pairs, 1, 60)
        check_range("no_load_speed_rpm", self.no_load_speed_rpm, 1.0, 10000.0, unit="rpm")
        check_range("mit_p_max_rad", self.mit_p_max_rad, 1.0, 1000.0, unit="rad")
        check_range("mit_v_max_rad_s", self.mit_v_max_rad_s, 1.0, 1000.0, unit="rad/s")
        check_range("mit_t_max_nm", self.mit_t_max_nm, 0.5, 1000.0, unit="N m")

    @property
    def output_nm_per_a(self) -> float:
        """Torque at the actuator's output per q ampere, Kt x planetary (no loss): MIT mode's torque scaling."""
        return self.torque_constant_nm_per_a * self.gear_ratio

    @property
    def erpm_per_output_rad_s(self) -> float:
        """Electrical rpm per rad/s at the actuator's output: 60 / (2 pi) x planetary x pole pairs."""
        return 60.0 / (2.0 * math.pi) * self.gear_ratio * self.pole_pairs

    def no_load_ankle_speed_rad_s(self, belt_ratio: float) -> float:
        """The fastest the ankle can turn through a belt of this ratio (rad/s)."""
        return self.no_load_speed_rpm * 2.0 * math.pi / 60.0 / belt_ratio

    @classmethod
    def from_table(cls, table: dict[str, Any]) -> MotorRatings:
        """The ratings a [motor] table states (the rest the AK60-6's); ValueError names a bad value."""
        return cls(**{k: v for k, v in table.items() if k in RATING_KEYS})


RATING_KEYS = tuple(f.name for f in fields(MotorRatings))
"""The keys of [motor] that state the motor's ratings."""

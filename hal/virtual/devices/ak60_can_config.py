"""The CAN side of the AK60-6 over CAN: driver id, mode, status rate, MIT ranges, servo mode's current convention.

Interpreted on purpose (docs/compiled.md, "Values checked as given").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from protocol import can_mit, can_servo

__all__ = ["CURRENT_CONVENTIONS", "MODES", "Ak60CanConfig"]

MODES = ("servo", "mit")
CURRENT_CONVENTIONS = {"catalogue": 1.0, "rms": 1.0 / math.sqrt(1.5), "peak": 2.0 / math.sqrt(3.0)}
"""Servo mode's amps on the wire per amp of the plant, by the current convention the client's torque constant
assumes. The plant's current is the catalogue's: torque = Kt x I with the maker's Kt, which CubeMars gives as 1/Kv
(AK80-9 KV100: 60 / (2 pi 100) = 0.0955, printed 0.095 N m/A). For a sinusoidal motor whose Kv is counted against the
line-to-line peak voltage, the same torque takes an RMS phase current sqrt(2/3) of that (Kt_rms = sqrt(3/2) / Kv:
0.117 for the AK80-9, within 2 % of the 0.115 opensourceleg and TMotorCANControl use) and an amplitude-invariant q
current (the peak phase current, Ben Katz's mini-cheetah firmware convention) 2/sqrt(3) of it (Kt = (sqrt(3)/2) /
Kv: 0.0827). Copper loss is the same I^2 R_line-to-line in the catalogue's convention as 3/2 I_peak^2 R_phase: only
the amps on the wire change. docs/hardware.md, "Current conventions"."""


@dataclass(frozen=True)
class Ak60CanConfig:
    """The CAN side: driver id, mode, status rate (servo mode), the model's MIT ranges."""

    driver_id: int = 1
    mode: str = "servo"
    status_period_s: float = 0.002  # 500 Hz: the drive's highest upload rate (1..500 Hz, set in the maker's tool)
    limits: can_mit.MitLimits = can_mit.AK60_6
    current_convention: str = "catalogue"  # servo mode's amps on the wire (CURRENT_CONVENTIONS)

    def __post_init__(self) -> None:
        """Check the id, the mode, the status period and the current convention."""
        if self.current_convention not in CURRENT_CONVENTIONS:
            raise ValueError(f"current convention {self.current_convention!r} unknown: one of "
                             f"{sorted(CURRENT_CONVENTIONS)}")
        if isinstance(self.driver_id, bool) or not isinstance(self.driver_id, int) or not 0 <= self.driver_id <= 127:
            raise ValueError(f"driver_id {self.driver_id!r} out of range: an int in 0..127")
        if self.mode not in MODES:
            raise ValueError(f"CAN mode {self.mode!r} invalid: one of {MODES}")
        lo, hi = 1.0 / can_servo.STATUS_HZ_MAX, 1.0 / can_servo.STATUS_HZ_MIN
        if not (math.isfinite(self.status_period_s) and lo <= self.status_period_s <= hi):
            raise ValueError(f"status_period_s {self.status_period_s!r} out of range [{lo}, {hi}] s (the drive's "
                             f"{can_servo.STATUS_HZ_MIN}..{can_servo.STATUS_HZ_MAX} Hz, manual 5.2.1)")

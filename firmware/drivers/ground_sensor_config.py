"""The firmware's [ground_sensors] table (profiles/firmware.toml): channels, calibration, thresholds.

Used by the driver (ground_sensors.py) and the event detector (firmware/control/ground_events.py).
Interpreted on purpose (setup.py): the checks must see the values as given.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

from firmware.control.validation import check_range

__all__ = ["GroundSensorConfig"]


@dataclass(frozen=True)
class GroundSensorConfig:
    """The firmware's [ground_sensors] table: channels, calibration, thresholds (profiles/firmware.toml)."""

    force_channel: str = "load_force"
    moment_channel: str = "load_moment"
    heel_channel: str = "fsr_heel"
    toe_channel: str = "fsr_toe"
    calibration: tuple[tuple[float, float], tuple[float, float]] = ((865.789, -33.3508), (-0.692631, 66.7017))
    tare_s: float = 0.3
    rezero_tau_s: float = 2.0
    fsr_on_v: float = 1.5
    fsr_off_v: float = 1.0
    fsr_short_v: float = 3.25
    contact_on_n: float = 40.0
    contact_off_n: float = 20.0
    rail_margin_v: float = 0.08
    fault_samples: int = 20
    min_stance_s: float = 0.2
    min_swing_s: float = 0.15
    cost_cycles: int = 400

    def __post_init__(self) -> None:
        """ValueError naming a value out of its range."""
        cal = self.calibration
        if not (len(cal) == 2 and all(len(row) == 2 for row in cal)):
            raise ValueError(f"calibration = {cal!r} is not allowed: a 2x2 matrix [[N/V, N/V], [N m/V, N m/V]]")
        for row in cal:
            for x in row:
                check_range("calibration entry", x, -1e6, 1e6, unit="per V")
        if abs(cal[0][0] * cal[1][1] - cal[0][1] * cal[1][0]) < 1e-9:
            raise ValueError(f"calibration = {cal!r} is not allowed: singular")
        check_range("tare_s", self.tare_s, 0.0, 10.0, lo_open=True, unit="s")
        check_range("rezero_tau_s", self.rezero_tau_s, 0.0, 1000.0, lo_open=True, unit="s")
        check_range("fsr_off_v", self.fsr_off_v, 0.0, 5.5, lo_open=True, unit="V")
        check_range("fsr_on_v", self.fsr_on_v, self.fsr_off_v, 5.5, unit="V")
        check_range("fsr_short_v", self.fsr_short_v, self.fsr_on_v, 5.5, lo_open=True, unit="V")
        check_range("contact_off_n", self.contact_off_n, 0.0, 1e4, lo_open=True, unit="N")
        check_range("contact_on_n", self.contact_on_n, self.contact_off_n, 1e4, unit="N")
        check_range("rail_margin_v", self.rail_margin_v, 0.0, 1.0, unit="V")
        check_range("min_stance_s", self.min_stance_s, 0.0, 10.0, unit="s")
        check_range("min_swing_s", self.min_swing_s, 0.0, 10.0, unit="s")
        for name in ("fault_samples", "cost_cycles"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 1_000_000:
                raise ValueError(f"{name} = {value!r} is not allowed: must be an integer in [1, 1000000]")

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> GroundSensorConfig:
        """From the profile's table; ValueError naming an unknown key."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ValueError(f"has no key {unknown[0]!r}: its keys are {', '.join(sorted(known))}")
        values = dict(table)
        if "calibration" in values:
            cal = values["calibration"]
            if not isinstance(cal, list) or not all(isinstance(r, list) for r in cal):
                raise ValueError(f"calibration = {cal!r} is not allowed: a 2x2 matrix [[N/V, N/V], [N m/V, N m/V]]")
            values["calibration"] = tuple(tuple(r) for r in cal)
        return cls(**values)

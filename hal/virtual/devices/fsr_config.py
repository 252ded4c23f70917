"""A force-sensing resistor's and its divider's parameters (profiles/ground_sensors.toml, [fsr]).

The model is fsr.py.

Interpreted on purpose (setup.py): the range checks must see the values as given.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hal.virtual.checks import check_field_ranges, from_table

__all__ = ["FsrParams"]

_RANGES = {"actuation_n": (0.0, 10.0), "open_ohm": (1e5, 1e9), "ohm_at_1n": (10.0, 1e7), "exponent": (0.1, 3.0),
           "saturation_n": (0.5, 1e4), "hysteresis": (0.0, 0.5), "divider_ohm": (10.0, 1e7), "supply_v": (1.8, 5.5),
           "load_share": (0.0, 1.0)}


@dataclass(frozen=True)
class FsrParams:
    """One FSR and its divider (profiles/ground_sensors.toml, [fsr])."""

    actuation_n: float = 0.2
    open_ohm: float = 10e6
    ohm_at_1n: float = 8e3
    exponent: float = 0.9
    saturation_n: float = 20.0
    hysteresis: float = 0.10
    divider_ohm: float = 10e3
    supply_v: float = 3.3
    load_share: float = 0.05

    def __post_init__(self) -> None:
        """ValueError naming a value out of its range."""
        check_field_ranges(self, _RANGES)

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> FsrParams:
        """From the profile's [fsr] table."""
        return from_table(cls, table, "fsr")

    def resistance_ohm(self, force_n: float, falling: bool = False) -> float:
        """The FSR's resistance under force_n on its active area (lower by the hysteresis while unloading)."""
        if force_n < self.actuation_n:
            return self.open_ohm
        r = self.ohm_at_1n * min(force_n, self.saturation_n) ** -self.exponent
        r = min(r, self.open_ohm)
        return r * (1.0 - self.hysteresis) if falling else r

    def volts(self, resistance_ohm: float) -> float:
        """The divider's output for an FSR resistance."""
        return self.supply_v * self.divider_ohm / (self.divider_ohm + resistance_ohm)

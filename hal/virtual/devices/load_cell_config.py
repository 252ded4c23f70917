"""The pylon load cell's parameters (profiles/ground_sensors.toml, [load_cell]); the model is load_cell.py.

Interpreted on purpose (setup.py): the range checks must see the values as given.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from hal.virtual.checks import check_field_ranges, from_table

__all__ = ["LoadCellParams"]

_RANGES = {"rated_force_n": (100.0, 1e5), "rated_moment_nm": (1.0, 1e4), "rated_output_mv_per_v": (0.1, 10.0),
           "crosstalk": (0.0, 0.5), "excitation_v": (0.5, 10.0), "force_gain_resistor_ohm": (10.0, 1e6),
           "moment_gain_resistor_ohm": (10.0, 1e6), "supply_v": (1.8, 5.5), "force_ref_v": (0.0, 5.5),
           "moment_ref_v": (0.0, 5.5), "swing_v": (0.0, 0.5), "zero_balance": (0.0, 0.2), "drift_per_min": (0.0, 0.1),
           "height_m": (0.0, 1.0)}


@dataclass(frozen=True)
class LoadCellParams:
    """The load cell and its two amplifier channels (profiles/ground_sensors.toml, [load_cell])."""

    rated_force_n: float = 2500.0
    rated_moment_nm: float = 100.0
    rated_output_mv_per_v: float = 2.0
    crosstalk: float = 0.02
    excitation_v: float = 3.3
    force_gain_resistor_ohm: float = 229.0
    force_ref_v: float = 0.3
    moment_gain_resistor_ohm: float = 442.0
    moment_ref_v: float = 1.65
    supply_v: float = 3.3
    swing_v: float = 0.05
    zero_balance: float = 0.01
    drift_per_min: float = 0.0002
    height_m: float = 0.15

    def __post_init__(self) -> None:
        """ValueError naming a value out of its range."""
        check_field_ranges(self, _RANGES)

    @classmethod
    def from_table(cls, table: Mapping[str, Any]) -> LoadCellParams:
        """From the profile's [load_cell] table."""
        return from_table(cls, table, "load_cell")

    @property
    def force_gain(self) -> float:
        """The force channel's amplifier gain (INA333: 1 + 100 kOhm / R_G)."""
        return 1.0 + 100e3 / self.force_gain_resistor_ohm

    @property
    def moment_gain(self) -> float:
        """The moment channel's amplifier gain."""
        return 1.0 + 100e3 / self.moment_gain_resistor_ohm

    def sensitivity(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """Bridge outputs in V per (N, N m): rows force bridge, moment bridge; the off-diagonal is the crosstalk."""
        full_v = self.rated_output_mv_per_v * 1e-3 * self.excitation_v
        f, m = full_v / self.rated_force_n, full_v / self.rated_moment_nm
        return (f, self.crosstalk * m), (self.crosstalk * f, m)

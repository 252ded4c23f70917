"""A pylon load cell: axial force and sagittal moment through two strain-gauge bridges and two amplifiers.

Two full bridges on the pylon, excited from the 3.3 V rail, give ``rated_output_mv_per_v`` at the rated
force and moment; each bridge also sees a fraction ``crosstalk`` of the other load (the calibration
matrix of the part's certificate undoes it; the firmware's copy is in profiles/firmware.toml,
``[ground_sensors]``). Each bridge feeds an instrumentation amplifier (TI INA333: G = 1 + 100 kOhm / R_G,
output within ``swing_v`` of the rails, SBOS445) whose REF pin sets the zero-load output; the outputs go
to two ADC channels. The bridge has a zero offset (drawn with the seed within +-``zero_balance`` of the
rated output: the part's "zero balance") that drifts by ``drift_per_min`` of the rated output per minute.
Loads beyond what the rails allow saturate at the rails. Parameters and sources: profiles/ground_sensors.toml.
``fault``: None, ``"open"`` (a broken excitation wire: the amplifier sits at its REF) or ``"stuck_high"``.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from hal.virtual.checks import check_field_ranges, from_table

__all__ = ["LoadCell", "LoadCellParams"]

FAULTS = (None, "open", "stuck_high")
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


class LoadCell:
    """The load cell under the ground reaction ``ground.at(t_s) -> (F_z, F_x, CoP)``: two output voltages."""

    def __init__(self, params: LoadCellParams, ground: Any, f_hz: int, seed: int = 0) -> None:
        """Draw the zero offsets of both bridges from the seed (within the part's zero balance)."""
        self.params = p = params
        self.ground = ground
        self.f_hz = f_hz
        rng = random.Random(f"load_cell:{seed}")
        full_v = p.rated_output_mv_per_v * 1e-3 * p.excitation_v
        self.offset_v = (rng.uniform(-1, 1) * p.zero_balance * full_v, rng.uniform(-1, 1) * p.zero_balance * full_v)
        self.drift_v_per_s = p.drift_per_min * full_v / 60.0
        self.fault: str | None = None
        (self._a, self._b), (self._c, self._d) = p.sensitivity()
        self._force_gain, self._moment_gain = p.force_gain, p.moment_gain

    def set_fault(self, mode: str | None) -> None:
        """Inject a fault (FAULTS) from now on; None clears it."""
        if mode not in FAULTS:
            raise ValueError(f"load cell fault {mode!r} unknown: one of {list(FAULTS)}")
        self.fault = mode

    def loads(self, t_s: float) -> tuple[float, float]:
        """(axial force N, compression +; sagittal moment N m about the cell) at t_s: emulation truth."""
        fz, fx, cop = self.ground.at(t_s)
        return fz, fz * cop - fx * self.params.height_m

    def _output(self, bridge_v: float, gain: float, ref_v: float) -> float:
        p = self.params
        if self.fault == "open":
            return ref_v
        if self.fault == "stuck_high":
            return p.supply_v - p.swing_v
        v = ref_v + gain * bridge_v
        return min(p.supply_v - p.swing_v, max(p.swing_v, v))

    def force_volts(self, t: int) -> float:
        """The force channel's amplifier output at tick t."""
        t_s = t / self.f_hz
        fz, my = self.loads(t_s)
        bridge = self._a * fz + self._b * my + self.offset_v[0] + self.drift_v_per_s * t_s
        return self._output(bridge, self._force_gain, self.params.force_ref_v)

    def moment_volts(self, t: int) -> float:
        """The moment channel's amplifier output at tick t."""
        t_s = t / self.f_hz
        fz, my = self.loads(t_s)
        bridge = self._c * fz + self._d * my + self.offset_v[1] + self.drift_v_per_s * t_s
        return self._output(bridge, self._moment_gain, self.params.moment_ref_v)

    def outputs(self) -> dict[str, Callable[[int], float]]:
        """The output pins by ADC channel name."""
        return {"load_force": self.force_volts, "load_moment": self.moment_volts}

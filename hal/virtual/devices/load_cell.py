"""A pylon load cell: axial force and sagittal moment through two strain-gauge bridges and two amplifiers.

Two full bridges on the pylon, excited from the 3.3 V rail, give ``rated_output_mv_per_v`` at the rated
force and moment; each bridge also sees a fraction ``crosstalk`` of the other load (the calibration
matrix of the part's certificate undoes it; the firmware's copy is in profiles/firmware.toml,
``[ground_sensors]``). Each bridge feeds an instrumentation amplifier (TI INA333: G = 1 + 100 kOhm / R_G,
output within ``swing_v`` of the rails, SBOS445) whose REF pin sets the zero-load output; the outputs go
to two ADC channels. The bridge has a zero offset (drawn with the seed within +-``zero_balance`` of the
rated output: the part's "zero balance") that drifts by ``drift_per_min`` of the rated output per minute.
Loads beyond what the rails allow saturate at the rails. Parameters (load_cell_config.py) and sources:
profiles/ground_sensors.toml. Compiled (setup.py): the ADC samples it every scan.
``fault``: None, ``"open"`` (a broken excitation wire: the amplifier sits at its REF) or ``"stuck_high"``.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

from hal.virtual.devices.load_cell_config import LoadCellParams

__all__ = ["LoadCell", "LoadCellParams"]

FAULTS = (None, "open", "stuck_high")
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
        rows = p.sensitivity()
        self._a, self._b = rows[0]
        self._c, self._d = rows[1]
        self._force_gain = p.force_gain
        self._moment_gain = p.moment_gain

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

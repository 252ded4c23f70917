"""Supply sag: the battery behind the driver drops to a given voltage (a weak cell, a loose lead)."""

from __future__ import annotations

from typing import Any

from hal.virtual.faults.alarm import at
from hal.virtual.faults.base import FaultRig, Injector

__all__ = ["SupplySag"]


class SupplySag(Injector):
    """The driver's supply is ``voltage_v`` in the window, then nominal again.

    It acts on the driver model's supply (its input voltage, its UNDER_VOLTAGE fault at 8 V), not on the plant's
    voltage headroom (docs/safety.md).
    """

    NAME = "supply_sag"
    HAZARD = "the driver under-voltage trip releases the motor mid-stride"
    WHERE = "supply (battery) behind the AK60-6"
    PARAMS = {"voltage_v": (7.0, 0.0, 60.0)}

    def arm(self, rig: FaultRig) -> None:
        """Schedule the sag and the recovery on the driver model."""
        motor: Any = rig.bench.motor
        nominal = float(motor.meter.v_supply_v)
        v = self.params["voltage_v"]
        motor.set_supply_voltage(v, self.onset_s)
        if self.duration_s < 1e6:
            motor.set_supply_voltage(nominal, self.end_s)

        def check(t: int) -> None:
            if motor.meter.v_supply_v == v:
                self.note(t / rig.f_cpu_hz, f"supply {nominal:g} V -> {v:g} V")
        at(rig, self.onset_s + 1e-6, check)

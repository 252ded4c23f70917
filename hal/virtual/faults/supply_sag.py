"""Supply sag: the battery behind the driver drops to a given voltage (a weak cell, a loose lead)."""

from __future__ import annotations

from typing import Any

from hal.virtual.faults.alarm import at
from hal.virtual.faults.base import FaultRig, Injector

__all__ = ["SupplySag"]


class SupplySag(Injector):
    """The driver's supply is ``voltage_v`` in the window, then nominal again.

    It acts on the driver model's supply (its input voltage, its UNDER_VOLTAGE fault at 8 V), not on the plant's
    voltage headroom (docs/safety.md). On the fixed supply the source behind its resistance is ``voltage_v``;
    with a battery fitted (``--battery``, a design's battery) the pack's EMF is at most ``voltage_v`` behind the
    pack's own resistance (`Battery.sag`), so the bus the driver sees follows the pack's current as it does
    outside the sag.
    """

    NAME = "supply_sag"
    HAZARD = "the driver under-voltage trip releases the motor mid-stride"
    WHERE = "supply (battery) behind the AK60-6"
    PARAMS = {"voltage_v": (7.0, 0.0, 60.0)}

    def arm(self, rig: FaultRig) -> None:
        """Schedule the sag and the recovery on the driver model's supply, or on its battery when one is fitted."""
        motor: Any = rig.bench.motor
        v = self.params["voltage_v"]
        battery = motor.meter.battery
        if battery is not None:
            def sag(t: int) -> None:
                e = battery.open_circuit_v()
                battery.sag(v)
                self.note(t / rig.f_cpu_hz, f"battery EMF {e:.3g} V -> at most {v:g} V")

            at(rig, self.onset_s, sag)
            if self.duration_s < 1e6:
                at(rig, self.end_s, lambda t: battery.sag(None))
            return
        nominal = float(motor.meter.v_supply_v)
        motor.set_supply_voltage(v, self.onset_s)
        if self.duration_s < 1e6:
            motor.set_supply_voltage(nominal, self.end_s)

        def check(t: int) -> None:
            if motor.meter.v_supply_v == v:
                self.note(t / rig.f_cpu_hz, f"supply {nominal:g} V -> {v:g} V")
        at(rig, self.onset_s + 1e-6, check)

"""Motor stall: a mechanical jam at the output (a stone in the belt, a seized bearing) locks the ankle."""

from __future__ import annotations

from typing import Any

from hal.virtual.faults.alarm import at
from hal.virtual.faults.base import FaultRig, Injector

__all__ = ["MotorStall"]


class MotorStall(Injector):
    """In the window the plant's stops close on the angle at the onset (the stop contact model holds the foot)."""

    NAME = "motor_stall"
    HAZARD = "the ankle locks: the motor pushes against the jam at up to the current limit"
    WHERE = "transmission (plant: the output jammed)"

    def arm(self, rig: FaultRig) -> None:
        """Close the plant's stops on the onset angle at the onset; open them at the end."""
        plant: Any = rig.bench.plant.raw
        c = plant._c  # the integrator's coefficients: the stop angles lo, hi (hal/virtual/plant/integrator.py)
        saved = (c.lo, c.hi)

        def jam(t: int) -> None:
            t_s = t / rig.f_cpu_hz
            angle = plant.output_angle_rad(t_s)
            _restart(plant, t_s)
            c.lo = c.hi = angle
            self.note(t_s, f"output jammed at {angle:.4f} rad")

        def release(t: int) -> None:
            _restart(plant, t / rig.f_cpu_hz)
            c.lo, c.hi = saved
        at(rig, self.onset_s, jam)
        at(rig, self.end_s, release)


def _restart(plant: Any, t_s: float) -> None:
    """Commit the plant's state at t_s and drop its look-ahead (as an input does), so the new stops act from t_s."""
    plant._commit_event(t_s)

"""Motor fault code: the AK60-6 raises a fault (VESC ``mc_fault_code``), releases the motor and reports the code."""

from __future__ import annotations

from typing import Any, ClassVar

from hal.virtual.faults.alarm import at
from hal.virtual.faults.base import FaultRig, Injector
from protocol.vesc_values import FaultCode

__all__ = ["MotorFaultCode"]


class MotorFaultCode(Injector):
    """The driver model faults with ``code`` at the onset and holds it for the duration (VESC's fault stop)."""

    NAME = "motor_fault_code"
    HAZARD = "the motor is released mid-stride: the foot is unsupported"
    WHERE = "motor driver (AK60-6 model)"
    PARAMS: ClassVar[dict[str, tuple[Any, ...]]] = {"code": (float(FaultCode.DRV), 1.0, 18.0)}

    def fault_code(self) -> int:
        """The code raised."""
        return int(self.params["code"])

    def arm(self, rig: FaultRig) -> None:
        """Schedule the fault on the driver model; note it when the model holds it."""
        motor: Any = rig.bench.motor
        code = self.fault_code()
        motor.inject_fault(code, self.onset_s, self.duration_s if self.duration_s < 1e6 else 1e6)

        def check(t: int) -> None:
            if motor.fault == code:
                self.note(t / rig.f_cpu_hz, f"AK60-6 fault {FaultCode(code).name}, motor released")
        at(rig, self.onset_s + 1e-6, check)

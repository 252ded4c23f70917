"""Motor over-temperature: the AK60-6 reports OVER_TEMP_MOTOR (VESC fault 6) and releases the motor."""

from __future__ import annotations

from typing import Any, ClassVar

from hal.virtual.faults.motor_fault_code import MotorFaultCode
from protocol.vesc_values import FaultCode

__all__ = ["MotorOverTemp"]


class MotorOverTemp(MotorFaultCode):
    """The driver's motor-temperature limit trips (the fault code, not a thermal model: docs/safety.md)."""

    NAME = "motor_over_temp"
    HAZARD = "the driver releases the motor mid-stride: the foot is unsupported"
    PARAMS: ClassVar[dict[str, tuple[Any, ...]]] = {}

    def fault_code(self) -> int:
        """OVER_TEMP_MOTOR."""
        return int(FaultCode.OVER_TEMP_MOTOR)

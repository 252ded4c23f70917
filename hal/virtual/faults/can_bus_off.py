"""CAN bus-off: the MCU's controller has gone bus-off (TEC > 255 after repeated errors): no frame is exchanged."""

from __future__ import annotations

from hal.can import CanFrame
from hal.virtual.faults.can_fault import CanFault

__all__ = ["CanBusOff"]


class CanBusOff(CanFault):
    """Every frame between the MCU and the motor in the window is lost.

    The window is the episode as the nodes see it: bus-off plus the recovery of 128 x 11 recessive bits (ISO
    11898-1), which the duration includes. The bxCAN's mailboxes are not held back (docs/safety.md).
    """

    NAME = "can_bus_off"
    HAZARD = "no command reaches the motor and no feedback the MCU: the motor runs on its last command"

    def fate(self, frame: CanFrame, t_s: float) -> float | None:
        """Destroyed."""
        return None

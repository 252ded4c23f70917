"""Motor replies lost: nothing from the AK60-6 reaches the MCU (a broken RX wire, a dead transceiver)."""

from __future__ import annotations

from hal.virtual.faults.wire_faults import Lost

__all__ = ["MotorRepliesLost"]


class MotorRepliesLost(Lost):
    """Every byte (UART) or frame (CAN) the motor sends in the window is lost."""

    NAME = "motor_replies_lost"
    HAZARD = "the firmware controls on stale angle and current feedback"
    WHERE = "motor -> MCU wire (UART RX line or CAN frames from the motor)"
    WIRE = "motor_rx"

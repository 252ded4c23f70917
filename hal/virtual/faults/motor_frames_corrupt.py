"""Motor frames corrupted: a burst of bit errors on the motor's replies (EMI on the motor cable)."""

from __future__ import annotations

from hal.virtual.faults.wire_faults import BitErrors

__all__ = ["MotorFramesCorrupt"]


class MotorFramesCorrupt(BitErrors):
    """Bit errors on the motor -> MCU wire; on CAN a corrupted frame fails its CRC and is destroyed."""

    NAME = "motor_frames_corrupt"
    HAZARD = "replies fail their CRC and are dropped (stale feedback), or a corrupted value passes"
    WHERE = "motor -> MCU wire (UART bytes; CAN frames)"
    WIRE = "motor_rx"

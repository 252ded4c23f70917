"""IMU frames corrupted: a burst of bit errors on the IMU's line (EMI, a failing cable)."""

from __future__ import annotations

from hal.virtual.faults.wire_faults import BitErrors

__all__ = ["ImuCorrupt"]


class ImuCorrupt(BitErrors):
    """Bit errors on the IMU -> MCU wire."""

    NAME = "imu_corrupt"
    HAZARD = "frames fail their checksum and are dropped (the IMU falls silent), or a corrupted value passes"
    WHERE = "IMU -> MCU wire"
    WIRE = "imu_rx"

"""IMU silent: nothing from the BNO08x reaches the MCU (a loose connector, a dead sensor)."""

from __future__ import annotations

from hal.virtual.faults.wire_faults import Lost

__all__ = ["ImuSilent"]


class ImuSilent(Lost):
    """Every byte the IMU sends in the window is lost."""

    NAME = "imu_silent"
    HAZARD = "the fused angle runs on the encoder alone; a drift or encoder fault goes unchecked"
    WHERE = "IMU -> MCU wire"
    WIRE = "imu_rx"

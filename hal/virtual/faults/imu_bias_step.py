"""IMU bias step: the BNO08x's pitch jumps by a fixed offset (a knock on the mount, a re-zeroed fusion)."""

from __future__ import annotations

import math

from hal.virtual.faults.base import ByteFault
from hal.virtual.faults.rvc_frames import rewrite_frames
from protocol.rvc import RvcFrame

__all__ = ["ImuBiasStep"]


class ImuBiasStep(ByteFault):
    """Every frame in the window reports pitch + ``step_deg``."""

    NAME = "imu_bias_step"
    HAZARD = "the fused angle drifts by the step: the foot is driven off the reference"
    WHERE = "IMU output (frames rewritten on the IMU -> MCU wire)"
    WIRE = "imu_rx"
    DANGEROUS = True  # a plausible false angle: the controller drives the foot by it
    PARAMS = {"step_deg": (10.0, -90.0, 90.0)}

    def change(self, data: bytes, t_s: float) -> bytes:
        """Pitch plus the step."""
        step = math.radians(self.params["step_deg"])
        return rewrite_frames(data, lambda f: RvcFrame(f.index, f.yaw_rad, f.pitch_rad + step, f.roll_rad,
                                                       f.accel_x_mps2, f.accel_y_mps2, f.accel_z_mps2,
                                                       f.motion_intent, f.motion_request))

"""IMU frozen: the BNO08x keeps sending frames, every one with the values of the last frame before the onset."""

from __future__ import annotations

from hal.virtual.faults.base import ByteFault
from hal.virtual.faults.rvc_frames import rewrite_frames
from protocol.rvc import RvcFrame

__all__ = ["ImuFrozen"]


class ImuFrozen(ByteFault):
    """Frames keep coming (index counting) with yaw, pitch, roll and accelerations held at their last value."""

    NAME = "imu_frozen"
    HAZARD = "the fused angle is pulled towards a stale pitch: the foot drifts while every source looks alive"
    WHERE = "IMU output (frames rewritten on the IMU -> MCU wire)"
    WIRE = "imu_rx"
    DANGEROUS = True  # a plausible false angle: the controller drives the foot by it

    def __init__(self, *args: object, **kwargs: object) -> None:
        """See Injector."""
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.held: RvcFrame | None = None

    def filter(self, data: bytes, t_s: float) -> bytes:
        """Remember the newest frame before the onset; in the window, send it again under each new index."""
        if t_s < self.onset_s:
            rewrite_frames(data, self._keep)
            return data
        if self.held is None:
            return data
        return super().filter(data, t_s)

    def _keep(self, frame: RvcFrame) -> RvcFrame:
        self.held = frame
        return frame

    def change(self, data: bytes, t_s: float) -> bytes:
        """The held values under the frame's own index."""
        held = self.held
        assert held is not None

        def frozen(f: RvcFrame) -> RvcFrame:
            return RvcFrame(f.index, held.yaw_rad, held.pitch_rad, held.roll_rad, held.accel_x_mps2,
                            held.accel_y_mps2, held.accel_z_mps2, f.motion_intent, f.motion_request)
        return rewrite_frames(data, frozen)

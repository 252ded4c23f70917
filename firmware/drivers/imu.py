"""BNO08x driver in UART-RVC mode: decode 19-byte frames, keep the latest pitch and its time."""

from __future__ import annotations

from firmware.drivers.link import LinkState
from hal.errors import HalError
from hal.interfaces import Uart
from protocol.rvc import RvcDecoder, RvcFrame

__all__ = ["ImuDriver"]


class ImuDriver(LinkState):
    """Reads the IMU UART; `pitch_rad` is the newest frame's pitch, `last_frame_s` when it came.

    `last_poll_s` is when the port was last read (frames or not): an age measured to it is the IMU's silence,
    not the host's stall of this task. `changed_s` is when a frame last carried a measurement different from
    the frame before it (its index aside): a sensor stuck at one value keeps sending bit-identical content.
    """

    def __init__(self, uart: Uart, mounting_offset_rad: float = 0.0) -> None:
        """Bind the UART; `mounting_offset_rad` is subtracted from the sensor's pitch."""
        self.uart = uart
        self.decoder = RvcDecoder()
        self.mounting_offset_rad = mounting_offset_rad
        self.latest: RvcFrame | None = None
        self.last_frame_s: float | None = None
        self.last_poll_s: float | None = None
        self.changed_s: float | None = None
        self.frames = 0

    def relink(self, uart: Uart) -> None:
        """Continue on a reopened port (the supervisor's latched fault is not cleared)."""
        self.uart = uart
        self._relinked()
        self.decoder = RvcDecoder()

    @property
    def pitch_rad(self) -> float | None:
        """Pitch of the newest frame less the mounting offset, or None before the first frame."""
        return None if self.latest is None else self.latest.pitch_rad - self.mounting_offset_rad

    def poll(self, now_s: float) -> int:
        """Decode what has arrived; return the number of new frames (0 if none)."""
        self.last_poll_s = now_s
        try:
            data = self.uart.read()
        except HalError as exc:  # port gone: latch it with the cause; the supervisor trips LINK_LOST
            self._lose(exc, now_s)
            return 0
        if not data:
            return 0
        frames = self.decoder.feed(data)
        if frames:
            before = self.latest
            for f in frames:
                if before is None or _content(f) != _content(before):
                    self.changed_s = now_s
                before = f
            self.latest = frames[-1]
            self.last_frame_s = now_s
            self.frames += len(frames)
        return len(frames)


def _content(f: RvcFrame) -> tuple[float, float, float, float, float, float]:
    """What a frame measured (angles and accelerations), without its index and flags."""
    return (f.yaw_rad, f.pitch_rad, f.roll_rad, f.accel_x_mps2, f.accel_y_mps2, f.accel_z_mps2)

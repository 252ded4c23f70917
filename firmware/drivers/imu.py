"""BNO08x driver in UART-RVC mode: decode 19-byte frames, keep the latest pitch and its time."""

from __future__ import annotations

from firmware.drivers.link import LinkState
from hal.errors import HalError
from hal.interfaces import Uart
from protocol.rvc import RvcDecoder, RvcFrame

__all__ = ["ImuDriver"]


class ImuDriver(LinkState):
    """Reads the IMU UART; `pitch_rad` is the newest frame's pitch, `last_frame_s` when it came."""

    def __init__(self, uart: Uart, mounting_offset_rad: float = 0.0) -> None:
        """Bind the UART; `mounting_offset_rad` is subtracted from the sensor's pitch."""
        self.uart = uart
        self.decoder = RvcDecoder()
        self.mounting_offset_rad = mounting_offset_rad
        self.latest: RvcFrame | None = None
        self.last_frame_s: float | None = None
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
        try:
            data = self.uart.read()
        except HalError as exc:  # port gone: latch it with the cause; the supervisor trips LINK_LOST
            self._lose(exc, now_s)
            return 0
        if not data:
            return 0
        frames = self.decoder.feed(data)
        if frames:
            self.latest = frames[-1]
            self.last_frame_s = now_s
            self.frames += len(frames)
        return len(frames)

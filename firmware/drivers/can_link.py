"""What the AK60-6's CAN drivers share (servo and MIT mode): taking frames, queueing one, the stop path.

A subclass sets ``LINK`` (its name in firmware.drivers.motor_links.MOTOR_LINKS), decodes the frames
``_take`` returns and builds its own commands; a port failure latches ``link_lost`` here, in one place.
"""

from __future__ import annotations

from typing import ClassVar

from firmware.config import FirmwareConfig
from firmware.drivers.motor_link import MotorFeedback, MotorLink, MotorLinkStats, RxCounter, SafeStop
from hal.can import CanFrame, CanPort
from hal.errors import HalError
from hal.interfaces import Board

__all__ = ["CanLink"]


class CanLink(MotorLink):
    """A motor driver on a CAN port: the port, the feedback, the accounting and the frame plumbing."""

    LINK: ClassVar[str] = "can"  # its name in motor_links.MOTOR_LINKS

    def __init__(self, port: CanPort, driver_id: int) -> None:
        """Feedback, statistics and counters empty; nothing is sent yet."""
        self.port = port
        self.driver_id = driver_id
        self.feedback = MotorFeedback()
        self.stats = MotorLinkStats()
        self.decoder = RxCounter()
        self.last_command_s = None
        self.other_frames = 0

    @classmethod
    def from_board(cls, board: Board, config: FirmwareConfig) -> CanLink:
        """The driver on the board's CAN port (HalError naming the link if the board has none)."""
        if board.can is None:
            raise HalError(f"motor link {cls.LINK} needs a CAN port on the board (Board.can is None)")
        return cls.on_port(board.can, config)

    @classmethod
    def on_port(cls, port: CanPort, config: FirmwareConfig) -> CanLink:
        """The driver on ``port`` for the profile's motor (a subclass adds what its mode scales by the motor)."""
        return cls(port, config.motor_can_id)

    def _take(self, now_s: float) -> list[CanFrame]:
        """Every frame waiting in the FIFOs, counted; a failing port is latched as lost (frames so far kept)."""
        frames: list[CanFrame] = []
        while True:
            try:
                frame = self.port.receive()
            except HalError as exc:
                self._lose(exc, now_s)
                return frames
            if frame is None:
                return frames
            self.decoder.stats.frames += 1
            self.decoder.stats.bytes_in += len(frame.data)
            frames.append(frame)

    def _put(self, frame: CanFrame, now_s: float) -> bool:
        """Queue one frame in a mailbox; False (counted) when refused or the port failed."""
        try:
            ok = self.port.send(frame)
        except HalError as exc:
            self._lose(exc, now_s)
            return False
        if not ok:
            self.stats.tx_refused += 1
        return ok

    def _stop(self, frames: tuple[CanFrame, ...], names: tuple[str, ...], now_s: float,
              timeout_s: float) -> SafeStop:
        """Queue the safe frames in order, then wait for the mailboxes to empty; a failing port is latched."""
        stop = SafeStop(b"".join(f.data for f in frames), now_s, names)
        try:
            for f in frames:
                if not self.port.send(f):
                    break
                stop.written += len(f.data)
            stop.drained = self.port.flush(timeout_s)
        except HalError as exc:
            self._lose(exc, now_s)
            stop.error = str(exc)
        if stop.written < len(stop.frames):
            self.stats.tx_refused += 1
        elif stop.written:
            self.last_command_s = now_s
        return stop

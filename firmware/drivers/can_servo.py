"""AK60-6 driver over CAN in servo mode: SET_CURRENT / SET_CURRENT_BRAKE out, the periodic status frames in.

Servo mode has no request: the motor sends a status frame (``0x29xx``) at its own rate whether or not a
command came (PROTOCOLS.md G). Each control tick the motor task calls ``poll`` (every status frame
waiting in the FIFOs updates ``feedback``) and ``send`` (one command frame into a mailbox). Accounting
(:class:`~firmware.drivers.motor_link.MotorLinkStats`): ``replies`` counts status frames, ``requests``
commands sent; ``max_age_s`` is the longest time between two status frames as the driver took them
(the oldest feedback the firmware held); ``stale_replies`` counts status frames from a motor in fault.
A silent bus leaves ``feedback.received_s`` behind, which the supervisor bounds (MOTOR_TIMEOUT); a
failing port latches ``link_lost``. The safe behaviours are servo mode's: release (SET_CURRENT 0), the brake
(SET_CURRENT_BRAKE) and the phase short (SET_DUTY 0); the stop path sends the safe command (the brake after a
zero current, as on the UART). The bxCAN sends its mailboxes by identifier, lowest first, whatever order they were
filled in: a zero current (0x1xx) queued beside the short (0x0xx) would go out after it and release the motor, so
the short goes alone; the brake's pair (0x1xx then 0x2xx) keeps its order.
"""

from __future__ import annotations

import math
from typing import ClassVar

from firmware.drivers.can_link import CanLink
from firmware.drivers.motor_link import SafeStop, stop_command
from firmware.safe_state import SafeCommand
from hal.can import CanFrame, CanPort
from protocol import can_servo

__all__ = ["CanServoDriver"]

_ERPM_PER_POLE_PAIR = 14  # AK60-6: ERPM = 14 x rotor rpm


class CanServoDriver(CanLink):
    """Talks to the AK60-6 in servo mode over ``port`` (driver id ``driver_id``); callers pass the time."""

    LINK: ClassVar[str] = "can-servo"
    SAFE_BEHAVIOURS: ClassVar[tuple[str, ...]] = ("release", "brake", "short", "hold")

    def __init__(self, port: CanPort, driver_id: int = 1) -> None:
        """Prepare the IDs; nothing is sent until ``send``."""
        super().__init__(port, driver_id)
        self._status_id = can_servo.status_id(driver_id)
        self._current_id = can_servo.command_id(can_servo.PacketId.SET_CURRENT, driver_id)
        self._brake_id = can_servo.command_id(can_servo.PacketId.SET_CURRENT_BRAKE, driver_id)
        self._last_status_s: float | None = None

    def relink(self, port: CanPort) -> None:
        """Continue on a reopened port (the supervisor's latched fault is not cleared)."""
        self.port = port
        self._relinked()

    def poll(self, now_s: float) -> int:
        """Take every status frame waiting; return how many."""
        taken = 0
        fb, st = self.feedback, self.stats
        for frame in self._take(now_s):
            if not (frame.extended and frame.arbitration_id == self._status_id and len(frame.data) == 8):
                self.other_frames += 1
                continue
            s = can_servo.decode_status(frame.data)
            fb.position_rad = math.radians(s.position_deg)
            fb.erpm = int(s.speed_erpm)
            fb.current_a = s.current_a
            fb.fault = s.error
            fb.temp_motor_c = float(s.temperature_c)
            fb.temp_received_s = now_s
            fb.received_s = now_s
            if s.error:
                st.stale_replies += 1
            st.replies += 1
            last = self._last_status_s
            if last is not None and now_s - last > st.max_age_s:
                st.max_age_s = now_s - last
            self._last_status_s = now_s
            taken += 1
        return taken

    def send(self, current_a: float, now_s: float, *, brake: bool = False, request: bool = True) -> int:
        """Send SET_CURRENT (or SET_CURRENT_BRAKE); return the data bytes queued (0 if refused)."""
        packet = can_servo.PacketId.SET_CURRENT_BRAKE if brake else can_servo.PacketId.SET_CURRENT
        data = can_servo.encode_command(packet, abs(current_a) if brake else current_a)
        self.stats.requests += 1
        if not self._put(CanFrame(self._brake_id if brake else self._current_id, data, True), now_s):
            return 0
        self.last_command_s = now_s
        return len(data)

    def send_safe(self, command: SafeCommand, now_s: float, *, request: bool = True) -> int:
        """Send the safe state's command (SET_CURRENT 0, SET_CURRENT_BRAKE, SET_DUTY 0 or SET_POS); return the data
        bytes."""
        frame, _ = self._safe_frame(command)
        self.stats.requests += 1
        if not self._put(frame, now_s):
            return 0
        self.last_command_s = now_s
        return len(frame.data)

    def _safe_frame(self, command: SafeCommand) -> tuple[CanFrame, str]:
        """The servo-mode frame of a safe behaviour and its name."""
        P = can_servo.PacketId
        behaviour = command.behaviour
        if behaviour == "brake":
            packet, value = P.SET_CURRENT_BRAKE, abs(command.current_a)
            name = f"SET_CURRENT_BRAKE({value} A)"
        elif behaviour == "short":
            packet, value, name = P.SET_DUTY, 0.0, "SET_DUTY(0.0)"
        elif behaviour == "hold":
            packet, value = P.SET_POS, math.degrees(command.position_rad)
            name = f"SET_POS({value:.4f} deg)"
        else:
            packet, value, name = P.SET_CURRENT, 0.0, "SET_CURRENT(0.0 A)"
        frame = CanFrame(can_servo.command_id(packet, self.driver_id), can_servo.encode_command(packet, value), True)
        return frame, name

    def send_stop(self, now_s: float, command: SafeCommand | float, timeout_s: float = 0.5) -> SafeStop:
        """The stop path: the safe command (a number: the brake current), the brake after a zero current; wait until
        they have left the mailboxes."""
        cmd = stop_command(command)
        pairs: tuple[tuple[CanFrame, str], ...] = (self._safe_frame(cmd),)
        if cmd.behaviour == "brake":
            pairs = (self._safe_frame(SafeCommand("release")), *pairs)
        return self._stop(tuple(f for f, _ in pairs), tuple(n for _, n in pairs), now_s, timeout_s)

    def published(self) -> dict[str, object]:
        """The port's overruns and refusals, frames not from this motor."""
        return {"link": "can-servo", "rx_overruns": self.port.errors.overruns,
                "tx_refused_frames": self.port.errors.tx_refused, "other_frames": self.other_frames}


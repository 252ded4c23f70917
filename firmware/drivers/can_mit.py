"""AK-series driver over CAN in MIT mode: a torque command each period, the motor's reply to each.

Its scalings follow the profile's motor ([motor] ratings, firmware/motor_ratings.py): the MIT ranges the fields
are mapped onto, the output torque per q ampere (Kt x planetary) and the ERPM per output rad/s (planetary x
pole pairs); the defaults are the AK60-6's.

The firmware's controllers compute a q current; this driver sends it as MIT mode's feed-forward torque
(``t_ff = current x nm_per_a``, kp = kd = 0, so the motor's law is a pure torque command) and the brake
as a damping-only command (``kd = brake_kd``, t_ff = 0). Before the first command it sends "enter motor
mode" (PROTOCOLS.md G). Replies come on the master ID (0, as Ben Katz's mini-cheetah firmware the AK
series follows) with the driver id in byte 0; the motor answers every frame, the special ones too, in
order: ``requests`` and ``replies`` count the commands and their answers, ``max_age_s`` is the
longest command-to-reply time as the driver took them, a command sent while the previous one is
unanswered counts a ``missing_replies``. The safe behaviours MIT mode carries are release (zero torque),
damping (kp = 0, kd > 0; the profile's "brake" is the damper at ``brake_kd``) and the hold (kp > 0, kd > 0 about
the position the motor last reported, v = t_ff = 0). The stop path sends zero torque then "exit motor mode" (torque
off), or for damping and the hold their frame alone (it replaces any torque; a zero-torque frame of the same
identifier could leave a mailbox after it), which it leaves on.
"""

from __future__ import annotations

import math
from collections import deque
from typing import ClassVar

from firmware.config import FirmwareConfig
from firmware.drivers.can_link import CanLink
from firmware.drivers.motor_link import SafeStop, stop_command
from firmware.safe_state import SafeCommand
from hal.can import CanFrame, CanPort
from protocol import can_mit

__all__ = ["AK60_6_NM_PER_A", "MASTER_ID", "CanMitDriver"]

MASTER_ID = can_mit.MASTER_ID
AK60_6_NM_PER_A = 0.078 * 6.0  # kt x planetary ratio: output torque per q amp (profiles/plant_ak60_6.toml)
AK60_6_ERPM_PER_RAD_S = 60.0 / (2.0 * math.pi) * 6.0 * 14  # output rad/s -> ERPM (ratio 6, 14 pole pairs)


class CanMitDriver(CanLink):
    """Talks to an AK-series motor (the AK60-6 by default) in MIT mode over ``port``; callers pass the time."""

    LINK: ClassVar[str] = "can-mit"
    SAFE_BEHAVIOURS: ClassVar[tuple[str, ...]] = ("release", "brake", "damping", "hold")

    def __init__(self, port: CanPort, driver_id: int = 1, *, nm_per_a: float = AK60_6_NM_PER_A,
                 brake_kd: float = 1.0, limits: can_mit.MitLimits = can_mit.AK60_6,
                 erpm_per_rad_s: float = AK60_6_ERPM_PER_RAD_S) -> None:
        """Prepare the frames; "enter motor mode" goes out with the first command."""
        super().__init__(port, driver_id)
        self.nm_per_a = nm_per_a
        self.erpm_per_rad_s = erpm_per_rad_s
        self.brake_kd = brake_kd
        self.limits = limits
        self.entered = False
        self._outstanding: deque[tuple[float, bool]] = deque()  # (sent at, is a command) per frame to be answered

    @classmethod
    def on_port(cls, port: CanPort, config: FirmwareConfig) -> CanLink:
        """The driver for the profile's motor: its MIT ranges, torque per ampere and ERPM scaling."""
        m = config.motor
        return cls(port, config.motor_can_id, nm_per_a=m.output_nm_per_a,
                   limits=can_mit.MitLimits(m.mit_p_max_rad, m.mit_v_max_rad_s, m.mit_t_max_nm),
                   erpm_per_rad_s=m.erpm_per_output_rad_s)

    def relink(self, port: CanPort) -> None:
        """Continue on a reopened port: motor mode is entered again with the next command."""
        self.port = port
        self.entered = False
        self._outstanding.clear()
        self._relinked()

    def poll(self, now_s: float) -> int:
        """Take every reply waiting; return how many."""
        taken = 0
        fb, st = self.feedback, self.stats
        for frame in self._take(now_s):
            data = frame.data
            if frame.extended or frame.arbitration_id != MASTER_ID or len(data) not in (6, 8) \
                    or data[0] != self.driver_id:
                self.other_frames += 1
                continue
            r = can_mit.decode_reply(data, self.limits)
            fb.position_rad = r.p
            fb.erpm = int(r.v * self.erpm_per_rad_s)
            fb.current_a = r.t / self.nm_per_a
            fb.fault = r.error
            fb.temp_motor_c = float(r.temperature_c)
            fb.temp_received_s = now_s
            taken += 1
            if not self._outstanding:
                st.stale_replies += 1
                continue
            sent_s, command = self._outstanding.popleft()
            fb.received_s = now_s
            if command:
                st.replies += 1
                age = now_s - sent_s
                if age > st.max_age_s:
                    st.max_age_s = age
        return taken

    def _put_data(self, data: bytes, now_s: float) -> bool:
        return self._put(CanFrame(self.driver_id, data), now_s)

    def send(self, current_a: float, now_s: float, *, brake: bool = False, request: bool = True) -> int:
        """Send the torque (or damping) command, after "enter motor mode" the first time; return data bytes."""
        cmd = can_mit.MitCommand(kd=self.brake_kd) if brake else can_mit.MitCommand(t_ff=current_a * self.nm_per_a)
        return self._command(cmd, now_s)

    def send_safe(self, command: SafeCommand, now_s: float, *, request: bool = True) -> int:
        """Send the safe state's MIT command: zero torque (release), kp = 0 and the damper's kd, or the hold's kp and kd
        about its target; return the bytes."""
        return self._command(self._safe_command(command), now_s)

    def _safe_command(self, command: SafeCommand) -> can_mit.MitCommand:
        if command.behaviour == "damping":
            return can_mit.MitCommand(kd=command.kd)
        if command.behaviour == "hold":
            return can_mit.MitCommand(p_des=command.position_rad, kp=command.kp, kd=command.kd)
        if command.behaviour == "brake":
            return can_mit.MitCommand(kd=self.brake_kd)
        return can_mit.MitCommand()

    def _command(self, cmd: can_mit.MitCommand, now_s: float) -> int:
        """Send one MIT command, after "enter motor mode" the first time; return data bytes."""
        written = 0
        outstanding = self._outstanding
        if outstanding:  # unanswered by now: their replies are lost or late (a late one counts as stale)
            self.stats.missing_replies += sum(1 for _, command in outstanding if command)
            outstanding.clear()
        if not self.entered:
            if not self._put_data(can_mit.ENTER_MOTOR_MODE, now_s):
                return 0
            self.entered = True
            self._outstanding.append((now_s, False))  # the motor answers the special frame too
            written += 8
        if not self._put_data(can_mit.encode_command(cmd, self.limits), now_s):
            return written
        self.stats.requests += 1
        outstanding.append((now_s, True))
        self.last_command_s = now_s
        return written + 8

    def send_stop(self, now_s: float, command: SafeCommand | float, timeout_s: float = 0.5) -> SafeStop:
        """The stop path: zero torque, then exit motor mode (torque off), or for damping and the hold their frame alone
        (left on: a motor not in motor mode ignores it and stays released); wait until they have left."""
        cmd = stop_command(command)
        if cmd.behaviour in ("damping", "hold"):
            frame = CanFrame(self.driver_id, can_mit.encode_command(self._safe_command(cmd), self.limits))
            what = f"MIT command (damping, kp = 0, kd = {cmd.kd})" if cmd.behaviour == "damping" else \
                f"MIT command (hold at {cmd.position_rad:.4f} rad, kp = {cmd.kp}, kd = {cmd.kd})"
            return self._stop((frame,), (what,), now_s, timeout_s)
        zero = CanFrame(self.driver_id, can_mit.encode_command(can_mit.MitCommand(), self.limits))
        frames = (zero, CanFrame(self.driver_id, can_mit.EXIT_MOTOR_MODE))
        stop = self._stop(frames, ("MIT command (zero torque, kp = kd = 0)", "EXIT_MOTOR_MODE"), now_s, timeout_s)
        self.entered = False
        return stop

    def published(self) -> dict[str, object]:
        """The port's overruns and refusals, frames not from this motor."""
        return {"link": "can-mit", "rx_overruns": self.port.errors.overruns,
                "tx_refused_frames": self.port.errors.tx_refused, "other_frames": self.other_frames}

"""CubeMars AK60-6 over CAN (servo mode or MIT mode): the UART model's plant, meter and protections behind a CAN node.

The device owns an :class:`~hal.virtual.devices.ak60.Ak60` without a UART (``core``): the same shared
plant, current target, meter (temperatures, supply), command timeout and faults as the UART device. It
is a node of a :class:`~hal.virtual.can_bus.VirtualCanBus` that takes frames addressed to its
``driver_id`` (PROTOCOLS.md G; codecs in :mod:`protocol.can_servo` and ``can_mit``):

* servo mode: commands on 29-bit IDs ``(packet << 8) | driver_id`` (SET_CURRENT, SET_CURRENT_BRAKE,
  SET_DUTY, SET_RPM, SET_POS, SET_POS_SPD, SET_ORIGIN_HERE, with the manual's scalings: protocol.can_servo)
  act as their UART counterparts (amps in the config's ``current_convention``); a status frame (ID ``0x29xx``:
  output angle x 0.1 deg wrapped to +-3200 deg, ERPM, q current, motor temperature, the manual's error code) goes
  out every ``status_period_s`` (1..500 Hz, as the drive is configured) whether or not a command came. Unknown packet
  ids (opensourceleg's packet-7 "mode switch") are counted in ``unknown_packets`` and ignored; the MIT-style
  power-on/off/zero frames clients send on extended IDs are handled by ``_servo_special``;
* MIT mode: the special frames enter motor mode, exit it (torque off) and zero the position; a command
  (accepted in motor mode only) sets p_des, v_des, kp, kd, t_ff, and the law
  ``torque = kp (p_des - p) + kd (v_des - v) + t_ff`` (p, v: output angle from the zero, output
  velocity) is evaluated every ``inner_loop_period_s`` of the UART model's configuration (the driver's own
  loop rate), the torque becoming a q current through ``kt x gearbox ratio``. Every frame addressed to
  it is answered after ``reply_latency_s`` on the master ID 0 with ``[id, p, v, torque, temperature, error]``.

A command resets the command timeout (``timeout_s``): when it expires the core releases the motor and
MIT mode's law stops until the next command.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, Protocol

from hal.can import CanFrame
from hal.virtual.devices.ak60 import Ak60
from hal.virtual.devices.ak60_can_config import CURRENT_CONVENTIONS, MODES, Ak60CanConfig
from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.world import World
from hal.virtual.events import NEVER, EventDevice
from protocol import can_mit, can_servo
from protocol.vesc import OriginMode

__all__ = ["MODES", "Ak60Can", "Ak60CanConfig", "CanBusPort"]

class CanBusPort(Protocol):
    """Where the device's frames go: the virtual bus, or the wall-clock stand-in of `pafp emulate --can`."""

    def attach(self, node: Any) -> None:
        """Receive the frames of the other nodes."""
        ...

    def offer(self, node: Any, frame: CanFrame, ready: int) -> None:
        """Put frame on the wire from tick ready on."""
        ...


class Ak60Can(EventDevice):
    """The AK60-6 on a virtual CAN bus (see the module docstring)."""

    def __init__(self, world: World, bus: CanBusPort | None, can_config: Ak60CanConfig | None = None,
                 config: Ak60Config | None = None) -> None:
        """Build the core on world's plant and attach to bus (None: frames come through ``on_frame`` only)."""
        super().__init__()
        self.world = world
        self.can_config = cc = can_config if can_config is not None else Ak60CanConfig()
        self.core = core = Ak60(world, config, link=None)
        self.driver_id = cc.driver_id
        self.mode = cc.mode
        self.limits = cc.limits
        p = core.params
        self._nm_per_a = p.kt_nm_per_a * p.gearbox_ratio  # output torque per q amp
        self._gear = p.gearbox_ratio
        self._wire_a = CURRENT_CONVENTIONS[cc.current_convention]  # servo mode: wire amps per plant amp
        self._pole_pairs = p.pole_pairs
        self._rx: deque[tuple[int, CanFrame]] = deque()
        self._status_period = max(1, world.ticks(cc.status_period_s))
        self._status_at = self._status_period if cc.mode == "servo" else NEVER
        self._loop_period = max(1, world.ticks(core.config.inner_loop_period_s))
        self._mit_at = NEVER
        self.motor_mode = False
        self.mit_command: can_mit.MitCommand | None = None
        self.frames_in = 0
        self.frames_out = 0
        self.ignored_frames = 0
        self.unknown_packets = 0  # servo mode: packet ids outside the manual's 0..6 (e.g. opensourceleg's 7)
        self.special_frames = 0  # servo mode: MIT-style power-on/off/zero frames on extended IDs
        self.late_before = -1
        """Servo mode, a wall-clock server behind the clock: a status frame whose successor is also due before this
        tick would only go out late in a burst; it is superseded by the successor (not built, counted in
        ``status_superseded``). -1 (the virtual bench): every status frame is built."""
        self.status_superseded = 0
        self.bus: CanBusPort | None = bus
        if bus is not None:
            bus.attach(self)
        world.add(self)
        self._update_next()

    # ------------------------------------------------------------------ bus node
    def on_frame(self, frame: CanFrame, t: int) -> None:
        """A frame ended at t: keep it if it is addressed to this driver."""
        if self.mode == "mit":
            mine = not frame.extended and frame.arbitration_id == self.driver_id
        else:
            mine = frame.extended and (frame.arbitration_id & 0xFF) == self.driver_id and \
                frame.arbitration_id >> 8 != can_servo.STATUS_PACKET
        if not mine:
            return
        self._rx.append((t, frame))
        if t < self.next_event:
            self.next_event = t

    def tx_done(self, frame: CanFrame, t: int) -> None:
        """Our frame left (nothing to do: the driver has no mailbox limit in this model)."""

    def _out(self, frame: CanFrame, t: int) -> None:
        self.frames_out += 1
        if self.bus is not None:  # None: a silent motor (frames built and dropped)
            self.bus.offer(self, frame, t)

    # ------------------------------------------------------------------ events
    def _update_next(self) -> None:
        nxt = min(self._status_at, self._mit_at)
        if self._rx and self._rx[0][0] < nxt:
            nxt = self._rx[0][0]
        self.next_event = nxt

    def run_event(self) -> None:
        """Frames due, the MIT law's tick, the status frame."""
        t = self.next_event
        rx = self._rx
        while rx and rx[0][0] <= t:
            self._handle(rx.popleft()[1], t)
        if self._mit_at <= t:
            self._mit_tick(t)
        if self._status_at <= t:
            if t + self._status_period > self.late_before:
                self._status(t)
            else:
                self.status_superseded += 1
            self._status_at = t + self._status_period
        self.core._update_next()  # a command may have started or stopped the core's loop or timeout
        self._update_next()

    def _commanded(self, t: int) -> None:
        core = self.core
        core.stats.commands += 1
        core._timeout_at = t + core._timeout if core._timeout else NEVER
        core.timed_out = False
        core._update_next()

    def _handle(self, frame: CanFrame, t: int) -> None:
        self.frames_in += 1
        core = self.core
        core._sample(t)
        if self.mode == "mit":
            self._handle_mit(frame.data, t)
            return
        if self._servo_special(can_servo.special_frame(frame.arbitration_id, frame.data), t):
            return
        try:
            cmd = can_servo.decode_command(frame.arbitration_id, frame.data)
        except can_servo.UnknownPacket:
            self.unknown_packets += 1
            return
        except ValueError:
            self.ignored_frames += 1
            return
        P = can_servo.PacketId
        if cmd.packet == P.SET_ORIGIN_HERE and cmd.value not in (0, 1, 2):
            self.ignored_frames += 1
            return
        self._commanded(t)
        if cmd.packet == P.SET_CURRENT:
            core._drive_current(cmd.value / self._wire_a, t)
        elif cmd.packet == P.SET_CURRENT_BRAKE:
            core._drive_brake(cmd.value / self._wire_a, t)
        elif cmd.packet == P.SET_DUTY:
            core._drive_duty(cmd.value, t)
        elif cmd.packet == P.SET_RPM:
            core._drive_speed(cmd.value, t)
        elif cmd.packet == P.SET_POS:
            core._drive_position(math.radians(cmd.value), 0.0, 0.0, t)
        elif cmd.packet == P.SET_POS_SPD:
            core._drive_position(math.radians(cmd.value), cmd.speed_erpm, cmd.accel_erpm_s, t)
        elif cmd.packet == P.SET_ORIGIN_HERE:
            core._on_set_origin(OriginMode(int(cmd.value)), t)

    def _servo_special(self, special: str, t: int) -> bool:
        """A MIT-style special frame sent to the servo-mode drive (what opensourceleg's power_on/power_off and
        TMotorCANControl's servo manager send): True if it was one.

        The manual defines these frames for MIT mode only (5.3); read as servo packets they would be SET_DUTY with
        8 data bytes. The model takes them for what the clients mean: power-on changes nothing (a servo-mode drive
        is on and streams its status regardless), power-off releases the motor (torque off, as in MIT mode), the
        zero frame sets a temporary origin. None of them is a command for the command timeout. Counted in
        ``special_frames``.
        """
        if not special:
            return False
        self.special_frames += 1
        if special == "exit":
            self.core._release(t)
        elif special == "zero":
            self.core._on_set_origin(OriginMode.TEMPORARY, t)
        return True

    def _handle_mit(self, data: bytes, t: int) -> None:
        core = self.core
        special = can_mit.special_frame(data)
        if special == "enter":
            self.motor_mode = True
        elif special == "exit":
            self.motor_mode, self.mit_command, self._mit_at = False, None, NEVER
            core._release(t)
        elif special == "zero":
            core._on_set_origin(OriginMode.TEMPORARY, t)
        elif len(data) != 8 or not self.motor_mode:
            self.ignored_frames += 1
        else:
            self.mit_command = can_mit.decode_command(data, self.limits)
            self._commanded(t)
            self._mit_tick(t)
        self._reply(t + core._latency)

    def _output(self) -> tuple[float, float]:
        """Output angle from the zero (rad) and output velocity (rad/s) at the core's last sample."""
        core = self.core
        return math.radians(core.pid_pos_deg()), core._velocity / self._gear

    def _mit_tick(self, t: int) -> None:
        core = self.core
        cmd = self.mit_command
        if cmd is None or not self.motor_mode or core.timed_out or core.fault:
            self._mit_at = NEVER
            return
        core._sample(t)
        p, v = self._output()
        torque = cmd.kp * (cmd.p_des - p) + cmd.kd * (cmd.v_des - v) + cmd.t_ff
        core._drive_current(torque / self._nm_per_a, t)
        self._mit_at = t + self._loop_period

    def _reply(self, t: int) -> None:
        core = self.core
        p, v = self._output()
        reply = can_mit.MitReply(self.driver_id, p, v, core.meter.current_a * self._nm_per_a,
                                 int(round(core.meter.temp_motor_c)), can_servo.error_code(core.fault))
        self._out(CanFrame(can_mit.MASTER_ID, can_mit.encode_reply(reply, self.limits)), t)

    def _status(self, t: int) -> None:
        core = self.core
        core._sample(t)
        deg = (core.pid_pos_deg() + 3200.0) % 6400.0 - 3200.0
        erpm = core._velocity * 60.0 / (2.0 * math.pi) * self._pole_pairs
        status = can_servo.ServoStatus(deg, erpm, core.meter.current_a * self._wire_a,
                                       int(round(core.meter.temp_motor_c)), can_servo.error_code(core.fault))
        self._out(CanFrame(can_servo.status_id(self.driver_id), can_servo.encode_status(status), True), t)

"""CubeMars AK60-6 in servo mode over UART: a VESC-protocol device model on the shared plant.

The model is a :class:`~hal.virtual.uart.UartPeer` and a :class:`~hal.virtual.devices.world.World`
device. Bytes from the MCU are kept with their stop-bit end times and fed to the codec's streaming
decoder only when the world reaches them, in slices ending at each ``03`` byte
(:class:`~hal.virtual.devices.vesc_rx.TimedBytes`), so every decoded message gets the exact end time of
the byte that completed it. A request at tick ``t`` samples the plant at ``t`` and its reply starts at
``t + reply_latency``. Conventions (docs/devices.md):

* currents: the q-axis current is the plant's (it already models the FOC lag and the 22.7 A clamp);
  SET_CURRENT_REL is relative to that peak;
* the safe behaviours (SET_DUTY, SET_CURRENT_BRAKE, SET_HANDBRAKE) follow the winding's laws of
  :mod:`~hal.virtual.devices.ak60_winding`, evaluated every ``winding_period_s``: duty 0 shorts the phases,
  the brake regenerates at most the short-circuit current, the handbrake holds an open-loop current vector;
* ERPM = rotor rpm x 14; tachometer = 6 steps per electrical revolution since power-up;
* ``pid_pos`` = the actuator's output angle (rotor angle / 6, the planetary's output, before the belt)
  in degrees, multi-turn (single-turn 0..360 after SET_POS_SINGLE), minus the origin set by
  SET_POS_ORIGIN; ROTOR_POSITION streams it (SET_DETECT 4) at ``rotor_position_scale``;
* the command timeout (then ``timeout_brake_current_a``, VESC's ``timeout.c``), faults and the fault stop
  time follow VESC's ``mc_interface``.
"""

from __future__ import annotations

import heapq
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any, Final

from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.devices.ak60_loops import InnerLoops, LoopMode, degrees, radians
from hal.virtual.devices.ak60_meter import Ak60Meter
from hal.virtual.devices.ak60_values import ValueSource
from hal.virtual.devices.ak60_winding import Winding
from hal.virtual.devices.vesc_rx import TimedBytes
from hal.virtual.devices.world import NEVER, Link, World
from hal.virtual.events import EventDevice
from protocol import vesc
from protocol.vesc import DetectMode, OriginMode

__all__ = ["Ak60", "Ak60Stats", "DriveMode"]

log = logging.getLogger(__name__)

_MESSAGES: tuple[type[vesc.Message], ...] = (
    vesc.SetCurrent, vesc.SetCurrentRel, vesc.SetCurrentBrake, vesc.SetHandbrake, vesc.SetDuty, vesc.SetRpm,
    vesc.SetPos, vesc.SetPosSpd, vesc.Alive, vesc.SetDetect, vesc.SetPosOrigin, vesc.SetPosMulti,
    vesc.SetPosSingle, vesc.GetValuesSelective, vesc.GetValues, vesc.GetFwVersion,
)
"""The messages the driver acts on; a message's kind is its index here (Unknown ids are ignored). Commands
come first, then the requests (kinds from ``_FIRST_QUERY`` on), which do not reset the command timeout."""
_SET_CURRENT: Final = 0
_SET_CURRENT_REL: Final = 1
_SET_CURRENT_BRAKE: Final = 2
_SET_HANDBRAKE: Final = 3
_SET_DUTY: Final = 4
_SET_RPM: Final = 5
_SET_POS: Final = 6
_SET_POS_SPD: Final = 7
_ALIVE: Final = 8
_SET_DETECT: Final = 9
_SET_POS_ORIGIN: Final = 10
_SET_POS_MULTI: Final = 11
_SET_POS_SINGLE: Final = 12
_GET_VALUES_SELECTIVE: Final = 13
_GET_VALUES: Final = 14
_GET_FW_VERSION: Final = 15
_FIRST_QUERY: Final = _GET_VALUES_SELECTIVE
BUS_STEP_V: Final = 0.05
"""With a battery attached, the plant's bus voltage is updated when the meter's has moved by more than this
(0.2 % of 24 V: each update restarts the plant's step grid, so not at every sample)."""


class DriveMode(Enum):
    """What drives the current command."""

    RELEASED = "released"
    CURRENT = "current"
    LOOP = "loop"  # the speed or position loop (InnerLoops)
    DUTY = "duty"  # the winding's laws (ak60_winding.Winding)
    BRAKE = "brake"
    HANDBRAKE = "handbrake"


@dataclass
class Ak60Stats:
    """Counters of the driver model."""

    commands: int = 0
    requests: int = 0
    stream_frames: int = 0
    timeouts: int = 0
    faults: int = 0
    ignored_commands: int = 0
    bytes_out: int = 0


class Ak60(EventDevice):
    """The AK60-6 driver speaking VESC servo-mode packets on one UART, driving the world's plant."""

    def __init__(self, world: World, config: Ak60Config | None = None, *, link: Link | None = None) -> None:
        """Build the driver on world's plant; connect its transmit side with ``link`` (or ``connect``)."""
        super().__init__()
        self.world = world
        self.config = cfg = config if config is not None else Ak60Config()
        self.plant = plant = world.plant
        self.params = p = plant.params
        self._gear_ratio = p.gearbox_ratio
        self._peak_a = p.peak_current_a
        self.link = link
        self.decoder = vesc.Decoder("to-motor")
        self.stats = Ak60Stats()
        self.loops = InnerLoops(cfg, p)
        t0_s = plant.latest_time_s
        current_a, self._velocity, self._angle = plant.motor_sample(t0_s)
        self.meter = Ak60Meter(cfg, p, t0_s, self._angle, current_a, self._velocity)
        self._plant_bus_v = p.supply_voltage_v  # the bus voltage the plant was last given
        self._latency = world.ticks(cfg.reply_latency_s)
        self._stream_period = max(1, world.ticks(cfg.stream_period_s))
        self._loop_period = max(1, world.ticks(cfg.inner_loop_period_s))
        self._winding_period = max(1, world.ticks(cfg.winding_period_s))
        self.winding = Winding(p.ke_v_s_per_rad, p.phase_resistance_ohm, p.phase_inductance_h, p.pole_pairs)
        self._duty = 0.0
        # the plant's current lag over one winding period (the handbrake's vector is held in the stator frame:
        # its q projection follows the rotor at once, so the command leads the lag by one period)
        self._lag_decay = math.exp(-self._winding_period / world.f_hz / p.current_time_constant_s)
        self._timeout = world.ticks(cfg.timeout_s)
        self._fault_stop = world.ticks(cfg.fault_stop_time_s)
        # read at every event: copied from the (interpreted, frozen) configuration into native fields
        self._limits = (cfg.abs_max_current_a, cfg.temp_fet_max_c, cfg.temp_motor_max_c, cfg.min_input_voltage_v,
                        cfg.over_voltage_v(p.supply_voltage_v))
        self.mode = DriveMode.RELEASED
        self.fault = 0
        self.timed_out = False
        self.single_turn = False
        self.origin_deg = 0.0
        self.detect_mode: int = DetectMode.NONE
        self._brake_a = 0.0
        self._sampled_at = -1
        self._next_target: float | None = None
        self._rx = TimedBytes()
        self._timeout_at = NEVER
        self._loop_at = NEVER
        self._stream_at = NEVER
        self._fault_until = NEVER
        self._actions: list[tuple[int, int, Callable[[int], None]]] = []
        self._seq = 0
        self.values = ValueSource(self, self.meter, p.pole_pairs, cfg)
        self._kinds: dict[type, int] = {cls: kind for kind, cls in enumerate(_MESSAGES)}
        world.add(self)

    # ---------------------------------------------------------------- UART peer
    def connect(self, link: Link | None) -> None:
        """Send replies through link (None: replies are built and dropped)."""
        self.link = link

    def on_bytes(self, data: bytes, end_times_cycles: Sequence[int]) -> None:
        """Keep bytes from the MCU with their stop-bit end times; they are decoded when the world gets there."""
        if data and end_times_cycles[0] <= self.world.now:
            raise ValueError(f"byte end time {end_times_cycles[0]} is not after tick {self.world.now}, "
                             "which the world has already reached")
        self._rx.push(data, end_times_cycles)
        if self._rx.next_at < self.next_event:
            self.next_event = self._rx.next_at

    def advance_to(self, t_cycles: int) -> None:
        """Bring the whole world (this driver included) up to t_cycles."""
        self.world.advance_to(t_cycles)

    # ------------------------------------------------------------ fault injection
    def inject_fault(self, code: object, t_s: float, duration_s: float | None = None) -> None:
        """At t_s raise fault ``code`` (1..255, see FaultCode): motor released, reported, held duration_s."""
        if isinstance(code, bool) or not isinstance(code, int) or not 1 <= code <= 255:
            raise ValueError(f"fault code {code!r} out of range: an int in 1..255 (FaultCode)")
        fault: int = code
        hold = self._fault_stop if duration_s is None else self._check_duration(duration_s)
        self._schedule(t_s, lambda t: self._raise_fault(fault, t, hold))

    def set_supply_voltage(self, voltage_v: float, t_s: float) -> None:
        """From t_s on, the supply behind the source resistance is voltage_v (e.g. to provoke UNDER_VOLTAGE)."""
        if not (math.isfinite(voltage_v) and 0.0 <= voltage_v <= 100.0):
            raise ValueError(f"voltage_v = {voltage_v!r} out of range [0, 100] V")
        self._schedule(t_s, lambda t: setattr(self.meter, "v_supply_v", float(voltage_v)))

    def _check_duration(self, duration_s: float) -> int:
        if not (math.isfinite(duration_s) and duration_s > 0.0):
            raise ValueError(f"duration_s = {duration_s!r} out of range: finite and > 0")
        return max(1, self.world.ticks(duration_s))

    def _schedule(self, t_s: float, action: Callable[[int], None]) -> None:
        t = self.world.ticks(t_s)
        if t <= self.world.now:
            raise ValueError(f"t_s = {t_s!r} is in the past: the world is already at "
                             f"{self.world.seconds(self.world.now)!r} s")
        self._seq += 1
        heapq.heappush(self._actions, (t, self._seq, action))
        self._update_next()

    # --------------------------------------------------------------- world device
    def _update_next(self) -> None:
        nxt = min(min(self._rx.next_at, self._timeout_at), min(self._loop_at, self._stream_at))
        nxt = min(nxt, self._fault_until)
        if self._actions and self._actions[0][0] < nxt:
            nxt = self._actions[0][0]
        self.next_event = nxt

    def run_event(self) -> None:
        """Run everything scheduled at ``next_event``: actions, frames, timers; the plant is sampled once."""
        t = self.next_event
        actions = self._actions
        while actions and actions[0][0] <= t:
            heapq.heappop(actions)[2](t)
        if self._fault_until <= t:
            self.fault, self._fault_until = 0, NEVER
        if self._rx.next_at <= t:
            self._receive(t)
        if self._timeout_at <= t:
            self._timeout_at, self.timed_out = NEVER, True
            self.stats.timeouts += 1
            self._on_timeout(t)
        if self._loop_at <= t:
            self._loop_tick(t)
        if self._stream_at <= t:
            self._stream_tick(t)
        self._sample(t)
        if not self.fault:
            self._check_limits(t)
        self._update_next()

    def _sample(self, t: int) -> None:
        """Sample the plant at t once (after any input at t: the state at t is the same, and cheaper).

        The meter integrates the interval ending at t with the target held over it; a target set by a
        command at t before the sample waits in ``_next_target`` and takes over after it.
        """
        if self._sampled_at == t:
            return
        self._sampled_at = t
        t_s = t / self.world.f_hz
        i, w, self._angle = self.plant.motor_sample(t_s)
        self._velocity = w
        meter = self.meter
        meter.sample(t_s, i, w, self._angle)
        if meter.battery is not None and abs(meter.v_in_v - self._plant_bus_v) > BUS_STEP_V:
            self._plant_bus_v = meter.v_in_v  # the plant's back-EMF limit follows the sagging bus
            self.plant.set_supply_voltage(max(meter.v_in_v, 0.1), t_s)
        if self._next_target is not None:
            meter.target_a, self._next_target = self._next_target, None

    def _target(self, current_a: float, t: int) -> None:
        """From t on the q current heads for current_a (clamped to the peak; 0 when unpowered)."""
        peak = self._peak_a
        value = max(-peak, min(peak, current_a)) if self.plant.powered else 0.0
        if self._sampled_at == t:
            self.meter.target_a = value
        else:
            self._next_target = value

    def _receive(self, t: int) -> None:
        messages = self.decoder.feed(self._rx.take())
        kinds = self._kinds
        for msg in messages:
            kind = kinds.get(type(msg), -1)
            if kind < 0:
                continue  # Unknown ids are counted by the decoder and ignored
            if kind >= _FIRST_QUERY:
                self.stats.requests += 1
            else:
                self.stats.commands += 1
                self._timeout_at = t + self._timeout if self._timeout else NEVER
                self.timed_out = False
            self._handle(kind, msg, t)

    def _handle(self, kind: int, msg: Any, t: int) -> None:
        """Act on msg, a message of the given kind (an index into ``_MESSAGES``), received at t."""
        if kind == _SET_CURRENT:
            self._drive_current(msg.current_a, t)
        elif kind == _GET_VALUES_SELECTIVE:
            self._on_selective(msg.mask, t)
        elif kind == _SET_CURRENT_REL:
            self._drive_current(msg.current_rel * self._peak_a, t)
        elif kind == _SET_CURRENT_BRAKE:
            self._drive_brake(msg.current_a, t)
        elif kind == _SET_HANDBRAKE:
            self._drive_winding(DriveMode.HANDBRAKE, msg.current_a, t)
        elif kind == _SET_DUTY:
            self._drive_duty(msg.duty, t)
        elif kind == _SET_RPM:
            self._drive_speed(msg.erpm, t)
        elif kind == _SET_POS:
            self._drive_position(msg.position_rad, 0, 0, t)
        elif kind == _SET_POS_SPD:
            self._drive_position(msg.position_rad, msg.erpm, msg.accel_erpm_per_s, t)
        elif kind == _SET_DETECT:
            self._on_set_detect(msg.mode, t)
        elif kind == _SET_POS_ORIGIN:
            self._on_set_origin(msg.mode, t)
        elif kind == _SET_POS_MULTI or kind == _SET_POS_SINGLE:
            self.single_turn = kind == _SET_POS_SINGLE
        elif kind == _GET_VALUES:
            self._on_get_values(t)
        elif kind == _GET_FW_VERSION:
            cfg = self.config
            self._reply(vesc.FwVersion(cfg.fw_major, cfg.fw_minor, cfg.hw_name, cfg.uuid), t)
        # _ALIVE only resets the timeout (in _receive)

    # ------------------------------------------------------------------- driving
    def _apply(self, current_a: float, t: int) -> None:
        """Put a q-current command on the plant from tick t."""
        self.plant.set_current_command(current_a, t / self.world.f_hz)

    def _accepts(self) -> bool:
        if self.fault:
            self.stats.ignored_commands += 1
            return False
        return True

    def _drive_current(self, current_a: float, t: int) -> None:
        if self._accepts():
            self.mode, self._loop_at = DriveMode.CURRENT, NEVER
            self._apply(current_a, t)
            self._target(current_a, t)

    def _drive_winding(self, mode: DriveMode, value: float, t: int) -> None:
        """Duty (value: the duty cycle), brake or handbrake (value: the current) from t, by the winding's laws."""
        if self._accepts():
            if mode is DriveMode.DUTY:
                cap = self.config.max_duty
                self._duty = max(-cap, min(cap, value))
            else:
                self._brake_a = min(abs(value), self._peak_a)
            self.mode = mode
            self._winding_tick(t)
            self._update_next()  # called from the CAN node's event too: the world reads next_event

    def _drive_loop(self, t: int, start: Callable[[float, float], None]) -> None:
        if self._accepts():
            self._sample(t)
            start(self.meter.current_a, self._velocity)
            self.mode = DriveMode.LOOP
            self._loop_tick(t)
            self._update_next()

    def _drive_duty(self, duty: float, t: int) -> None:
        self._drive_winding(DriveMode.DUTY, duty, t)

    def _drive_brake(self, current_a: float, t: int) -> None:
        self._drive_winding(DriveMode.BRAKE, current_a, t)

    def _drive_speed(self, erpm: float, t: int) -> None:
        self._drive_loop(t, lambda i, w: self.loops.start_speed(erpm, i, w))

    def _drive_position(self, position_rad: float, erpm: float, accel: float, t: int) -> None:
        self._sample(t)
        target_deg = degrees(position_rad)
        gear = self._gear_ratio
        if self.single_turn:
            delta = (target_deg - self.pid_pos_deg() + 180.0) % 360.0 - 180.0
            rotor_target = self._angle + radians(delta) * gear
        else:
            rotor_target = radians(target_deg + self.origin_deg) * gear
        self._drive_loop(t, lambda i, w: self.loops.start_position(rotor_target, i, w, erpm, accel))

    def _loop_tick(self, t: int) -> None:
        mode = self.mode
        if mode is not DriveMode.LOOP:
            if mode is DriveMode.DUTY or mode is DriveMode.BRAKE or mode is DriveMode.HANDBRAKE:
                self._winding_tick(t)
            else:
                self._loop_at = NEVER
            return
        self._sample(t)
        dt_s = self._loop_period / self.world.f_hz
        current = self.loops.current_a(dt_s, self._angle, self._velocity)
        self._apply(current, t)
        self._target(current, t)
        self._loop_at = t + self._loop_period

    def _winding_tick(self, t: int) -> None:
        """The winding's law of the present mode at the rotor's angle and speed at t, until the next tick."""
        self._sample(t)
        mode, winding = self.mode, self.winding
        if mode is DriveMode.DUTY:
            current = winding.duty_current_a(self._duty, self.meter.v_in_v, self._velocity)
        elif mode is DriveMode.BRAKE:
            current = winding.brake_current_a(self._brake_a, self._velocity)
        else:  # the vector's projection at the next tick, reached through the current loop's lag (deadbeat)
            h = self._winding_period / self.world.f_hz
            current = winding.handbrake_current_a(self._brake_a, self._angle + self._velocity * h)
            decay = self._lag_decay
            current = (current - self.meter.current_a * decay) / (1.0 - decay)
        self._apply(current, t)
        self._target(current, t)
        self._loop_at = t + self._winding_period

    def _on_timeout(self, t: int) -> None:
        """No command for ``timeout_s``: VESC's timeout.c brakes with ``timeout_brake_current`` (0: releases)."""
        brake_a = self.config.timeout_brake_current_a
        log.debug("ak60: command timeout at %.6f s, %s", self.world.seconds(t),
                  f"brake {brake_a} A" if brake_a > 0.0 else "motor released")
        if brake_a > 0.0 and not self.fault:
            self._drive_winding(DriveMode.BRAKE, brake_a, t)
        else:
            self._release(t)

    def _release(self, t: int) -> None:
        self.mode, self._loop_at = DriveMode.RELEASED, NEVER
        self._apply(0.0, t)
        self._target(0.0, t)

    def _raise_fault(self, code: int, t: int, hold_ticks: int) -> None:
        self.fault = code
        self._fault_until = t + hold_ticks
        self.stats.faults += 1
        log.info("ak60: fault %d at %.6f s", code, self.world.seconds(t))
        self._release(t)

    def _check_limits(self, t: int) -> None:
        m = self.meter
        max_current_a, temp_fet_max_c, temp_motor_max_c, min_input_voltage_v, max_input_voltage_v = self._limits
        if abs(m.current_a) > max_current_a:
            code = vesc.FaultCode.ABS_OVER_CURRENT
        elif m.temp_fet_c > temp_fet_max_c:
            code = vesc.FaultCode.OVER_TEMP_FET
        elif m.temp_motor_c > temp_motor_max_c:
            code = vesc.FaultCode.OVER_TEMP_MOTOR
        elif m.v_in_v < min_input_voltage_v:
            code = vesc.FaultCode.UNDER_VOLTAGE
        elif m.v_in_v > max_input_voltage_v:
            code = vesc.FaultCode.OVER_VOLTAGE
        else:
            return
        self._raise_fault(code, t, self._fault_stop)

    # ----------------------------------------------------------------- reporting
    def pid_pos_deg(self) -> float:
        """Actuator output angle (rotor / 6) in degrees at the last sample, minus the origin."""
        deg = degrees(self._angle / self._gear_ratio) - self.origin_deg
        return deg % 360.0 if self.single_turn else deg

    def position_error_deg(self) -> float:
        """Position-loop error (target - present) in pid_pos degrees; 0 outside position mode."""
        if self.mode is not DriveMode.LOOP or self.loops.mode is not LoopMode.POSITION:
            return 0.0
        return degrees((self.loops.position_target_rad - self._angle) / self._gear_ratio)

    def _on_set_origin(self, mode: int, t: int) -> None:
        self._sample(t)
        if mode == OriginMode.RESTORE_DEFAULT:
            self.origin_deg = 0.0
        else:
            self.origin_deg = degrees(self._angle / self._gear_ratio)

    def _on_set_detect(self, mode: int, t: int) -> None:
        streams = mode in (DetectMode.ENCODER, DetectMode.PID_POS, DetectMode.PID_POS_ERROR)
        if streams and self._stream_at == NEVER:
            self._stream_at = t + self._stream_period
        elif not streams:
            self._stream_at = NEVER
        self.detect_mode = mode

    def _stream_tick(self, t: int) -> None:
        self._sample(t)
        mode = self.detect_mode
        if mode == DetectMode.ENCODER:
            deg = degrees(self._angle) % 360.0
        elif mode == DetectMode.PID_POS_ERROR:
            deg = self.position_error_deg()
        else:
            deg = self.pid_pos_deg()
        scale = self.config.rotor_position_scale
        limit = (2**31 - 1) / scale
        deg = max(-limit, min(limit, deg))
        self._send(vesc.RotorPosition(radians(deg), scale).encode(), t)
        self.stats.stream_frames += 1
        self._stream_at = t + self._stream_period

    def _on_selective(self, mask: int, t: int) -> None:
        self._sample(t)
        payload = self.values.selective_payload(mask)
        self._send(vesc.encode_frame(payload), t + self._latency)

    def _on_get_values(self, t: int) -> None:
        self._sample(t)
        self._send(vesc.encode_frame(self.values.values_payload()), t + self._latency)

    def _reply(self, message: Any, t: int) -> None:
        self._send(message.encode(), t + self._latency)

    def _send(self, frame: bytes, start: int) -> None:
        self.stats.bytes_out += len(frame)
        if self.link is not None:
            self.link.transmit_to_mcu(frame, start)

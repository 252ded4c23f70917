"""The safety supervisor: limits, timeouts and faults latch the firmware into a safe state.

The supervisor is pure logic: the tasks hand it what they saw (`SafetyInputs`) once per control
period, and it answers with the state and, in the safe state, what the motor must be told (the profile's
``safe_state``, firmware/safe_state.py). A trip latches: only `reset` (a power cycle) leaves SAFE.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from firmware.control.pid import parallel_spring_torque_nm
from firmware.safe_state import BEHAVIOURS, SafeCommand, SafePolicy
from firmware.safety_limits import SafetyLimits, ThermalLimits
from protocol.rvc import RVC_RATE_HZ
from protocol.telemetry import FaultReason, SupervisorState

log = logging.getLogger(__name__)

__all__ = ["FaultReason", "FrozenImu", "JamCheck", "JamObserver", "MotorEncoderGap", "SafetyInputs", "SafetyLimits",
           "SafeCommand", "Supervisor", "SupervisorState", "ThermalGuard", "ThermalLimits"]


@dataclass
class SafetyInputs:
    """What the supervisor looks at in one check (times in seconds since boot, None = never)."""

    now_s: float
    angle_rad: float
    current_meas_a: float = 0.0
    last_motor_reply_s: float | None = None
    last_command_s: float | None = None
    last_imu_frame_s: float | None = None
    last_imu_poll_s: float | None = None  # when the IMU port was last read (None: take now)
    imu_frozen_s: float = 0.0  # how long the IMU's frames have been bit-identical while the encoder moved (FrozenImu)
    jam_s: float = 0.0  # how long the motor has pushed at its limit without motion against a moving reference
    jam_dorsiflexing: bool = False  # that push is towards dorsiflexion, with the reference (judged in stance too)
    loaded: bool = False  # the foot in stance (the controller's stance flag): a plantarflexing jam is judged in swing
    jam_torque_s: float = 0.0  # how long the torque balance has missed a moment on a slow foot (JamObserver)
    jam_residual_nm: float = 0.0  # that missing moment, and the bound it exceeded
    jam_bound_nm: float = 0.0
    disagreement_rad: float = 0.0
    motor_fault_code: int = 0
    deadline_miss_streak: int = 0
    estop_pressed: bool = False
    link_lost: bool = False
    motor_encoder_gap_rad: float = 0.0
    motor_temp_c: float = math.nan  # the motor's winding temperature, fresh (ThermalGuard.fresh_c) or NaN


class Supervisor:
    """Latched safety state machine: INIT until the sensors speak, RUN, then SAFE on any fault."""

    def __init__(self, limits: SafetyLimits | None = None, thermal: ThermalLimits | None = None) -> None:
        """Start in INIT with no fault."""
        self.limits = limits or SafetyLimits()
        self.thermal = thermal or ThermalLimits()
        self._fault_c = self.thermal.fault_c
        self.state = SupervisorState.INIT
        # any behaviour until the firmware binds the policy to its motor link's offer (FirmwareTasks does)
        self.policy = SafePolicy.of(self.limits, BEHAVIOURS, "any")
        self.reason = FaultReason.NONE
        self.tripped_at_s: float | None = None
        self.detail = ""  # what was measured when it tripped (e.g. "command age 23.4 ms > 20.0 ms")
        self.trips: list[tuple[float, str, str]] = []  # (time s, reason, detail) of each trip, for the trace
        self.on_trip: Callable[[], None] | None = None  # told of each trip (the trace's watch of the safe command)
        # On a host's wall clock a late job is the host's stall, not the firmware's defect: a miss streak
        # is then counted as a warning (the command and feedback ages judge whether it endangered anyone).
        self.latch_deadline_misses = True
        self.miss_streak_warnings = 0
        self._streak_warned = False

    @property
    def healthy(self) -> bool:
        """True while not in the safe state (the watchdog may be kicked)."""
        return self.state is not SupervisorState.SAFE

    def trip(self, reason: FaultReason, now_s: float) -> None:
        """Latch the safe state for `reason` (a second trip keeps the first reason)."""
        if self.state is SupervisorState.SAFE:
            return
        self.state = SupervisorState.SAFE
        self.reason = reason
        self.tripped_at_s = now_s
        self.trips.append((now_s, reason.name, self.detail))
        if self.on_trip is not None:
            self.on_trip()
        log.warning("safe state at %.4f s: %s %s", now_s, reason.name, self.detail)

    def check(self, x: SafetyInputs) -> SupervisorState:
        """Evaluate every rule once; return the (possibly new) state."""
        state = self.state
        if state is _SAFE:
            return state
        reason = self._first_fault(x)
        if reason is not _NONE:
            self.detail = self._describe(reason, x)
            self.trip(reason, x.now_s)
        elif state is _INIT and x.last_motor_reply_s is not None and x.last_imu_frame_s is not None:
            self.state = _RUN
        return self.state

    def safe_command(self, now_s: float, *, loaded: bool = False, drive_fault: bool = False,
                     position_rad: float | None = None) -> SafeCommand:
        """In SAFE: the policy's drive command now (``brake``: zero current for `brake_delay_s`, then the brake;
        ``hold``: at position_rad, the drive's reported position while fresh)."""
        return self.policy.command(now_s, self.tripped_at_s, loaded=loaded, drive_fault=drive_fault,
                                   position_rad=position_rad)

    def _describe(self, reason: FaultReason, x: SafetyInputs) -> str:
        """The measured value behind a trip and its limit (ages in ms), for the log and the summary."""
        lim = self.limits
        ages = {FaultReason.COMMAND_STALE: (x.last_command_s, lim.command_timeout_s, "command"),
                FaultReason.MOTOR_TIMEOUT: (x.last_motor_reply_s, lim.motor_timeout_s, "motor feedback"),
                FaultReason.IMU_TIMEOUT: (x.last_imu_frame_s, lim.imu_timeout_s, "IMU frame")}
        if reason is FaultReason.IMU_FROZEN:
            return f"IMU frames bit-identical for {x.imu_frozen_s * 1e3:.1f} ms, {lim.imu_timeout_s * 1e3:.1f} ms " \
                   f"of frames at {RVC_RATE_HZ} Hz " \
                   f"while the encoder moved more than {math.degrees(lim.imu_frozen_motion_rad):.2f} deg"
        if reason is FaultReason.MOTOR_JAM and x.jam_torque_s > lim.jam_torque_time_s:
            return f"torque balance: {x.jam_residual_nm:+.1f} N m unexplained > {x.jam_bound_nm:.1f} N m for " \
                   f"{x.jam_torque_s * 1e3:.1f} ms > {lim.jam_torque_time_s * 1e3:.1f} ms on a foot slower than " \
                   f"{lim.jam_slow_rad_s:.2f} rad/s"
        if reason is FaultReason.MOTOR_JAM:
            return f"current at {lim.jam_current_share:.0%} of its limit, the encoder within " \
                   f"{math.degrees(lim.jam_still_rad):.2f} deg, the reference moving, for {x.jam_s * 1e3:.1f} ms > " \
                   f"{lim.jam_time_s * 1e3:.1f} ms " \
                   f"({'dorsiflexing' if x.jam_dorsiflexing else 'plantarflexing in swing'})"
        if reason in ages:
            last_s, limit_s, what = ages[reason]
            if last_s is None:
                return f"no {what} within the {lim.startup_grace_s * 1e3:.0f} ms start-up grace"
            return f"{what} age {(x.now_s - last_s) * 1e3:.1f} ms > {limit_s * 1e3:.1f} ms"
        if reason is FaultReason.SENSOR_DISAGREEMENT:
            return f"encoder/IMU disagreement {math.degrees(x.disagreement_rad):.2f} deg > " \
                   f"{math.degrees(lim.disagreement_rad):.2f} deg"
        if reason is FaultReason.MOTOR_ENCODER_DISAGREEMENT:
            return f"encoder/motor-position disagreement {math.degrees(x.motor_encoder_gap_rad):.2f} deg > " \
                   f"{math.degrees(lim.motor_encoder_gap_rad):.2f} deg"
        if reason is FaultReason.ANGLE_LIMIT:
            return f"angle {math.degrees(x.angle_rad):.2f} deg outside " \
                   f"{math.degrees(lim.angle_min_rad):.1f}..{math.degrees(lim.angle_max_rad):.1f} deg"
        if reason is FaultReason.OVER_TEMPERATURE:
            return f"motor temperature {x.motor_temp_c:.1f} C > {self._fault_c:.1f} C"
        if reason is FaultReason.CURRENT_LIMIT:
            return f"current {x.current_meas_a:.2f} A beyond {lim.current_limit_a:.1f} A"
        return ""

    def _first_fault(self, x: SafetyInputs) -> FaultReason:
        """The highest-ranked fault present in `x`, or NONE.

        A source is stale when silent longer than its timeout; one never heard from counts as stale
        once the start-up grace has passed. The motor's command is stale when the last one the port took
        whole is older than ``command_timeout_s`` (the motor has been running on it unsupervised).
        """
        lim = self.limits
        if x.estop_pressed:
            return FaultReason.ESTOP
        if x.link_lost:
            return FaultReason.LINK_LOST
        if x.motor_fault_code:
            return FaultReason.MOTOR_FAULT
        if x.deadline_miss_streak >= lim.deadline_miss_streak:
            if self.latch_deadline_misses:
                return FaultReason.DEADLINE_MISSES
            if not self._streak_warned:
                self._streak_warned = True
                self.miss_streak_warnings += 1
                log.warning("deadline-miss streak %d at %.4f s (host stall: a warning)", x.deadline_miss_streak,
                            x.now_s)
        elif self._streak_warned:
            self._streak_warned = False
        now_s = x.now_s
        last_s = x.last_command_s
        if last_s is not None and now_s - last_s > lim.command_timeout_s:
            return FaultReason.COMMAND_STALE
        last_s = x.last_motor_reply_s
        if (now_s > lim.startup_grace_s) if last_s is None else (now_s - last_s > lim.motor_timeout_s):
            return FaultReason.MOTOR_TIMEOUT
        last_s = x.last_imu_frame_s
        if last_s is None:
            if now_s > lim.startup_grace_s:
                return FaultReason.IMU_TIMEOUT
        else:  # silent up to the last read of its port (a host's stall of the IMU task is not the IMU's silence),
            poll_s = x.last_imu_poll_s  # and never longer than twice the limit, read or not
            age_s = (now_s if poll_s is None else poll_s) - last_s
            if age_s > lim.imu_timeout_s or now_s - last_s > 2.0 * lim.imu_timeout_s:
                return FaultReason.IMU_TIMEOUT
        if x.motor_temp_c > self._fault_c:  # NaN (no fresh reading) never latches
            return FaultReason.OVER_TEMPERATURE
        if self.state is _RUN:
            if not lim.angle_min_rad <= x.angle_rad <= lim.angle_max_rad:
                return FaultReason.ANGLE_LIMIT
            if abs(x.current_meas_a) > lim.current_limit_a:
                return FaultReason.CURRENT_LIMIT
            if x.disagreement_rad > lim.disagreement_rad:
                return FaultReason.SENSOR_DISAGREEMENT
            if x.motor_encoder_gap_rad > lim.motor_encoder_gap_rad:
                return FaultReason.MOTOR_ENCODER_DISAGREEMENT
            # identical frames come at the IMU's rate, so the frozen time grows in frame periods: imu_timeout_s of
            # them is reached at the frame that ends it, give or take its arrival's jitter (half a period)
            if x.imu_frozen_s > lim.imu_timeout_s - _HALF_FRAME_S:
                return FaultReason.IMU_FROZEN
            # in stance only a dorsiflexing push: the ground's moment helps it, so a still foot is jammed, where a
            # plantarflexing one may be a push-off the motor is too weak for (docs/safety.md, "Jam")
            if (x.jam_dorsiflexing or not x.loaded) and x.jam_s > lim.jam_time_s:
                return FaultReason.MOTOR_JAM
            if x.jam_torque_s > lim.jam_torque_time_s:  # the torque balance (JamObserver), in stance and swing
                return FaultReason.MOTOR_JAM
        return _NONE


class MotorEncoderGap:
    """Plausibility of the output encoder: its motion against the motor's own position seen through the belt.

    The AK60-6 reports the planetary's output angle with its replies; divided by the belt ratio it is a second,
    independent measure of the ankle's motion. Both are zeroed at the first reply; ``update`` returns how far they
    have parted. Only a new reply at most ``fresh_s`` old is compared (the encoder is read now): stale feedback is
    the stale-data check's hazard (MOTOR_TIMEOUT), so without a fresh reply the last gap is kept. A stuck,
    glitching or reversed encoder parts them within a few degrees of motion, long before the IMU (lagged, 100 Hz,
    biased) can tell (docs/safety.md, "Mends").
    """

    def __init__(self, belt_ratio: float, fresh_s: float = 0.002) -> None:
        """Nothing seen yet."""
        self.belt_ratio = belt_ratio
        self.fresh_s = fresh_s
        self.gap_rad = 0.0
        self._seeded = False
        self._encoder0 = 0.0
        self._motor0 = 0.0
        self._reply_s = -1.0

    def update(self, encoder_rad: float, motor_position_rad: float, reply_s: float | None, now_s: float) -> float:
        """|encoder motion - motor motion / belt ratio| at the newest fresh reply (0.0 before the first one)."""
        if reply_s is None or reply_s == self._reply_s or now_s - reply_s > self.fresh_s:
            return self.gap_rad
        self._reply_s = reply_s
        if not self._seeded:
            self._seeded = True
            self._encoder0, self._motor0 = encoder_rad, motor_position_rad
        self.gap_rad = abs((encoder_rad - self._encoder0) - (motor_position_rad - self._motor0) / self.belt_ratio)
        return self.gap_rad


class FrozenImu:
    """An IMU stuck at a plausible value: its frames keep coming, index counting, with bit-identical measurements.

    A healthy BNO08x's pitch resolves 0.01 deg and its accelerations 1 mg, so while the foot turns by a degree
    its frames cannot repeat; at rest they may. ``update`` returns how long identical frames have kept coming
    (from the change to the newest frame: a silent IMU is IMU_TIMEOUT's), counted only once the encoder has
    moved more than ``motion_rad`` since they last changed (else 0).
    """

    def __init__(self, motion_rad: float) -> None:
        """Nothing seen yet."""
        self.motion_rad = motion_rad
        self._changed_s: float | None = None
        self._encoder0 = 0.0

    def update(self, changed_s: float | None, last_frame_s: float | None, encoder_rad: float) -> float:
        """Seconds of identical frames (the content last changed at changed_s, the newest frame came at last_frame_s),
        if the encoder has moved enough since the change; else 0."""
        if changed_s is None or last_frame_s is None:
            return 0.0
        if changed_s != self._changed_s:
            self._changed_s = changed_s
            self._encoder0 = encoder_rad
            return 0.0
        if abs(encoder_rad - self._encoder0) > self.motion_rad:
            return last_frame_s - changed_s
        return 0.0


class JamCheck:
    """A jammed output: the current command near its limit, the encoder still, the reference moving.

    Each alone is normal (a loaded stance saturates the current; a foot at rest is still; the gait's reference
    moves); together they mean the motor pushes against something that does not give. Still is judged on the
    encoder's angle (within ``still_rad`` of where the window began), not its differenced speed, which a
    single count's flicker on a stop's compliance swings by 1.6 rad/s. ``update`` returns how long all three
    have held, with the push's direction in ``dorsiflexing`` (docs/safety.md, "Jam").
    """

    def __init__(self, current_share: float, still_rad: float, reference_rad_s: float) -> None:
        """Near the limit: at least current_share of it; still: within still_rad; moving: above reference_rad_s."""
        self.current_share = current_share
        self.still_rad = still_rad
        self.reference_rad_s = reference_rad_s
        self._since: float | None = None
        self._angle0 = 0.0
        self.dorsiflexing = False  # the window's push: towards dorsiflexion, where the reference goes

    def update(self, now_s: float, current_a: float, limit_a: float, angle_rad: float,
               reference_velocity_rad_s: float) -> float:
        """Seconds the three conditions have held up to now_s (0.0 when one does not)."""
        if abs(current_a) < self.current_share * limit_a or abs(reference_velocity_rad_s) <= self.reference_rad_s:
            self._since = None
            return 0.0
        dorsiflexing = current_a > 0.0 and reference_velocity_rad_s > 0.0  # pushing the way the reference goes
        if self._since is None or abs(angle_rad - self._angle0) > self.still_rad \
                or dorsiflexing != self.dorsiflexing:  # (re)start: it moved, or the push turned
            self._since, self._angle0, self.dorsiflexing = now_s, angle_rad, dorsiflexing
        return now_s - self._since


class JamObserver:
    """A jammed output by the ankle's torque balance: a moment the foot's model does not explain, on a slow foot.

    The moments the firmware can measure act on the foot: the motor's (the measured current times Kt N eta, or
    divided by the backdriven share when it opposes the motion, as the feedforward takes it), the parallel spring's
    at the encoder's angle, the foot's weight and the ground's (the pylon load cell's moment). Their sum changes the
    foot's angular momentum J w, with w the encoder's speed. A momentum observer (De Luca and Mattone, ICRA 2003;
    Haddadin et al., IEEE T-RO 33(6) 2017) compares the two without differentiating the encoder twice:

        r = K (J w - J w0 - integral(moments + r) dt)

    follows, with time constant 1/K, the moment nothing measured applies: a jam's reaction. It is judged against a
    bound for what the model misses: ``residual_nm`` (friction, the filtered speed's lag), ``share`` of the measured
    moments (Kt, efficiency, the spring's rate and the load cell's calibration within a few per cent) and
    ``per_n_m`` times the axial force (the ground's shear force acts on the ankle below the load cell: its moment
    there is the shear times the cell's height above the ankle, which the cell does not report). ``update`` returns
    how long the residual has stayed beyond that bound while the encoder was slower than ``slow_rad_s``
    (docs/safety.md, "Jam").
    """

    def __init__(self, inertia_kg_m2: float, nm_per_a: float, backdriven_share: float, gravity_moment_nm: float,
                 com_angle_rad: float, spring: tuple[float, float, bool], time_constant_s: float,
                 residual_nm: float, share: float, per_n_m: float, slow_rad_s: float) -> None:
        """The foot's model (the feedforward's), the observer's time constant and the bound's terms."""
        self.inertia_kg_m2 = inertia_kg_m2
        self.nm_per_a = nm_per_a
        self.backdriven_share = backdriven_share
        self.gravity_moment_nm = gravity_moment_nm
        self.com_angle_rad = com_angle_rad
        self.spring_k, self.spring_engage_rad, self.spring_two_sided = spring
        self.gain = 1.0 / time_constant_s
        self.residual_nm = residual_nm
        self.share = share
        self.per_n_m = per_n_m
        self.slow_rad_s = slow_rad_s
        self.residual = 0.0  # the unexplained moment now (N m)
        self.bound = 0.0  # the bound it was judged against
        self._last_s = -1.0  # no sample yet
        self._momentum0 = 0.0
        self._integral = 0.0
        self._known = 0.0  # the measured moments at the last sample
        self._since = -1.0  # when the residual went beyond its bound (-1: it is within)

    def reset(self) -> None:
        """Start again at the next sample (the foot's momentum then is the observer's origin)."""
        self._last_s = -1.0
        self._since = -1.0
        self.residual = 0.0

    def update(self, now_s: float, velocity_rad_s: float, angle_rad: float, current_a: float, moment_nm: float,
               force_n: float) -> float:
        """Seconds the residual has been beyond its bound on a slow foot up to now_s (0.0 when it is not)."""
        motor = self.nm_per_a * current_a
        if current_a * velocity_rad_s < 0.0 and self.backdriven_share != 1.0:  # against the motion: backdriven
            motor /= self.backdriven_share
        spring = parallel_spring_torque_nm(self.spring_k, self.spring_engage_rad, self.spring_two_sided, angle_rad) \
            if self.spring_k != 0.0 else 0.0
        known = motor + spring + moment_nm - self.gravity_moment_nm * math.sin(angle_rad + self.com_angle_rad)
        momentum = self.inertia_kg_m2 * velocity_rad_s
        if self._last_s < 0.0:
            self._momentum0, self._integral, self.residual = momentum, 0.0, 0.0
        else:  # the moments of the last sample acted over the interval since (held, as the drive holds its current)
            self._integral += (self._known + self.residual) * (now_s - self._last_s)
            self.residual = self.gain * (momentum - self._momentum0 - self._integral)
        self._last_s = now_s
        self._known = known
        self.bound = self.residual_nm + self.share * (abs(motor) + abs(spring) + abs(moment_nm)) \
            + self.per_n_m * abs(force_n)
        if abs(self.residual) <= self.bound or abs(velocity_rad_s) > self.slow_rad_s:
            self._since = -1.0
            return 0.0
        if self._since < 0.0:
            self._since = now_s
        return now_s - self._since


class ThermalGuard:
    """The motor's reported winding temperature, taken only while fresh, and the current limit it allows.

    A reading older than ``max_age_s`` (or none, or not finite) is NaN: it neither derates nor latches; a
    motor that stopped replying is MOTOR_TIMEOUT's to catch. ``derating_since_s`` is when the limit first fell
    below the full one (None: never).
    """

    def __init__(self, limits: ThermalLimits) -> None:
        """No reading yet: the full limit."""
        self.limits = limits
        self.max_age_s = limits.max_age_s
        self._start_c = limits.derate_start_c  # native copy: the common case (cool) makes no call into the limits
        self.derating_since_s: float | None = None
        self.factor = 1.0

    def fresh_c(self, temp_c: float, received_s: float | None, now_s: float) -> float:
        """temp_c if it was received at most max_age_s before now_s and is finite, else NaN."""
        if received_s is None or now_s - received_s > self.max_age_s or not math.isfinite(temp_c):
            return math.nan
        return temp_c

    def limit_a(self, limit_a: float, temp_c: float, received_s: float | None, now_s: float) -> float:
        """The current limit allowed now: limit_a derated by the fresh temperature (limit_a itself without one)."""
        t = self.fresh_c(temp_c, received_s, now_s)
        if not t > self._start_c:  # cool, or no fresh reading (NaN): the full limit
            self.factor = 1.0
            return limit_a
        factor = self.limits.derating(t)
        self.factor = factor
        if self.derating_since_s is None:
            self.derating_since_s = now_s
            log.warning("derating at %.4f s: motor temperature %.1f C, current limit %.2f A", now_s, t,
                        limit_a * factor)
        return limit_a * factor


# Enum members as module constants: the per-period checks compare against them without the enum's
# class attribute lookup (Final: compiled, they are C statics, not looked up in the module's dict).
_INIT: Final = SupervisorState.INIT
_RUN: Final = SupervisorState.RUN
_SAFE: Final = SupervisorState.SAFE
_NONE: Final = FaultReason.NONE
_HALF_FRAME_S: Final = 0.5 / RVC_RATE_HZ  # half the IMU's frame period (FrozenImu's time grows in whole periods)

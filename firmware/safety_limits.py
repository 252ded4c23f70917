"""The safety supervisor's thresholds as given in a profile.

Interpreted on purpose (docs/compiled.md, "Values checked as given"); the compiled
:class:`~firmware.safety.Supervisor` reads them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from firmware.control.validation import check_int_range, check_range
from firmware.motor_ratings import MotorRatings
from firmware.safe_state import SAFE_STATES

__all__ = ["ANGLE_LIMIT_RAD", "BRAKE_CURRENT_MAX_A", "BRAKE_DELAY_MAX_S", "DAMPING_KD_MAX", "HOLD_KP_MAX",
           "MISS_STREAK_MAX", "PEAK_CURRENT_A", "STARTUP_GRACE_MAX_S", "TEMPERATURE_MAX_AGE_S", "TEMPERATURE_RANGE_C",
           "TIMEOUT_MAX_S", "SafetyLimits", "ThermalLimits"]

# The hardware's bounds on every limit; a limit beyond them is no limit at all (or asks the motor for what it
# cannot give). Sources are the report's Table B2 and the maker's table (shared/PROTOCOLS.md section C). The two
# currents are the AK60-6's, the default motor: a profile whose [motor] states another motor's ratings
# (firmware.motor_ratings.MotorRatings) bounds the limits with that motor's figures instead.
PEAK_CURRENT_A = 22.7
"""AK60-6 peak phase current (report Table B2; maker 22.7 A): the motor cannot carry more, so a current limit
above it never trips and a command above it is not what the motor will do."""
BRAKE_CURRENT_MAX_A = 6.5
"""AK60-6 rated (continuous) current (maker, PROTOCOLS.md section C): the brake is held for as long as the
device stays in SAFE, which may be minutes, so it must not ask more than the winding carries continuously."""
ANGLE_LIMIT_RAD = math.pi / 2
"""Angle limits lie within +-90 deg: 0 is the foot perpendicular to the shank (docs/plant.md), and at +-90 deg
the foot would lie along the shank, further than any ankle or the frame's stops (-30/+36 deg) go."""
TIMEOUT_MAX_S = 0.1
"""Longest age limit of a command, of the motor's feedback and of an IMU frame. At the peak current the ankle
gets Kt*I*N*eta = 0.078*22.7*28*0.855 = 42 N*m on about 0.05 kg*m^2 (report Table B2, the [feedforward]
model): 860 rad/s^2, which swings the foot 1/2*860*0.1^2 = 4.3 rad, more than any range of motion, in 0.1 s.
A longer limit would let a stale command run from stop to stop unsupervised (docs/serial_mode.md)."""
STARTUP_GRACE_MAX_S = 5.0
"""Longest start-up grace: until RUN the motor is told zero current, so the grace only delays the report of
a sensor that never spoke; the serial start-up check gives a port 1 s (docs/serial_mode.md). [I] choice."""
BRAKE_DELAY_MAX_S = 1.0
"""Longest zero-current phase before the brake: the motor's own command timeout (VESC APPCONF_TIMEOUT_MSEC,
1 s, PROTOCOLS.md B.2), after which it would let go on its own anyway."""
DAMPING_KD_MAX = 5.0
"""Largest MIT damping kd: the AK series' MIT field range for kd, 0..5 N*m*s/rad (PROTOCOLS.md G); the law's torque
is further clamped to the motor's MIT torque range, which is within its peak (firmware/motor_ratings.py)."""
HOLD_KP_MAX = 500.0
"""Largest MIT hold kp: the AK series' MIT field range for kp, 0..500 N*m/rad (PROTOCOLS.md G); the law's torque is
clamped to the motor's MIT torque range as the damper's is."""
MISS_STREAK_MAX = 1000
"""Longest deadline-miss streak: TIMEOUT_MAX_S at the fastest control rate a profile may set (10 kHz); the
firmware configuration also holds it to TIMEOUT_MAX_S at its own control rate."""


@dataclass(frozen=True)
class SafetyLimits:
    """Thresholds of the supervisor (SI units); defaults follow the firmware's requirements."""

    angle_min_rad: float = math.radians(-33.0)
    angle_max_rad: float = math.radians(38.0)
    current_limit_a: float = 20.0
    motor_timeout_s: float = 0.020
    command_timeout_s: float = 0.020
    imu_timeout_s: float = 0.040
    disagreement_rad: float = math.radians(6.0)
    deadline_miss_streak: int = 3
    startup_grace_s: float = 0.5
    brake_delay_s: float = 0.010
    brake_current_a: float = 2.0
    # the output encoder against the motor's own position through the belt (docs/safety.md, "Mends")
    motor_encoder_gap_rad: float = math.radians(3.0)
    belt_ratio: float = 89.127 / 19.1
    # what the motor is told in the safe state (firmware/safe_state.py: release, brake, short, handbrake, hold,
    # damping, graded), the MIT damper's kd (N m s/rad at the actuator's output, the MIT law's units) and the MIT
    # hold's kp (N m/rad there; its kd is damping_kd)
    safe_state: str = "graded"
    damping_kd: float = 1.0
    hold_kp: float = 20.0
    # a frozen IMU: its frames bit-identical for imu_timeout_s while the encoder moved more than this
    imu_frozen_motion_rad: float = math.radians(1.0)
    # a jam: the current command at jam_current_share of its limit, the encoder within jam_still_rad, the
    # reference's speed above jam_reference_rad_s, all for longer than jam_time_s; in stance only when the push is
    # towards dorsiflexion with the reference (a plantarflexing one looks like a push-off the motor is too weak for;
    # docs/safety.md, "Jam")
    jam_current_share: float = 0.95
    jam_still_rad: float = math.radians(0.5)
    jam_reference_rad_s: float = 0.1
    jam_time_s: float = 0.025
    # a jam by the torque balance (firmware.safety.JamObserver; docs/safety.md, "Jam"), judged with a healthy load
    # cell: the moment the foot's model does not explain, followed with time constant jam_observer_s, beyond
    # jam_residual_peak_share x the design's peak output torque (Kt N eta x the current limit) + jam_residual_share x
    # the measured moments + jam_residual_m x the axial force, while the encoder is slower than jam_slow_rad_s, for
    # longer than jam_torque_time_s
    jam_observer_s: float = 0.015
    jam_residual_peak_share: float = 0.135
    jam_residual_share: float = 0.05
    jam_residual_m: float = 0.01
    jam_slow_rad_s: float = 0.87
    jam_torque_time_s: float = 0.005
    # the motor the current limits are bounded by ([motor] of the profile; a mapping, as a record's header holds it,
    # is read as MotorRatings)
    motor: MotorRatings = field(default_factory=MotorRatings)

    def __post_init__(self) -> None:
        """Reject limits that cannot describe a working supervisor or lie beyond the hardware (the motor's ratings)."""
        motor: Any = self.motor
        if isinstance(motor, dict):
            object.__setattr__(self, "motor", MotorRatings(**motor))
        elif not isinstance(motor, MotorRatings):
            raise ValueError(f"motor = {motor!r} is not allowed: the motor's ratings (MotorRatings)")
        for name in ("angle_min_rad", "angle_max_rad"):
            check_range(name, getattr(self, name), -ANGLE_LIMIT_RAD, ANGLE_LIMIT_RAD, unit="rad (+-90 deg)")
        if not self.angle_min_rad < self.angle_max_rad:
            raise ValueError(
                f"angle limits ({self.angle_min_rad}, {self.angle_max_rad}) rad: min must be below max"
            )
        span = self.angle_max_rad - self.angle_min_rad
        check_range("disagreement_rad", self.disagreement_rad, 0.0, span, lo_open=True,
                    unit="rad (at most the span of the angle limits: a wider one could not tell any two readings "
                         "inside them apart)")
        m = self.motor
        name = "AK60-6" if m.model == "ak60_6" else m.model
        check_range("current_limit_a", self.current_limit_a, 0.0, m.peak_current_a, lo_open=True,
                    unit=f"A (the {name}'s peak current)")
        check_range("brake_current_a", self.brake_current_a, 0.0, m.rated_current_a, lo_open=True,
                    unit=f"A (the {name}'s rated continuous current)")
        for name in ("motor_timeout_s", "command_timeout_s", "imu_timeout_s"):
            check_range(name, getattr(self, name), 0.0, TIMEOUT_MAX_S, lo_open=True,
                        unit="s (a stale peak-current command crosses any range of motion in 0.1 s)")
        check_range("startup_grace_s", self.startup_grace_s, 0.0, STARTUP_GRACE_MAX_S, lo_open=True, unit="s")
        check_range("brake_delay_s", self.brake_delay_s, 0.0, BRAKE_DELAY_MAX_S,
                    unit="s (the motor's own command timeout)")
        check_int_range("deadline_miss_streak", self.deadline_miss_streak, 1, MISS_STREAK_MAX)
        check_range("motor_encoder_gap_rad", self.motor_encoder_gap_rad, 0.0, span, lo_open=True,
                    unit="rad (at most the span of the angle limits)")
        check_range("belt_ratio", self.belt_ratio, 0.0, 100.0, lo_open=True, unit="(output over input pulley)")
        if self.safe_state not in SAFE_STATES:
            raise ValueError(f"safe_state = {self.safe_state!r} is not allowed: one of {', '.join(SAFE_STATES)}")
        check_range("imu_frozen_motion_rad", self.imu_frozen_motion_rad, 0.0, span, lo_open=True,
                    unit="rad (at most the span of the angle limits)")
        check_range("jam_current_share", self.jam_current_share, 0.0, 1.0, lo_open=True, unit="(of the current limit)")
        check_range("jam_still_rad", self.jam_still_rad, 0.0, span, lo_open=True,
                    unit="rad (at most the span of the angle limits)")
        check_range("jam_reference_rad_s", self.jam_reference_rad_s, 0.0, 10.0, unit="rad/s")
        check_range("jam_time_s", self.jam_time_s, 0.0, TIMEOUT_MAX_S, lo_open=True,
                    unit="s (a stalled peak-current command crosses any range of motion in 0.1 s once freed)")
        check_range("jam_observer_s", self.jam_observer_s, 0.0, TIMEOUT_MAX_S, lo_open=True,
                    unit="s (the observer's time constant: at most the longest age limit)")
        check_range("jam_residual_peak_share", self.jam_residual_peak_share, 0.0, 1.0, lo_open=True,
                    unit="(of the design's peak output torque)")
        check_range("jam_residual_share", self.jam_residual_share, 0.0, 1.0, unit="(of the measured moments)")
        check_range("jam_residual_m", self.jam_residual_m, 0.0, 0.5, unit="m (N m per N of axial force)")
        check_range("jam_slow_rad_s", self.jam_slow_rad_s, 0.0, 10.0, lo_open=True, unit="rad/s")
        check_range("jam_torque_time_s", self.jam_torque_time_s, 0.0, TIMEOUT_MAX_S,
                    unit="s (a jam released after it frees a stalled command)")
        check_range("damping_kd", self.damping_kd, 0.0, DAMPING_KD_MAX, lo_open=True,
                    unit="N m s/rad (MIT mode's kd range on the AK series)")
        check_range("hold_kp", self.hold_kp, 0.0, HOLD_KP_MAX, lo_open=True,
                    unit="N m/rad (MIT mode's kp range on the AK series)")


TEMPERATURE_RANGE_C = (40.0, 180.0)
"""Allowed [thermal] thresholds. Above 180 C no catalogue winding holds (IEC 60085 thermal class H, 180 C, the
cap the motor profiles put on max_winding_c); below 40 C a warm day's ambient would derate a motor at rest."""
TEMPERATURE_MAX_AGE_S = 5.0
"""Longest age of a temperature reading the firmware still acts on. The UART driver asks for the full GET_VALUES
(with temp_motor) at [rates_hz] full_values, 10 Hz by default; the CAN status frames carry it at every frame.
The winding's time constant is tens of seconds (profiles/motors/, [thermal]), so a few seconds old is still
current; an older one is no reading, and a lost reply is MOTOR_TIMEOUT's hazard, not this one's."""


@dataclass(frozen=True)
class ThermalLimits:
    """The firmware's response to the motor's reported winding temperature ([thermal] of the profile), degrees C.

    Between ``derate_start_c`` and ``derate_end_c`` the current limit falls linearly from the full limit to zero;
    above ``fault_c`` the supervisor latches OVER_TEMPERATURE (zero current, then the brake). Defaults and
    sources (docs/safety.md, "Over-temperature"):

    * ``derate_end_c`` 100: VESC's ``l_temp_motor_end`` default (``MCCONF_L_LIM_TEMP_MOTOR_END`` 100.0 in
      vedderb/bldc mcconf_default.h), where the AK60-6's own driver cuts the motor (the device model's
      ``temp_motor_max_c``): the firmware's limit reaches zero where the driver would drop it anyway.
    * ``derate_start_c`` 70: [I] choice, 15 K below VESC's ``l_temp_motor_start`` default (85.0, the same
      file): the firmware's own derating starts before the driver's, so the limit the user feels is the one
      the firmware announces (in its telemetry and summary), not the driver's unannounced one.
    * ``fault_c`` 90: [I] choice, 10 K below the driver's cutoff, so the firmware's stop path (zero current, then
      the brake) acts before the driver lets go on its own; far below the insulation's limit (CubeMars lists
      class C, above 180 C; IEC 60085 class H 180 C): the limit is the driver's, not the copper's.
    * ``max_age_s`` 1.0: [I] ten full GET_VALUES periods at 10 Hz (see TEMPERATURE_MAX_AGE_S).
    """

    derate_start_c: float = 70.0
    derate_end_c: float = 100.0
    fault_c: float = 90.0
    max_age_s: float = 1.0

    def __post_init__(self) -> None:
        """Thresholds inside TEMPERATURE_RANGE_C, the derating a rising ramp, the fault above its start."""
        lo, hi = TEMPERATURE_RANGE_C
        for name in ("derate_start_c", "derate_end_c", "fault_c"):
            check_range(name, getattr(self, name), lo, hi, unit="C (IEC 60085 class H at most)")
        if not self.derate_start_c < self.derate_end_c:
            raise ValueError(f"derate_start_c = {self.derate_start_c!r} must be below derate_end_c = "
                             f"{self.derate_end_c!r} C (the current limit falls from the one to the other)")
        if not self.fault_c > self.derate_start_c:
            raise ValueError(f"fault_c = {self.fault_c!r} must be above derate_start_c = {self.derate_start_c!r} C "
                             "(the firmware derates before it stops)")
        check_range("max_age_s", self.max_age_s, 0.0, TEMPERATURE_MAX_AGE_S, lo_open=True,
                    unit="s (a reading older than this is no reading)")

    def derating(self, temp_c: float) -> float:
        """Fraction of the current limit allowed at winding temperature ``temp_c`` (1.0 for NaN: no reading).

        >>> ThermalLimits().derating(70.0), ThermalLimits().derating(85.0), ThermalLimits().derating(100.0)
        (1.0, 0.5, 0.0)
        """
        if not temp_c > self.derate_start_c:  # NaN too
            return 1.0
        if temp_c >= self.derate_end_c:
            return 0.0
        return (self.derate_end_c - temp_c) / (self.derate_end_c - self.derate_start_c)

"""The AK60-6 driver's own speed and position loops: each turns a set-point into a q-current command.

CubeMars does not publish its loops or gains; these are simple, documented stand-ins (docs/devices.md).
Duty mode is not a loop here: it is the winding's law (:mod:`hal.virtual.devices.ak60_winding`).

* speed (SET_RPM): PI on the motor-side speed, ``i = Kp e + Ki integral(e)``, integral clamped to the
  peak current (anti-windup), output clamped to +-peak;
* position (SET_POS, SET_POS_SPD): P on the motor-side angle giving a speed reference, limited to the
  speed limit and to ``sqrt(2 a |error|)`` (so the move can stop at the acceleration limit ``a``) and
  slewed at ``a`` (a trapezoidal move), then the speed PI.

Everything is motor side (rotor rad, rad/s); ERPM = rotor rpm x pole pairs. Entering a loop is bumpless:
the integral starts at the present current and the speed reference at the present speed.
"""

from __future__ import annotations

import math
from enum import Enum
from typing import Final

from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.plant import PlantParams

__all__ = ["InnerLoops", "LoopMode", "degrees", "erpm_to_rad_s", "radians"]

_DEG_PER_RAD: Final = 180.0 / math.pi
_RAD_PER_DEG: Final = math.pi / 180.0


class LoopMode(Enum):
    """Which inner loop makes the current command."""

    SPEED = "speed"
    POSITION = "position"


def erpm_to_rad_s(erpm: float, pole_pairs: int) -> float:
    """Electrical RPM to motor-side mechanical rad/s.

    >>> round(erpm_to_rad_s(14 * 60, 14), 6)  # 60 rotor rpm
    6.283185
    """
    return erpm / pole_pairs * math.tau / 60.0


def degrees(angle_rad: float) -> float:
    """``math.degrees``, bit for bit (CPython multiplies by the same constant), as a native call when compiled.

    >>> degrees(math.pi / 3) == math.degrees(math.pi / 3)
    True
    """
    return angle_rad * _DEG_PER_RAD


def radians(angle_deg: float) -> float:
    """``math.radians``, bit for bit (CPython multiplies by the same constant), as a native call when compiled.

    >>> radians(57.3) == math.radians(57.3)
    True
    """
    return angle_deg * _RAD_PER_DEG


class InnerLoops:
    """Set-points and state of the driver's inner loops; ``current_a`` is called once per loop period."""

    def __init__(self, cfg: Ak60Config, params: PlantParams) -> None:
        """Take the gains from cfg and the motor constants from params."""
        self.kp = cfg.speed_kp_a_s_per_rad
        self.ki = cfg.speed_ki_a_per_rad
        self.kp_pos = cfg.position_kp_per_s
        self.default_speed_erpm = cfg.pos_speed_erpm
        self.default_accel_erpm_s = cfg.pos_accel_erpm_per_s
        self.peak_a = params.peak_current_a
        self.pole_pairs = params.pole_pairs
        self.mode: LoopMode | None = None  # None until a loop is started
        self.speed_target_rad_s = 0.0
        self.position_target_rad = 0.0
        self.max_speed_rad_s = 0.0
        self.max_accel_rad_s2 = 0.0
        self.speed_ref_rad_s = 0.0
        self.integral_a = 0.0

    def _clamp(self, current_a: float) -> float:
        peak = self.peak_a
        return peak if current_a > peak else -peak if current_a < -peak else current_a

    def _enter(self, mode: LoopMode, current_a: float, motor_velocity_rad_s: float) -> None:
        if self.mode is not mode:
            self.integral_a = self._clamp(current_a)
            self.speed_ref_rad_s = motor_velocity_rad_s
        self.mode = mode

    def start_speed(self, erpm: float, current_a: float, motor_velocity_rad_s: float) -> None:
        """Speed mode (SET_RPM) towards erpm."""
        self._enter(LoopMode.SPEED, current_a, motor_velocity_rad_s)
        self.speed_target_rad_s = erpm_to_rad_s(erpm, self.pole_pairs)

    def start_position(self, target_rad: float, current_a: float, motor_velocity_rad_s: float,
                       speed_erpm: float = 0.0, accel_erpm_per_s: float = 0.0) -> None:
        """Position mode towards the rotor angle target_rad; speed/accel <= 0 take the defaults."""
        self._enter(LoopMode.POSITION, current_a, motor_velocity_rad_s)
        self.position_target_rad = target_rad
        speed = abs(speed_erpm) if speed_erpm else self.default_speed_erpm
        accel = abs(accel_erpm_per_s) if accel_erpm_per_s else self.default_accel_erpm_s
        self.max_speed_rad_s = erpm_to_rad_s(speed, self.pole_pairs)
        self.max_accel_rad_s2 = erpm_to_rad_s(accel, self.pole_pairs)

    def current_a(self, dt_s: float, motor_angle_rad: float, motor_velocity_rad_s: float) -> float:
        """One loop period: the q-current command for the present rotor angle and speed."""
        w = motor_velocity_rad_s
        if self.mode is LoopMode.POSITION:
            err = self.position_target_rad - motor_angle_rad
            accel = self.max_accel_rad_s2
            # speed limit, P law, and the speed from which the move can still stop in time
            vmax = min(self.max_speed_rad_s, self.kp_pos * abs(err), math.sqrt(2.0 * accel * abs(err)))
            want = math.copysign(vmax, err)
            step = accel * dt_s
            ref = self.speed_ref_rad_s
            ref = min(want, ref + step) if want > ref else max(want, ref - step)
            self.speed_ref_rad_s = ref
        else:
            self.speed_ref_rad_s = self.speed_target_rad_s
        err = self.speed_ref_rad_s - w
        self.integral_a = self._clamp(self.integral_a + self.ki * err * dt_s)
        return self._clamp(self.kp * err + self.integral_a)

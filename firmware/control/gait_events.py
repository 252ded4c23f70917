"""Stance detection from the firmware's own sensors: the external moment the motor is seen to carry.

The ankle's foot model (the feed-forward's J, m g d) says what torque the foot alone needs; the motor's
measured current says what it delivers (with a parallel spring, the spring's moment at the angle too; with
[feedforward] efficiency_backdriven, a current against the ankle's motion gives 1 / (eta_fwd eta_back) times the
driving moment, as the plant's transmission does). The difference is the moment from outside: the ground's in
stance. Heel strike is that moment rising above ``on_nm``, toe off it falling below ``off_nm``
(hysteresis); a stance lasts at least ``min_stance_s`` and a swing at least ``min_swing_s`` (a push-off
that unloads the sensed moment early is not yet toe off). Compiled (setup.py): it runs every control period.
"""

from __future__ import annotations

import math

from firmware.control.pid import Feedforward
from firmware.control.validation import check_range

__all__ = ["LoadDetector"]


class LoadDetector:
    """Heel strike / toe off from the estimated external moment at the ankle (positive = dorsiflexing)."""

    def __init__(self, ts_s: float, nm_per_a: float, inertia_kg_m2: float, gravity_moment_nm: float,
                 com_angle_rad: float, on_nm: float = 9.0, off_nm: float = 6.0, cutoff_hz: float = 20.0,
                 min_stance_s: float = 0.3, min_swing_s: float = 0.2, feedforward: Feedforward | None = None) -> None:
        """Bind the foot model and the thresholds (N m), the low-pass cutoff (Hz) and the least stance and swing (s)."""
        check_range("on_nm", on_nm, 0.0, 1000.0, lo_open=True, unit="N m")
        check_range("off_nm", off_nm, 0.0, on_nm, unit="N m")
        check_range("cutoff_hz", cutoff_hz, 0.0, 0.5 / ts_s, lo_open=True, unit="Hz")
        check_range("min_stance_s", min_stance_s, 0.0, 10.0, unit="s")
        check_range("min_swing_s", min_swing_s, 0.0, 10.0, unit="s")
        self.nm_per_a = nm_per_a
        self.inertia_kg_m2 = inertia_kg_m2
        self.gravity_moment_nm = gravity_moment_nm
        self.com_angle_rad = com_angle_rad
        self.on_nm = on_nm
        self.off_nm = off_nm
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * ts_s)
        self.min_stance_s = min_stance_s
        self.min_swing_s = min_swing_s
        self.feedforward = feedforward  # its parallel spring's moment is not from outside (none: no spring)
        self.load_torque_nm = 0.0
        self.stance = False
        self.changed_s = -math.inf
        self.heel_strikes = 0
        self.toe_offs = 0
        self.heel_strike_s: list[float] = []  # when each was detected (for the detection latency)
        self.toe_off_s: list[float] = []

    def update(self, now_s: float, current_meas_a: float, angle_rad: float, accel_rad_s2: float,
               velocity_rad_s: float = 0.0) -> bool:
        """Take one period's measurements; return True while in stance."""
        model_nm = self.inertia_kg_m2 * accel_rad_s2 + self.gravity_moment_nm * math.sin(angle_rad + self.com_angle_rad)
        ff = self.feedforward
        motor_nm = self.nm_per_a * current_meas_a
        if ff is not None and current_meas_a * velocity_rad_s < 0.0:  # backdriven: more moment per ampere
            motor_nm /= ff.backdriven_share
        external_nm = model_nm - motor_nm
        if ff is not None and ff.spring_k != 0.0:  # the parallel spring's moment: the motor's share is the rest
            external_nm -= ff.spring_current_a(angle_rad) * self.nm_per_a
        load = self.load_torque_nm + self.alpha * (external_nm - self.load_torque_nm)
        self.load_torque_nm = load
        held_s = now_s - self.changed_s
        if self.stance:
            if load < self.off_nm and held_s >= self.min_stance_s:
                self.stance = False
                self.changed_s = now_s
                self.toe_offs += 1
                self.toe_off_s.append(now_s)
        elif load > self.on_nm and held_s >= self.min_swing_s:
            self.stance = True
            self.changed_s = now_s
            self.heel_strikes += 1
            self.heel_strike_s.append(now_s)
        return self.stance

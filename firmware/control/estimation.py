"""State estimation: encoder count -> angle and velocity, and encoder + IMU fusion for the absolute angle.

The encoder arithmetic is the C firmware's: the timer's CNT register wraps, and the per-sample delta is
the wrap-safe difference equivalent to `(int16_t)(cnt - prev)`. The fusion is a complementary filter:
the encoder carries the fast relative motion, the IMU slowly fixes the encoder's unknown zero.
"""

from __future__ import annotations

import logging
import math

from firmware.control.filters import FirstOrderLowPass
from firmware.control.validation import check_int_range, check_range

logger = logging.getLogger(__name__)

#: Counts per output revolution of the 1000-line encoder in x4 mode.
COUNTS_PER_REV = 4000
#: IMU lag time constant from the report's model 1/(1 + 0.0195 s), seconds.
IMU_LAG_S = 0.0195


def wrap_delta_counts(count: int, previous: int, modulus: int = 1 << 16) -> int:
    """Signed count change from previous to count on a counter wrapping at modulus (|delta| < modulus/2).

    For modulus 2**16 this equals the C expression (int16_t)(cnt - prev).

    >>> wrap_delta_counts(3, 65533)
    6
    >>> wrap_delta_counts(65533, 3)
    -6
    """
    half = modulus >> 1
    return ((count - previous + half) % modulus) - half


class VelocityEstimator:
    """Encoder CNT -> continuous output angle (rad) and low-pass filtered velocity (rad/s).

    The angle is 0 at the first sample (the encoder's zero at power-up is arbitrary).

    >>> est = VelocityEstimator(ts_s=0.001, velocity_cutoff_hz=1000.0 / 3.0)
    >>> est.update(65535)
    (0.0, 0.0)
    >>> round(est.update(9)[0], 6)   # 10 counts forward across the wrap
    0.015708
    """

    __slots__ = ("counts_per_rev", "counter_modulus", "ts_s", "direction", "_rad_per_count",
                 "_vel_gain", "_filter", "_prev", "_total", "_angle", "_raw_velocity", "_velocity")

    def __init__(self, ts_s: float, velocity_cutoff_hz: float = 50.0, counts_per_rev: int = COUNTS_PER_REV,
                 counter_modulus: int = 1 << 16, direction: int = 1) -> None:
        """Build for samples every ts_s, velocity low-passed at velocity_cutoff_hz; CNT wraps at modulus."""
        check_range("ts_s", ts_s, 1e-6, 1.0, unit="s")
        check_int_range("counts_per_rev", counts_per_rev, 2, 1 << 32)
        check_int_range("counter_modulus", counter_modulus, 2, 1 << 32)
        if direction not in (1, -1):
            raise ValueError(f"direction = {direction!r} is not allowed: must be +1 or -1")
        self.counts_per_rev = counts_per_rev
        self.counter_modulus = counter_modulus
        self.ts_s = float(ts_s)
        self.direction = direction
        self._rad_per_count = direction * 2.0 * math.pi / counts_per_rev
        self._vel_gain = self._rad_per_count / self.ts_s
        self._filter = FirstOrderLowPass(velocity_cutoff_hz, 1.0 / self.ts_s)
        self._prev: int | None = None
        self._total = 0
        self._angle = 0.0
        self._raw_velocity = 0.0
        self._velocity = 0.0

    def reset(self) -> None:
        """Forget the previous count; the next sample becomes angle 0."""
        self._prev = None
        self._total = 0
        self._angle = 0.0
        self._raw_velocity = 0.0
        self._velocity = 0.0
        self._filter.reset(0.0)

    def update(self, count: int) -> tuple[float, float]:
        """Take one CNT sample (0 <= count < counter_modulus); return (angle_rad, filtered velocity_rad_s)."""
        prev = self._prev
        self._prev = count
        if prev is None:
            return self._angle, self._velocity
        delta = wrap_delta_counts(count, prev, self.counter_modulus)
        self._total += delta
        self._angle = self._total * self._rad_per_count
        self._raw_velocity = delta * self._vel_gain
        self._velocity = self._filter.step(self._raw_velocity)
        return self._angle, self._velocity

    @property
    def total_counts(self) -> int:
        """Accumulated signed counts since the first sample (before the direction sign)."""
        return self._total

    @property
    def raw_velocity_rad_s(self) -> float:
        """Unfiltered one-sample velocity delta*2pi/(counts_per_rev*ts), rad/s."""
        return self._raw_velocity


class AngleEstimator:
    """Complementary filter: angle = encoder + offset, offset slowly pulled towards imu - lagged encoder.

    Call update() every control sample with the encoder angle and the IMU pitch when a new IMU sample
    arrived (None otherwise). The first IMU sample seeds the offset; later ones move it by
    beta = 1 - exp(-n Ts / offset_tau_s) of the innovation, n = control samples since the last IMU sample.
    The encoder is passed through the IMU's own first-order lag (imu_lag_s) before the comparison, so
    fast motion does not look like an offset error.

    >>> est = AngleEstimator(ts_s=0.001, offset_tau_s=2.0, imu_lag_s=0.0)
    >>> est.update(0.25, None)   # no IMU yet: encoder only, offset 0
    0.25
    >>> est.update(0.25, 0.75)   # first IMU sample seeds offset = 0.5
    0.75
    """

    __slots__ = ("ts_s", "offset_tau_s", "imu_lag_s", "_lag_beta", "_enc_lagged", "_offset", "_seeded",
                 "_since_imu", "_disagreement", "imu_samples")

    def __init__(self, ts_s: float, offset_tau_s: float = 2.0, imu_lag_s: float = IMU_LAG_S) -> None:
        """Build for control period ts_s, offset time constant offset_tau_s, IMU lag constant imu_lag_s."""
        check_range("ts_s", ts_s, 1e-6, 1.0, unit="s")
        check_range("offset_tau_s", offset_tau_s, 0.0, 3600.0, lo_open=True, unit="s")
        check_range("imu_lag_s", imu_lag_s, 0.0, 1.0, unit="s")
        self.ts_s = float(ts_s)
        self.offset_tau_s = float(offset_tau_s)
        self.imu_lag_s = float(imu_lag_s)
        self._lag_beta = 1.0 if imu_lag_s == 0.0 else 1.0 - math.exp(-self.ts_s / self.imu_lag_s)
        self.reset()

    def reset(self) -> None:
        """Forget the offset; the next IMU sample seeds it again."""
        self._enc_lagged: float | None = None
        self._offset = 0.0
        self._seeded = False
        self._since_imu = 0
        self._disagreement = 0.0
        self.imu_samples = 0

    def update(self, encoder_angle_rad: float, imu_pitch_rad: float | None) -> float:
        """Fuse one control sample (imu_pitch_rad None when no new IMU sample) and return the angle in rad."""
        lagged = self._enc_lagged
        if lagged is None:
            lagged = encoder_angle_rad
        else:
            lagged += self._lag_beta * (encoder_angle_rad - lagged)
        self._enc_lagged = lagged
        self._since_imu += 1
        if imu_pitch_rad is not None:
            self.imu_samples += 1
            if not self._seeded:
                self._offset = imu_pitch_rad - encoder_angle_rad
                self._seeded = True
                self._disagreement = 0.0
            else:
                innovation = imu_pitch_rad - (lagged + self._offset)
                self._disagreement = abs(innovation)
                gain = 1.0 - math.exp(-self._since_imu * self.ts_s / self.offset_tau_s)
                self._offset += gain * innovation
            self._since_imu = 0
        return encoder_angle_rad + self._offset

    @property
    def offset_rad(self) -> float:
        """Current estimate of imu - encoder (the encoder's unknown zero), radians."""
        return self._offset

    @property
    def seeded(self) -> bool:
        """True once an IMU sample has fixed the absolute offset."""
        return self._seeded

    @property
    def disagreement_rad(self) -> float:
        """|imu - (lagged encoder + offset)| at the last IMU sample, radians (for the safety supervisor)."""
        return self._disagreement

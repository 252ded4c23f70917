"""Configuration of the BNO08x UART-RVC model (interpreted on purpose: docs/compiled.md, "Values checked as
given")."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hal.virtual.checks import check_field_ranges

__all__ = ["BANNER_LINES", "Bno08xConfig"]

BANNER_LINES: tuple[str, ...] = (
    "%Hillcrest Labs 10003608",
    "%SW Ver 3.2.x",
    "%(c) 2017 Hillcrest Laboratories, Inc.",
)
"""The ASCII lines printed after reset (BNO080 datasheet 1000-3927 section 5.1, PROTOCOLS.md D.1)."""

_RANGES: dict[str, tuple[float, float]] = {
    "rate_hz": (0.1, 1000.0),
    "lag_time_constant_s": (0.0, 10.0),
    "hold_interval_s": (0.0, 10.0),
    "substep_s": (1e-5, 1.0),
    "period_jitter_s": (0.0, 1.0),
    "boot_delay_s": (0.0, 10.0),
    "mounting_offset_rad": (-math.pi, math.pi),
    "lever_arm_m": (0.0, 1.0),
    "pitch_noise_rad": (0.0, 1.0),
    "pitch_bias_rad": (-1.0, 1.0),
    "bias_sigma_rad": (0.0, 1.0),
    "bias_drift_sigma_rad": (0.0, 1.0),
    "bias_drift_tau_s": (0.01, 3600.0),
    "accel_noise_mps2": (0.0, 50.0),
    "accel_bias_sigma_mps2": (0.0, 50.0),
    "yaw_rad": (-math.pi, math.pi),
    "roll_rad": (-math.pi, math.pi),
}


@dataclass(frozen=True)
class Bno08xConfig:
    """Output rate, lag, mounting, noise and boot timing of the BNO08x model (SI units)."""

    rate_hz: float = 100.0
    """RVC report rate (datasheet: 100 Hz)."""
    lag_time_constant_s: float = 0.0195
    """First-order lag of the sensor output (report eq 3.42: 1/(1 + 0.0195 s)); 0 = none."""
    hold_interval_s: float = 0.0
    """Sample-and-hold of the pitch at this interval (report 3.5.4 read as "the time difference between two
    data points", 0.0195 s: the sample-hold reading, hal.virtual.plant.readings); 0 = none. With a hold the
    first-order lag is not applied (the other reading)."""
    substep_s: float = 2.5e-3
    """[I] sampling step of the true pitch for the lag integration (frames are always sample points)."""
    period_jitter_s: float = 0.0
    """[I] uniform jitter of each frame period, +- this much."""
    boot_delay_s: float = 0.0
    """[I] from power-up to the first banner byte; the first frame follows one period later."""
    mounting_offset_rad: float = 0.0
    """Tilt of the sensor on the foot: added to the ankle angle (the firmware subtracts it)."""
    pitch_sign: int = 1
    """+1: toe up reads positive pitch; -1 for a sensor mounted the other way round."""
    lever_arm_m: float = 0.08
    """[I] distance from the ankle axis to the sensor along the sole."""
    pitch_noise_rad: float = math.radians(0.05)
    """[I] standard deviation of the white noise on yaw, pitch and roll."""
    pitch_bias_rad: float = 0.0
    """Fixed pitch bias."""
    bias_sigma_rad: float = 0.0
    """[I] standard deviation of a random pitch bias drawn once at power-up."""
    bias_drift_sigma_rad: float = 0.0
    """Stationary standard deviation of a first-order Gauss-Markov drift of the pitch bias; 0 = none."""
    bias_drift_tau_s: float = 10.0
    """Correlation time of that drift."""
    accel_noise_mps2: float = 0.02
    """[I] standard deviation of the white noise on each acceleration (about 2 mg)."""
    accel_bias_sigma_mps2: float = 0.0
    """[I] standard deviation of random acceleration biases drawn once at power-up."""
    yaw_rad: float = 0.0
    """Yaw reported (rotation about z since reset; the bench does not turn)."""
    roll_rad: float = 0.0
    """Roll reported."""
    banner: tuple[str, ...] = BANNER_LINES
    """Lines printed at power-up (each followed by CR LF, an assumption)."""

    def __post_init__(self) -> None:
        """Check every number against its allowed range."""
        check_field_ranges(self, _RANGES)
        if self.pitch_sign not in (1, -1):
            raise ValueError(f"Bno08xConfig.pitch_sign = {self.pitch_sign!r} must be +1 or -1")
        if self.period_jitter_s >= 0.5 / self.rate_hz:
            raise ValueError(f"Bno08xConfig.period_jitter_s = {self.period_jitter_s!r} must be below half "
                             f"the period, {0.5 / self.rate_hz!r} s")


def with_imu_reading(config: Bno08xConfig, reading: str, interval_s: float = 0.0195) -> Bno08xConfig:
    """The config under an IMU reading of report 3.5.4 (hal.virtual.plant.readings.IMUS).

    first-order-lag: the lag of interval_s, no hold; sample-hold: held every interval_s, no lag.
    """
    from dataclasses import replace

    from hal.virtual.plant.readings import check_reading

    if check_reading("imu", reading) == "sample-hold":
        return replace(config, lag_time_constant_s=0.0, hold_interval_s=interval_s)
    return replace(config, lag_time_constant_s=interval_s, hold_interval_s=0.0)


def imu_reading_of(config: Bno08xConfig) -> str:
    """The IMU reading a config models: sample-hold when it holds, else first-order-lag."""
    return "sample-hold" if config.hold_interval_s > 0.0 else "first-order-lag"

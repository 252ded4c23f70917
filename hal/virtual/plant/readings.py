"""The two readings of the report the bench depends on, named: gravity geometry, FOC driver, IMU model.

The report can be read two ways in three places (docs/bench.md, "Readings"):

- **geometry** -- ``level-com`` (the profile's default): at 0 deg the foot's centre of mass is level with
  the ankle, so the unpowered suspended foot falls onto the -30 deg stop (report 3.6.1, "falls from early
  stance to late stance within 0.5 s"); ``hanging``: the report's own leg model, eq 3.55,
  (J_c + m d^2) th'' + k th' + m g d sin(th) = T_d, a pendulum hanging at 0 deg (3.5.6).
  A plant-profile value: ``foot.com_angle_at_zero_rad`` (pi/2 level, 0 hanging).
- **driver** -- ``current-lag`` (the plant's): the driver closes a current loop, the q current follows the
  command with the report's 1.14 ms time constant (eq 3.41's pole, its gain dropped); ``voltage-amplifier``:
  eq 3.41 as written, 24/(1 + 0.00114 s), the PID's +-1 becoming +-24 V on the winding (3.6.3), the current
  then set by L di/dt = V - R i - K_e w (eq 3.62). A plant choice: ``Plant(driver=...)``; the firmware's
  runs use the current-lag reading (it commands current in servo mode); the report's analyses (motor-tf,
  open-loop, root-locus) use the voltage amplifier, linear (:mod:`hal.virtual.plant.linear`) and on the plant.
- **imu** -- ``first-order-lag``: 1/(1 + 0.0195 s), eq 3.42 as written; ``sample-hold``: 0.0195 s as the
  interval between two data points (3.5.4, "the time difference between two data points"), a 51 Hz
  sample-and-hold.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

from hal.virtual.plant.params import PlantParams

if TYPE_CHECKING:
    import numpy as np

__all__ = ["DRIVERS", "GEOMETRIES", "IMUS", "IMU_INTERVAL_S", "READINGS", "check_reading", "geometry_of",
           "imu_reading_signal", "with_geometry"]

#: Geometry reading -> foot.com_angle_at_zero_rad (angle of the ankle->COM line from the downward vertical).
GEOMETRIES: dict[str, float] = {"level-com": math.pi / 2, "hanging": 0.0}
#: Driver readings (the first is the nonlinear plant's).
DRIVERS: tuple[str, ...] = ("current-lag", "voltage-amplifier")
#: IMU readings (the first is the device model's).
IMUS: tuple[str, ...] = ("first-order-lag", "sample-hold")
#: Report 3.5.4: 0.0195 s, a time constant (eq 3.42) or the interval between two data points.
IMU_INTERVAL_S = 0.0195
#: Every reading kind and its names.
READINGS: dict[str, tuple[str, ...]] = {"geometry": tuple(GEOMETRIES), "driver": DRIVERS, "imu": IMUS}


def check_reading(kind: str, name: str) -> str:
    """Return name if it is a reading of this kind; ValueError naming the value and the allowed names."""
    names = READINGS.get(kind)
    if names is None:
        raise ValueError(f"reading kind {kind!r} unknown: one of {list(READINGS)}")
    if name not in names:
        raise ValueError(f"{kind} reading {name!r} unknown: one of {list(names)}")
    return name


def geometry_of(p: PlantParams) -> str:
    """The geometry reading a plant profile uses (``custom`` when its COM angle is neither)."""
    for name, psi0 in GEOMETRIES.items():
        if math.isclose(p.com_angle_at_zero_rad, psi0, abs_tol=1e-9):
            return name
    return "custom"


def with_geometry(p: PlantParams, name: str) -> PlantParams:
    """The same plant under the named geometry reading."""
    return replace(p, com_angle_at_zero_rad=GEOMETRIES[check_reading("geometry", name)])


def imu_reading_signal(t_s: np.ndarray, angle: np.ndarray, name: str,
                       interval_s: float = IMU_INTERVAL_S) -> np.ndarray:
    """What the IMU reports of a sampled angle under the named reading (same length as angle).

    first-order-lag: the exact lag for a piecewise-linear input; sample-hold: the angle sampled every
    interval_s (the sample at or before each hold instant) and held.
    """
    import numpy as np  # only the analyses need it

    check_reading("imu", name)
    t = np.asarray(t_s, dtype=float)
    u = np.asarray(angle, dtype=float)
    out = np.empty_like(u)
    if name == "sample-hold":
        held = np.floor((t - t[0]) / interval_s) * interval_s + t[0]
        idx = np.searchsorted(t, held + 1e-12, side="right") - 1
        return u[np.clip(idx, 0, len(u) - 1)]
    y = out[0] = u[0]
    for k in range(1, len(u)):
        dt = t[k] - t[k - 1]
        m = (u[k] - u[k - 1]) / dt
        e = math.exp(-dt / interval_s)
        y = u[k] - m * interval_s + (y - u[k - 1] + m * interval_s) * e
        out[k] = y
    return out

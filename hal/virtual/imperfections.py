"""Imperfections of the real bench (profiles/bench_imperfections.toml), each with its source, each switchable.

The default is the real device: every imperfection on. ``Imperfections.bench_options(seed)`` turns the
enabled ones into VirtualBench arguments (the IMU's bias, drift and noise; the foot's pose at power-up,
which is where the incremental encoder's zero falls; the gearbox backlash, a torque dead time at each
reversal in the plant);
random ones are drawn from the run's seed, so the same seed gives the same bench. Imperfections the
single-degree-of-freedom plant cannot carry yet are listed with ``modelled = False``: they are
documented with their size and change nothing (docs/plant.md, "Imperfections").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hal.virtual.devices.bno08x_config import Bno08xConfig
from profiles import profile_path, read_toml

__all__ = ["DEFAULT_PROFILE", "MODELLED", "NAMES", "Imperfections", "load_imperfections"]

DEFAULT_PROFILE = profile_path("bench_imperfections.toml")
#: Every imperfection the profile must describe, in its order.
NAMES: tuple[str, ...] = ("imu_bias", "imu_drift", "imu_noise", "encoder_offset", "gearbox_backlash",
                          "belt_compliance", "output_pulley_compliance", "torque_ripple")
#: The ones that act on the virtual bench today.
MODELLED: frozenset[str] = frozenset({"imu_bias", "imu_drift", "imu_noise", "encoder_offset", "gearbox_backlash"})
# key -> (lowest, highest) of every number the modelled ones read
_RANGES: dict[tuple[str, str], tuple[float, float]] = {
    ("imu_bias", "sigma_deg"): (0.0, 10.0),
    ("imu_drift", "sigma_deg"): (0.0, 10.0),
    ("imu_drift", "tau_s"): (0.01, 3600.0),
    ("imu_noise", "sigma_deg"): (0.0, 5.0),
    ("encoder_offset", "max_deg"): (0.0, 10.0),
    ("gearbox_backlash", "actuator_output_deg"): (0.0, 10.0),
}


@dataclass(frozen=True)
class Imperfections:
    """The imperfection tables of the profile (name -> its keys), and which are switched on."""

    tables: dict[str, dict[str, Any]]
    path: str = ""

    def enabled(self, name: str) -> bool:
        """Whether imperfection `name` is on."""
        return bool(self.tables[name]["enabled"])

    def without(self, names: tuple[str, ...] | list[str]) -> Imperfections:
        """A copy with `names` switched off ("all": every one); ValueError names an unknown one."""
        chosen = NAMES if "all" in names else tuple(names)
        for n in chosen:
            if n not in self.tables:
                raise ValueError(f"imperfection {n!r} unknown: choose from {', '.join(NAMES)} or all")
        return Imperfections({k: {**v, "enabled": False} if k in chosen else v for k, v in self.tables.items()},
                             self.path)

    def _value(self, name: str, key: str) -> float:
        return float(self.tables[name][key]) if self.enabled(name) else 0.0

    def bench_options(self, seed: int, backlash_deg: float | None = None) -> dict[str, Any]:
        """VirtualBench arguments for the enabled imperfections: imu_config, initial_angle_rad, backlash_rad.

        The encoder is incremental (the firmware's angle is 0 at its first sample), so its offset is
        the foot's pose at power-up: the bench starts the foot there instead of at the zero mark.
        backlash_deg is the plant profile's figure (its optional ``[transmission] backlash_deg``), which wins
        over this table's; None: this table's. Switched off, the backlash is 0 either way.
        """
        imu = Bno08xConfig(
            bias_sigma_rad=math.radians(self._value("imu_bias", "sigma_deg")),
            bias_drift_sigma_rad=math.radians(self._value("imu_drift", "sigma_deg")),
            bias_drift_tau_s=float(self.tables["imu_drift"]["tau_s"]),
            pitch_noise_rad=math.radians(self._value("imu_noise", "sigma_deg")))
        max_offset = math.radians(self._value("encoder_offset", "max_deg"))
        rng = np.random.default_rng((seed, 0xE0C))  # its own stream: the other draws do not move it
        offset = float(rng.uniform(-max_offset, max_offset)) if max_offset > 0 else 0.0
        if backlash_deg is None or not self.enabled("gearbox_backlash"):
            backlash_deg = self._value("gearbox_backlash", "actuator_output_deg")
        backlash = math.radians(backlash_deg)
        return {"imu_config": imu, "initial_angle_rad": offset, "backlash_rad": backlash}

    def as_dict(self) -> dict[str, dict[str, Any]]:
        """{name: {"enabled", "modelled", values...}} for summary.json."""
        return {k: {**v, "modelled": k in MODELLED} for k, v in self.tables.items()}


def load_imperfections(path: str | Path | None = None) -> Imperfections:
    """Read the imperfection profile; ValueError names the file, the key and the allowed range."""
    p = Path(path) if path is not None else DEFAULT_PROFILE
    doc = read_toml(p, "imperfection profile")
    unknown = sorted(set(doc) - set(NAMES))
    missing = [n for n in NAMES if n not in doc]
    if unknown or missing:
        raise ValueError(f"imperfection profile {p}: unknown tables {unknown}, missing tables {missing}")
    for name in NAMES:
        if not isinstance(doc[name].get("enabled"), bool):
            raise ValueError(f"imperfection profile {p}: [{name}] enabled = {doc[name].get('enabled')!r} must be "
                             "true or false")
    for (name, key), (lo, hi) in _RANGES.items():
        v = doc[name].get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
            raise ValueError(f"imperfection profile {p}: [{name}] {key} = {v!r} out of range [{lo}, {hi}]")
    return Imperfections({n: dict(doc[n]) for n in NAMES}, str(p))

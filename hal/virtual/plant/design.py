"""A design: a catalogue motor, a timing-belt stage and an optional parallel spring, built into a plant.

A design profile is a firmware profile (``profiles/firmware.toml``'s sections, complete) plus a
``[design]`` table that the firmware never reads::

    [design]
    motor = "ak80_9"            # a profiles/motors/ name (or a motor profile's path)
    belt_driver_teeth = 30      # the actuator's pulley
    belt_driven_teeth = 140     # the ankle's pulley: belt ratio = driven / driver
    belt_pitch_mm = 2.0         # a standard pitch (BELT_PITCHES)
    belt_width_mm = 12.0        # optional: a stock width of the pitch (transmission.BELT_WIDTHS_MM; default its widest)
    battery = "molicel_p42a_12s1p"   # optional: a profiles/batteries/ name
    ground_sensors = "pylon_300nm"   # optional: a profiles/ground_sensors/ name (default profiles/ground_sensors.toml)
    [design.spring]             # optional; absent or stiffness 0: no spring
    stiffness_nm_per_rad = 100.0
    engage_deg = 0.0
    sided = "one"               # "one": only dorsiflexion beyond engage_deg; "two": both sides

:func:`plant_params_for` builds the plant of a design: the motor's electrical and mechanical values,
its gearbox, the belt from the tooth counts (pitch diameter = teeth x pitch / pi) and the base plant's
driver, foot, stops and bench fixtures (docs/design.md, "Transmission").

>>> d = design_from_mapping({"motor": "ak60_6", "belt_driver_teeth": 30, "belt_driven_teeth": 140,
...                          "belt_pitch_mm": 2.0}, "example")
>>> round(d.belt_ratio, 4), round(d.driven_pitch_diameter_m * 1000, 3)
(4.6667, 89.127)
>>> belt_for_ratio(4.6667, 2.0)   # 14:3 on the smallest ankle pulley (the report's pulleys are 30/140)
(12, 56)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from hal.virtual.plant.motors import MotorSpec, load_motor
from hal.virtual.plant.params import PlantParams
from hal.virtual.plant.transmission import (
    belt_tension_n,
    belt_width_mm,
    planetary_backdriven_efficiency,
    rated_belt_tension_n,
)

__all__ = ["BELT_PITCHES", "BELT_RATIO_TOLERANCE", "MAX_DRIVEN_PITCH_DIAMETER_M", "SPRING_SIDES", "Design",
           "DesignSpring", "belt_for_ratio", "belt_tension_per_amp_n", "design_from_mapping", "load_design",
           "nearest_belt_pairs", "plant_params_for"]

BELT_PITCHES: dict[float, tuple[str, int]] = {
    2.0: ("GT2 2 mm (2MGT)", 12),
    3.0: ("GT2 3 mm (3MGT) / HTD 3M", 16),
    5.0: ("GT2 5 mm (5MGT) / HTD 5M", 18),
    8.0: ("GT2 8 mm (8MGT) / HTD 8M", 22),
}
"""Standard timing-belt pitches (mm) -> (name, fewest teeth on a pulley). The fewest teeth are [I]: the smallest
stock sprockets per pitch of the Gates PowerGrip GT2 Drive Design Manual (no. 17195, "Sprocket Specification
Tables") as recalled, not checked against the current catalogue; smaller pulleys bend the belt's cords below
their rated radius and shorten its life. Check them against the belt maker's table before building."""
MAX_DRIVEN_PITCH_DIAMETER_M = 0.100
"""Largest ankle pulley [I]: the report's is 89.1 mm (3.2.2); much larger would not fit inside the foot's
shell above the keel, so a ratio that needs one is refused."""
BELT_RATIO_TOLERANCE = 0.01
"""A ratio asked of :func:`belt_for_ratio` must be met by a whole tooth pair within 1 %."""
SPRING_SIDES = ("one", "two")
_KEYS = ("motor", "belt_driver_teeth", "belt_driven_teeth", "belt_pitch_mm", "spring", "battery", "belt_width_mm",
         "ground_sensors")
_SPRING_KEYS = ("stiffness_nm_per_rad", "engage_deg", "sided")
MOTOR_KEYS = ("supply_voltage_v", "kv_rpm_per_v", "kt_nm_per_a", "phase_resistance_ohm", "phase_inductance_h",
              "pole_pairs", "rotor_inertia_kg_m2", "peak_current_a")
"""The plant's keys a motor profile gives under the same name (MotorSpec's fields)."""
MAX_SPRING_NM_PER_RAD = 2000.0
"""Stiffest parallel spring: 2000 N m/rad is the plant's hard stop (profiles/plant_ak60_6.toml); the
prosthesis literature's parallel springs are far softer (a few hundred N m/rad)."""
MAX_ENGAGE_DEG = 30.0
"""Engagement angle within +-30 deg: the ankle's range of motion in gait is -20..+12 deg (data/gait)."""


@dataclass(frozen=True)
class DesignSpring:
    """A parallel spring at the ankle: torque -k (theta - theta_e) beyond theta_e (one side or both)."""

    stiffness_nm_per_rad: float = 0.0
    engage_deg: float = 0.0
    sided: str = "one"

    @property
    def engage_rad(self) -> float:
        """The engagement angle in radians."""
        return math.radians(self.engage_deg)


@dataclass(frozen=True)
class Design:
    """The [design] table of a design profile: motor, belt stage, spring, battery."""

    motor: str
    belt_driver_teeth: int
    belt_driven_teeth: int
    belt_pitch_mm: float
    spring: DesignSpring | None = None
    battery: str | None = None
    belt_width_mm: float | None = None  # None: the pitch's widest stock width
    ground_sensors: str | None = None  # a profiles/ground_sensors/ name or path; None: profiles/ground_sensors.toml

    @property
    def ground_profile(self) -> Path | None:
        """The ground sensor profile the virtual bench fits (None: the packaged profiles/ground_sensors.toml)."""
        from hal.virtual.plant.sourced import resolve_profile

        return None if self.ground_sensors is None else resolve_profile(self.ground_sensors, "ground_sensors",
                                                                         "ground sensor profile")

    @property
    def width_mm(self) -> float:
        """The belt's width (the pitch's widest stock width unless the design names one)."""
        return belt_width_mm(self.belt_pitch_mm, self.belt_width_mm)

    @property
    def rated_tension_n(self) -> float:
        """The belt's rated working tension (hal/virtual/plant/transmission.py, BELT_RATED_N_PER_MM: SDP/SI)."""
        return rated_belt_tension_n(self.belt_pitch_mm, self.width_mm)

    @property
    def belt_ratio(self) -> float:
        """Ankle pulley turns per actuator turn: driven / driver teeth."""
        return self.belt_driven_teeth / self.belt_driver_teeth

    @property
    def driver_pitch_diameter_m(self) -> float:
        """Pitch diameter of the actuator's pulley: teeth x pitch / pi."""
        return self.belt_driver_teeth * self.belt_pitch_mm * 1e-3 / math.pi

    @property
    def driven_pitch_diameter_m(self) -> float:
        """Pitch diameter of the ankle's pulley: teeth x pitch / pi."""
        return self.belt_driven_teeth * self.belt_pitch_mm * 1e-3 / math.pi

    @property
    def has_spring(self) -> bool:
        """Whether the design has a parallel spring (stiffness above 0)."""
        return self.spring is not None and self.spring.stiffness_nm_per_rad > 0.0

    def motor_spec(self) -> MotorSpec:
        """The design's catalogue motor."""
        return load_motor(self.motor)

    def as_table(self) -> dict[str, Any]:
        """The [design] table as a TOML-shaped mapping (design_from_mapping reads it back)."""
        table: dict[str, Any] = {"motor": self.motor, "belt_driver_teeth": self.belt_driver_teeth,
                                 "belt_driven_teeth": self.belt_driven_teeth, "belt_pitch_mm": self.belt_pitch_mm}
        if self.battery is not None:
            table["battery"] = self.battery
        if self.belt_width_mm is not None:
            table["belt_width_mm"] = self.belt_width_mm
        if self.ground_sensors is not None:
            table["ground_sensors"] = self.ground_sensors
        if self.spring is not None:
            table["spring"] = {"stiffness_nm_per_rad": self.spring.stiffness_nm_per_rad,
                               "engage_deg": self.spring.engage_deg, "sided": self.spring.sided}
        return table


def _number(value: object, key: str, lo: float, hi: float, source: str, unit: str = "") -> float:
    """value as a float when it is a finite number in [lo, hi]; else a one-line ValueError."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or not lo <= float(value) <= hi:  # type: ignore[arg-type]
        raise ValueError(f"{source}: [design] {key} = {value!r} is outside the allowed range [{lo:g}, {hi:g}]{unit}")
    return float(value)  # type: ignore[arg-type]


def _teeth(value: object, key: str, pitch_mm: float, source: str, most: int) -> int:
    """A whole tooth count in [fewest for the pitch, most]; else a one-line ValueError."""
    name, fewest = BELT_PITCHES[pitch_mm]
    if isinstance(value, bool) or not isinstance(value, int) or not fewest <= value <= most:
        raise ValueError(f"{source}: [design] {key} = {value!r} is outside the allowed range [{fewest}, {most}] "
                         f"(whole teeth; {name}: at least {fewest}, ankle pulley at most "
                         f"{MAX_DRIVEN_PITCH_DIAMETER_M * 1000:g} mm)")
    return value


def max_teeth(pitch_mm: float) -> int:
    """Most teeth on a pulley of this pitch: the ankle pulley's largest pitch diameter."""
    return int(MAX_DRIVEN_PITCH_DIAMETER_M * 1000 * math.pi / pitch_mm)


def design_from_mapping(table: dict[str, Any], source: str) -> Design:
    """Build and check a Design from a [design] table; ValueError in one line naming key, value and range."""
    if not isinstance(table, dict):
        raise ValueError(f"{source}: [design] must be a table, got {table!r}")
    unknown = sorted(set(table) - set(_KEYS))
    if unknown:
        raise ValueError(f"{source}: [design] has no key {unknown[0]!r}: the keys are {', '.join(_KEYS)}")
    missing = [k for k in _KEYS[:4] if k not in table]
    if missing:
        raise ValueError(f"{source}: [design] needs {', '.join(missing)} (the keys are {', '.join(_KEYS)})")
    motor = table["motor"]
    if not isinstance(motor, str) or not motor:
        raise ValueError(f"{source}: [design] motor = {motor!r} must be a profiles/motors/ name or a path")
    try:
        load_motor(motor)
    except ValueError as e:
        raise ValueError(f"{source}: [design] motor = {motor!r}: {e}") from None
    pitch = table["belt_pitch_mm"]
    if isinstance(pitch, bool) or not isinstance(pitch, (int, float)) or float(pitch) not in BELT_PITCHES:
        raise ValueError(f"{source}: [design] belt_pitch_mm = {pitch!r} is not allowed: one of "
                         f"{', '.join(f'{p:g} ({n})' for p, (n, _) in BELT_PITCHES.items())}")
    pitch = float(pitch)
    most = max_teeth(pitch)
    driver = _teeth(table["belt_driver_teeth"], "belt_driver_teeth", pitch, source, most)
    driven = _teeth(table["belt_driven_teeth"], "belt_driven_teeth", pitch, source, most)
    battery = _named_profile(table, "battery", "batteries", source)
    ground = _named_profile(table, "ground_sensors", "ground_sensors", source)
    spring = None
    if "spring" in table:
        spring = _spring(table["spring"], source)
    width = table.get("belt_width_mm")
    if width is not None:
        width = _number(width, "belt_width_mm", 1.0, 100.0, source, " mm")
        try:
            belt_width_mm(pitch, width)
        except ValueError as e:
            raise ValueError(f"{source}: [design] {e}") from None
    return Design(motor=motor, belt_driver_teeth=driver, belt_driven_teeth=driven, belt_pitch_mm=pitch,
                  spring=spring, battery=battery, belt_width_mm=width, ground_sensors=ground)


def _named_profile(table: dict[str, Any], key: str, directory: str, source: str) -> str | None:
    """The [design] key naming a profiles/<directory>/ profile (or a path), checked that it exists; None if absent."""
    name = table.get(key)
    if name is None:
        return None
    if not isinstance(name, str) or not name:
        raise ValueError(f"{source}: [design] {key} = {name!r} must be a profiles/{directory}/ name or a path")
    from hal.virtual.plant.sourced import resolve_profile

    try:
        path = resolve_profile(name, directory, key.replace("_", " "))
    except ValueError as e:
        raise ValueError(f"{source}: [design] {e}") from None
    if not path.is_file():
        raise ValueError(f"{source}: [design] {key} = {name!r}: no such file")
    return name



def _spring(table: object, source: str) -> DesignSpring:
    """The [design.spring] table, checked."""
    if not isinstance(table, dict):
        raise ValueError(f"{source}: [design.spring] must be a table, got {table!r}")
    unknown = sorted(set(table) - set(_SPRING_KEYS))
    if unknown:
        raise ValueError(f"{source}: [design.spring] has no key {unknown[0]!r}: the keys are "
                         f"{', '.join(_SPRING_KEYS)}")
    k = _number(table.get("stiffness_nm_per_rad", 0.0), "spring.stiffness_nm_per_rad", 0.0,
                MAX_SPRING_NM_PER_RAD, source, " N m/rad")
    engage = _number(table.get("engage_deg", 0.0), "spring.engage_deg", -MAX_ENGAGE_DEG, MAX_ENGAGE_DEG,
                     source, " deg")
    sided = table.get("sided", "one")
    if sided not in SPRING_SIDES:
        raise ValueError(f"{source}: [design] spring.sided = {sided!r} is not allowed: one of "
                         f"{', '.join(repr(s) for s in SPRING_SIDES)}")
    return DesignSpring(stiffness_nm_per_rad=k, engage_deg=engage, sided=sided)


def load_design(path: str | Path) -> Design | None:
    """The [design] of a design profile, checked; None for a profile without one."""
    from profiles import read_toml

    p = Path(path)
    doc = read_toml(p, "design profile")
    if "design" not in doc:
        return None
    return design_from_mapping(doc["design"], str(p))


def nearest_belt_pairs(ratio: float, pitch_mm: float | None = None, count: int = 3) -> list[tuple[float, int, int]]:
    """The whole tooth pairs (pitch, driver, driven) nearest to ``ratio``, nearest first (ties: smaller pulleys)."""
    pitches = BELT_PITCHES if pitch_mm is None else {float(pitch_mm): BELT_PITCHES[float(pitch_mm)]}
    pairs: list[tuple[float, float, float, int, int]] = []
    for pitch, (_, fewest) in pitches.items():
        most = max_teeth(pitch)
        for driver in range(fewest, most + 1):
            driven = min(max(round(ratio * driver), fewest), most)
            error = abs(driven / driver - ratio) / ratio
            pairs.append((error, driven * pitch, pitch, driver, driven))
    pairs.sort()
    return [(pitch, driver, driven) for _, _, pitch, driver, driven in pairs[:count]]


def belt_for_ratio(ratio: float, pitch_mm: float | None = None) -> tuple[int, int]:
    """(driver, driven) teeth of ``pitch_mm`` (default 2 mm) giving ``ratio`` within 1 % with the smallest ankle
    pulley; ValueError naming the nearest pairs when no whole pair does."""
    pitch = 2.0 if pitch_mm is None else float(pitch_mm)
    if pitch not in BELT_PITCHES:
        allowed = ", ".join(f"{p:g}" for p in BELT_PITCHES)
        raise ValueError(f"belt pitch {pitch_mm!r} mm is not allowed: one of {allowed}")
    if not (isinstance(ratio, (int, float)) and math.isfinite(ratio) and ratio > 0):
        raise ValueError(f"belt ratio {ratio!r} is not allowed: a positive number")
    _, fewest = BELT_PITCHES[pitch]
    most = max_teeth(pitch)
    for driven in range(fewest, most + 1):  # smallest ankle pulley first
        driver = round(driven / ratio)
        if fewest <= driver <= most and abs(driven / driver - ratio) <= BELT_RATIO_TOLERANCE * ratio:
            return driver, driven
    near = nearest_belt_pairs(ratio, pitch)
    listed = ", ".join(f"{dn}/{dr} = {dn / dr:.3f} at {p:g} mm" for p, dr, dn in near)
    raise ValueError(f"belt ratio {ratio!r} is not allowed: no whole tooth pair of the {pitch:g} mm pitch gives it "
                     f"within {BELT_RATIO_TOLERANCE:.0%} (teeth {fewest}..{most}); nearest pairs: {listed}")


def plant_params_for(design: Design, base: PlantParams) -> PlantParams:
    """The plant of ``design``: its motor, gearbox, belt and spring, with the base plant's driver, foot and bench.

    Rules (docs/design.md, "Transmission"): Ke = 60 / (2 pi Kv); the pulleys' inertias scale with the fourth
    power of their pitch diameters (discs of the base's width); the static friction is the motor's back-drive
    torque through the belt and the kinetic friction keeps the base's share of it; the backdriven efficiency is
    the planetary's by the meshing-loss argument (hal/virtual/plant/transmission.py) times the belt's.
    """
    m = design.motor_spec()
    driver_d, driven_d = design.driver_pitch_diameter_m, design.driven_pitch_diameter_m
    friction_share = base.coulomb_friction_nm / base.static_friction_nm if base.static_friction_nm > 0 else 0.0
    spring = design.spring if design.has_spring else None
    return replace(
        base,
        **{key: getattr(m, key) for key in MOTOR_KEYS},
        ke_v_s_per_rad=60.0 / (2.0 * math.pi * m.kv_rpm_per_v),
        gearbox_ratio=m.gear_ratio,
        belt_ratio=design.belt_ratio,
        belt_driver_pitch_diameter_m=driver_d,
        belt_driven_pitch_diameter_m=driven_d,
        actuator_output_inertia_kg_m2=base.actuator_output_inertia_kg_m2
        * (driver_d / base.belt_driver_pitch_diameter_m) ** 4,
        ankle_pulley_inertia_kg_m2=base.ankle_pulley_inertia_kg_m2
        * (driven_d / base.belt_driven_pitch_diameter_m) ** 4,
        actuator_backdrive_torque_nm=m.backdrive_torque_nm,
        coulomb_friction_nm=friction_share * m.backdrive_torque_nm * design.belt_ratio,
        efficiency_backdriven=planetary_backdriven_efficiency(base.gearbox_efficiency, m.gear_ratio)
        * base.belt_efficiency,
        **_spring_params(spring),
    )


def belt_tension_per_amp_n(params: PlantParams) -> float:
    """Belt tension per ampere of q current in the worse direction: backdriven, holding the rotor's Kt i takes
    Kt i N_gearbox / eta_back at the actuator's output (more than driving gives), over the driver pulley's radius."""
    torque = params.kt_nm_per_a * params.gearbox_ratio / planetary_backdriven_efficiency(
        params.gearbox_efficiency, params.gearbox_ratio)
    return belt_tension_n(torque, params.belt_driver_pitch_diameter_m)


def _spring_params(spring: DesignSpring | None) -> dict[str, Any]:
    """The plant's parallel-spring keys for a design's spring (none: the base's, no spring)."""
    if spring is None:
        return {}
    return {"parallel_stiffness_nm_per_rad": spring.stiffness_nm_per_rad,
            "parallel_engage_rad": spring.engage_rad,
            "parallel_two_sided": spring.sided == "two"}

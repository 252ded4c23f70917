"""The spec of a design search (`pafp design SPEC.toml`): motors x belts x springs x batteries x body masses x
speeds, each point a walking run of the firmware on its design profile; checked whole before any run
(docs/design.md)::

    [search]
    profile = "../firmware.toml"       # base firmware profile, relative to the spec (default profiles/firmware.toml)
    motors = ["ak60_6", "ak80_9"]      # profiles/motors/ names (or paths, relative to the spec)
    batteries = ["auto"]               # profiles/batteries/ names, "auto" (the shipped pack whose full voltage is
                                       # nearest the motor's supply) or "none" (the ideal supply)
    body_masses_kg = [60, 80]          # the walker's mass, 1..300 kg
    speeds = ["free", "fast"]          # speed groups of the normative data (host_tools/walk.py SPEEDS)
    strides = 20                       # per point, 1..10000
    controller = "impedance"           # a shipped controller (firmware/control/registry.py)
    ground_sensors = "pylon_300nm"     # every design's ground sensors: a profiles/ground_sensors/ name (default:
                                       # the packaged profiles/ground_sensors.toml)
    seed = 0                           # run seed, 0..2^32-1
    timeout_s = 900                    # wall seconds per point
    ambient_c = 25.0                   # the motor's surroundings, -40..80 C (pafp run --ambient-c)
    min_moment_share = 0.9             # a design "walks" the person when it delivers this share of the stance
                                       # moment, without a fault and within the thermal limit,
    max_tracking_rms_deg = 5.0         # and tracks the gait within this RMS (the encoder's, in RUN),
    min_thermal_margin_c = 20.0        # its steady winding (housing resistance at its pessimistic end) this far
                                       # below [thermal] derate_start_c,
    belt_within_rating = true          # and its belt's peak tension within the belt's rated working tension

    [[belt]]                           # one per ratio: the belt's tooth pair and pitch
    driver_teeth = 12                  # whole teeth from the pitch's smallest stock pulley (12 at 2 mm, 16 at 3,
    driven_teeth = 56                  # 18 at 5, 22 at 8) to a 100 mm ankle pulley (157 at 2 mm, 104, 62, 39)
    pitch_mm = 5.0                     # 2, 3, 5 or 8 mm

    [[spring]]                         # a parallel spring; one without stiffness (or 0) is "no spring"
    stiffness_nm_per_rad = 150.0       # 0..2000 N m/rad (the plant's hard stop)
    engage_deg = 0.0                   # -30..30 deg
    sided = "one"

Points are the product motor (outermost) x belt x spring x battery x body mass x speed (innermost), numbered
from 0. Every point's [design] table goes through the design loader (hal/virtual/plant/design.py) and its
profile through the firmware's loader before any run, so a bad value stops the search in one line.
"""

from __future__ import annotations

import hashlib
import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from firmware.config import DEFAULT_PROFILE
from hal.virtual.plant.design import BELT_PITCHES, MAX_ENGAGE_DEG, MAX_SPRING_NM_PER_RAD, max_teeth
from host_tools.studies.spec_values import SpecValues
from host_tools.studies.sweep_spec import SpecError

__all__ = ["DesignPoint", "DesignSpec", "SEARCH_KEYS", "WalkCriteria", "load_design_spec", "pick_battery"]

SEARCH_KEYS = ("profile", "motors", "batteries", "body_masses_kg", "speeds", "strides", "controller", "seed",
               "ground_sensors", "timeout_s", "ambient_c", "min_moment_share",
               "max_tracking_rms_deg", "min_thermal_margin_c", "belt_within_rating")
BELT_KEYS = ("driver_teeth", "driven_teeth", "pitch_mm")
SPRING_KEYS = ("stiffness_nm_per_rad", "engage_deg", "sided")
MAX_POINTS = 10_000


@dataclass(frozen=True)
class WalkCriteria:
    """What a point must show to walk the person (docs/design.md, "Reading the search")."""

    min_moment_share: float = 0.9
    max_tracking_rms_deg: float = 5.0
    min_thermal_margin_c: float = 20.0  # the pessimistic steady winding this far below [thermal] derate_start_c
    belt_within_rating: bool = True  # the belt's peak tension within its rated working tension


@dataclass(frozen=True)
class DesignPoint:
    """One search point: everything a worker needs (picklable; the design profile's text travels with it)."""

    index: int
    motor: str
    driver_teeth: int
    driven_teeth: int
    pitch_mm: float
    spring_nm_per_rad: float
    spring_engage_deg: float
    spring_sided: str
    battery: str  # a pack name, or "" for the ideal supply
    body_mass_kg: float
    speed: str
    strides: int
    controller: str
    seed: int
    timeout_s: float
    ambient_c: float
    profile_name: str  # where the command writes the design profile (the rerun command names it)
    profile_text: str

    @property
    def ratio(self) -> float:
        """The belt ratio, driven / driver teeth."""
        return self.driven_teeth / self.driver_teeth

    @property
    def spring_label(self) -> str:
        """``none`` or ``150 N·m/rad from 0° (one-sided)``."""
        if not self.spring_nm_per_rad:
            return "none"
        return f"{self.spring_nm_per_rad:g} N·m/rad from {self.spring_engage_deg:g}° ({self.spring_sided}-sided)"

    def label(self) -> str:
        """A short description for tables and the progress line."""
        return (f"{self.motor}, belt {self.driver_teeth}/{self.driven_teeth} x {self.pitch_mm:g} mm, spring "
                f"{self.spring_label}, {self.battery or 'ideal supply'}, {self.body_mass_kg:g} kg, {self.speed}")


def design_table(motor: str, belt: tuple[int, int, float], spring: tuple[float, float, str],
                 battery: str, ground_sensors: str = "") -> dict[str, Any]:
    """The [design] table of one design (the shared contract of issue 23)."""
    table: dict[str, Any] = {"motor": motor, "belt_driver_teeth": belt[0], "belt_driven_teeth": belt[1],
                             "belt_pitch_mm": belt[2]}
    if spring[0]:
        table["spring"] = {"stiffness_nm_per_rad": spring[0], "engage_deg": spring[1], "sided": spring[2]}
    if battery:
        table["battery"] = battery
    if ground_sensors:
        table["ground_sensors"] = ground_sensors
    return table


@dataclass(frozen=True)
class DesignSpec:
    """A checked search spec; ``profiles`` holds each design's profile text, keyed by its design."""

    path: Path
    base_profile: Path
    motors: tuple[str, ...]
    batteries: tuple[str, ...]
    body_masses_kg: tuple[float, ...]
    speeds: tuple[str, ...]
    belts: tuple[tuple[int, int, float], ...]
    springs: tuple[tuple[float, float, str], ...]
    strides: int
    controller: str
    seed: int
    timeout_s: float
    ambient_c: float
    criteria: WalkCriteria
    profiles: dict[tuple[Any, ...], str]
    digest: str
    ground_sensors: str = ""  # a profiles/ground_sensors/ name for every design ("": the packaged profile)

    def designs(self) -> list[tuple[str, tuple[int, int, float], tuple[float, float, str], str]]:
        """(motor, belt, spring, battery) of every design, in point order (batteries resolved per motor)."""
        out = []
        for motor, belt, spring, battery in itertools.product(self.motors, self.belts, self.springs, self.batteries):
            design = (motor, belt, spring, pick_battery(battery, motor))
            if design not in out:
                out.append(design)
        return out

    def points(self, out_dir: Path | None = None) -> list[DesignPoint]:
        """Every point, in index order; profile_name is its design profile's path under out_dir."""
        points: list[DesignPoint] = []
        for design in self.designs():
            motor, belt, spring, battery = design
            for mass, speed in itertools.product(self.body_masses_kg, self.speeds):
                i = len(points)
                name = str((out_dir or Path("runs") / f"design-{self.path.stem}") / "points" / f"{i:04d}" /
                           "design.toml")
                points.append(DesignPoint(i, motor, belt[0], belt[1], belt[2], spring[0], spring[1], spring[2],
                                          battery, mass, speed, self.strides, self.controller, self.seed,
                                          self.timeout_s, self.ambient_c, name, self.profiles[design]))
        return points


def pick_battery(name: str, motor: str) -> str:
    """The pack of a point: "none" -> "" (ideal supply), "auto" -> the shipped pack whose full open-circuit
    voltage is nearest the motor's supply voltage, else the name as given."""
    if name == "none":
        return ""
    if name != "auto":
        return name
    from hal.virtual.plant.battery import battery_names, load_battery
    from hal.virtual.plant.motors import load_motor

    supply = load_motor(motor).supply_voltage_v
    return min(battery_names(), key=lambda b: (abs(load_battery(b).open_circuit_v(1.0) - supply), b))


KIND = "design spec"
_SPEC = SpecValues(KIND, "[search]")
_err, _number, _int, _list = _SPEC.error, _SPEC.number, _SPEC.integer, _SPEC.nonempty_list


def _names(path: Path, key: str, values: list[Any], known: list[str], extra: tuple[str, ...] = ()) -> tuple[str, ...]:
    for v in values:
        if not isinstance(v, str) or (v not in known and v not in extra and not (path.parent / v).is_file()):
            raise _err(path, f"[search] {key}", v, f"one of {', '.join([*extra, *known])} (or a profile file)")
    return tuple(v if v in known or v in extra else str((path.parent / v).resolve()) for v in values)


def _belts(path: Path, doc: dict[str, Any]) -> tuple[tuple[int, int, float], ...]:
    belts = doc.get("belt")
    if not isinstance(belts, list) or not belts:
        raise SpecError(f"design spec {path}: no [[belt]]: give at least one (driver_teeth, driven_teeth, pitch_mm)")
    out = []
    for k, b in enumerate(belts):
        extra = sorted(set(b) - set(BELT_KEYS))
        if extra:
            raise SpecError(f"design spec {path}: [[belt]] {k} key {extra[0]!r} unknown: one of {', '.join(BELT_KEYS)}")
        for key in BELT_KEYS:
            if key not in b:
                raise SpecError(f"design spec {path}: [[belt]] {k} has no {key!r}")
        pitch = b["pitch_mm"]
        if isinstance(pitch, bool) or pitch not in BELT_PITCHES:  # the teeth's range depends on it
            raise _err(path, f"[[belt]] {k} pitch_mm", pitch, f"one of {', '.join(f'{p:g}' for p in BELT_PITCHES)}")
        fewest, most = BELT_PITCHES[pitch][1], max_teeth(pitch)  # the design loader's limits, not looser ones
        out.append((_int(path, f"[[belt]] {k} driver_teeth", b["driver_teeth"], fewest, most),
                    _int(path, f"[[belt]] {k} driven_teeth", b["driven_teeth"], fewest, most), float(pitch)))
    if len(set(out)) != len(out):
        raise SpecError(f"design spec {path}: [[belt]] repeats a tooth pair and pitch")
    return tuple(out)


def _springs(path: Path, doc: dict[str, Any]) -> tuple[tuple[float, float, str], ...]:
    out = []
    for k, s in enumerate(doc.get("spring", [{}])):
        extra = sorted(set(s) - set(SPRING_KEYS))
        if extra:
            raise SpecError(f"design spec {path}: [[spring]] {k} key {extra[0]!r} unknown: one of "
                            f"{', '.join(SPRING_KEYS)}")
        k_nm = _number(path, f"[[spring]] {k} stiffness_nm_per_rad", s.get("stiffness_nm_per_rad", 0.0), 0.0,
                       MAX_SPRING_NM_PER_RAD)
        engage = _number(path, f"[[spring]] {k} engage_deg", s.get("engage_deg", 0.0), -MAX_ENGAGE_DEG, MAX_ENGAGE_DEG)
        sided = _SPEC.choice(path, f"[[spring]] {k} sided", s.get("sided", "one"), ("one", "two"))
        out.append((k_nm, engage, sided) if k_nm else (0.0, 0.0, "one"))
    if len(set(out)) != len(out):
        raise SpecError(f"design spec {path}: [[spring]] repeats a spring (every spring without stiffness is "
                        "the same: none)")
    return tuple(out)


def _profile_of(path: Path, base: Path, design: tuple[Any, ...], ground: str = "") -> str:
    """The design's profile text (host_tools/design_profile.py), checked by the design and firmware loaders."""
    import tempfile

    from firmware.config import load_firmware_config
    from hal.virtual.plant.design import design_from_mapping
    from host_tools.design_profile import design_profile_text

    motor, belt, spring, battery = design
    where = f"design spec {path}: design ({', '.join(map(str, design))})"
    tmp_path = ""
    try:
        d = design_from_mapping(design_table(motor, belt, spring, battery, ground), f"{path} [design]")
        text = design_profile_text(d, base)
        with tempfile.TemporaryDirectory(prefix="pafp-design-") as tmp:
            p = Path(tmp) / "design.toml"
            tmp_path = str(p)
            p.write_text(text, encoding="utf-8")
            load_firmware_config(p)
    except (ValueError, TypeError) as e:
        message = str(e).replace(tmp_path, "its design profile") if tmp_path else str(e)
        raise SpecError(f"{where}: {message}".replace("\n", " ")) from None
    return text


def load_design_spec(path: Path) -> DesignSpec:
    """Read and check a search spec and build every design's profile; SpecError (one line naming the file, the
    key, the value and the allowed range) otherwise."""
    path = Path(path)
    text, doc = _SPEC.read(path, ("[search]", "[[belt]]", "[[spring]]"))
    s = doc.get("search", {})
    bad = sorted(set(s) - set(SEARCH_KEYS))
    if bad:
        raise SpecError(f"design spec {path}: [search] key {bad[0]!r} unknown: one of {', '.join(SEARCH_KEYS)}")
    base = _SPEC.file(path, "[search] profile", s["profile"]) if "profile" in s else DEFAULT_PROFILE
    from firmware.control.registry import CONTROLLERS
    from hal.virtual.plant.battery import battery_names
    from hal.virtual.plant.motors import catalogue_names
    from host_tools.walk import SPEEDS

    motors = _names(path, "motors", _list(path, s, "motors", ["ak60_6"]), catalogue_names())
    batteries = _names(path, "batteries", _list(path, s, "batteries", ["auto"]), battery_names(), ("auto", "none"))
    masses = tuple(_number(path, "[search] body_masses_kg", v, 1.0, 300.0)
                   for v in _list(path, s, "body_masses_kg", [80.0]))
    speeds = tuple(_list(path, s, "speeds", ["free"]))
    for v in speeds:
        _SPEC.choice(path, "[search] speeds", v, SPEEDS)
    strides = _int(path, "[search] strides", s.get("strides", 20), 1, 10_000)
    controller = _SPEC.choice(path, "[search] controller", s.get("controller", "impedance"), CONTROLLERS)
    seed = _int(path, "[search] seed", s.get("seed", 0), 0, 2**32 - 1)
    timeout = _number(path, "[search] timeout_s", s.get("timeout_s", 900.0), 0.0, 86_400.0, True)
    ambient = _number(path, "[search] ambient_c", s.get("ambient_c", 25.0), -40.0, 80.0)
    belt_rule = s.get("belt_within_rating", True)
    if not isinstance(belt_rule, bool):
        raise _err(path, "[search] belt_within_rating", belt_rule, "true or false")
    criteria = WalkCriteria(_number(path, "[search] min_moment_share", s.get("min_moment_share", 0.9), 0.0, 1.0),
                            _number(path, "[search] max_tracking_rms_deg", s.get("max_tracking_rms_deg", 5.0), 0.0,
                                    90.0, True),
                            _number(path, "[search] min_thermal_margin_c", s.get("min_thermal_margin_c", 20.0),
                                    -200.0, 200.0),
                            belt_rule)
    belts, springs = _belts(path, doc), _springs(path, doc)
    n = len(motors) * len(belts) * len(springs) * len(batteries) * len(masses) * len(speeds)
    if not 1 <= n <= MAX_POINTS:
        raise SpecError(f"design spec {path}: {n} points out of range: 1..{MAX_POINTS}")
    ground = s.get("ground_sensors", "")
    if not isinstance(ground, str):
        raise _err(path, "[search] ground_sensors", ground, "a profiles/ground_sensors/ name")
    spec = DesignSpec(path, Path(base), motors, batteries, masses, speeds, belts, springs, strides, controller,
                      seed, timeout, ambient, criteria, {}, "", ground)
    profiles = {d: _profile_of(path, Path(base), d, ground) for d in spec.designs()}
    digest = hashlib.sha256("\0".join([text, *(f"{d!r}\0{t}" for d, t in profiles.items())]).encode()).hexdigest()
    return DesignSpec(path, Path(base), motors, batteries, masses, speeds, belts, springs, strides, controller,
                      seed, timeout, ambient, criteria, profiles, digest, ground)

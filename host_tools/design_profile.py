"""Write a design profile: a complete firmware profile for a design's motor and transmission, plus its [design].

The firmware never reads [design]; what it needs of the motor is written into its own sections here
(docs/design.md, "How the firmware follows the motor"):

- [control] current_limit_a and [safety] current_limit_a from the motor's peak current
  (:data:`SAFETY_SHARE_OF_PEAK`, :data:`CONTROL_SHARE_OF_TRIP`), [safety] brake_current_a at most its
  rated current, [control] velocity_limit_rad_s at most its no-load speed at the ankle;
- [feedforward] the foot of the base plant, the rotor inertia reflected through the design's ratio, Kt,
  the total ratio and the base plant's transmission efficiency; on request (a design file whose [feedforward] has
  efficiency_backdriven) also the backdriven efficiency of the design's plant, with which the controllers ask
  eta_fwd eta_back of the current for a moment against the motion (off by default: the impedance controller's
  default gains were chosen with one efficiency both ways, and with it an AK10-9 at 5:1 walking 80 kg latches
  ANGLE_LIMIT);
- [feedforward] parallel_* the design's parallel spring, which the cascade's feed-forward and the impedance
  controller take off the moment they ask of the motor;
- [safety] belt_ratio, the design's;
- [motor] the motor's ratings (firmware/motor_ratings.py): peak and rated current, Kt, planetary, pole pairs,
  no-load speed and the CAN MIT ranges, which bound the limits above and scale the drivers.

The shipped designs in ``profiles/designs/`` are this module's output (a test writes them again and
compares). ``python -m host_tools.design_profile DESIGN.toml [HEADER.txt]`` prints the profile of a file holding a
[design] table (and its [controller] table, if it has one: the controller and gains chosen for the design; and the
backdriven efficiency if its [feedforward] has efficiency_backdriven), with the text of HEADER.txt (how the design was
chosen) as comments at the top.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

from hal.virtual.plant.design import Design, design_from_mapping, plant_params_for
from hal.virtual.plant.params import PlantParams, load_plant_params

__all__ = ["CONTROL_SHARE_OF_TRIP", "SAFETY_SHARE_OF_PEAK", "check_ratings", "derived_sections", "design_profile_text"]

SAFETY_SHARE_OF_PEAK = 0.88
"""[safety] current_limit_a = 0.88 x the motor's peak current: the AK60-6 profile's 20 A of 22.7 A. The trip must
sit below the driver's own clamp (a limit at the peak never trips) with room for the measurement's noise."""
CONTROL_SHARE_OF_TRIP = 0.6
"""[control] current_limit_a = 0.6 x the safety trip: the AK60-6 profile's 12 A of 20 A, the margin its gains were
tuned with (the current loop's lag and the feed-forward's error stay clear of the trip)."""


def _round_down(x: float, digits: int) -> float:
    """x rounded down at ``digits`` decimals (a limit written must not exceed the bound it came from)."""
    scale = 10.0**digits
    return math.floor(x * scale) / scale


def derived_sections(design: Design, base_plant: PlantParams | None = None,
                     backdriven_current: bool = False) -> dict[str, dict[str, tuple[Any, str]]]:
    """section -> key -> (value, why) of every firmware value the design decides; ``backdriven_current``: also
    [feedforward] efficiency_backdriven (the controllers ask eta_fwd eta_back of the current against the motion)."""
    plant = plant_params_for(design, base_plant if base_plant is not None else load_plant_params())
    m = design.motor_spec()
    trip = round(SAFETY_SHARE_OF_PEAK * m.peak_current_a, 1)
    control = round(CONTROL_SHARE_OF_TRIP * trip, 1)
    ankle_speed = m.no_load_speed_rpm * 2 * math.pi / 60 / design.belt_ratio
    n = plant.total_ratio
    inertia = plant.foot_output_inertia_kg_m2 + plant.rotor_inertia_kg_m2 * n**2
    return {
        "control": {
            "current_limit_a": (control, f"{CONTROL_SHARE_OF_TRIP:g} x the {trip:g} A trip ({m.name})"),
            "velocity_limit_rad_s": (min(8.0, _round_down(ankle_speed, 3)),
                                     f"8 rad/s, at most the no-load speed at the ankle ({ankle_speed:.2f} rad/s)"),
        },
        "feedforward": {
            "inertia_kg_m2": (round(inertia, 6), f"J_c + m d^2 + J_rotor N^2 ({m.rotor_inertia_kg_m2:.4g} x "
                                                 f"{n:.3f}^2)"),
            "mass_kg": (plant.foot_mass_kg, "the foot (base plant)"),
            "lever_m": (plant.foot_com_distance_m, "the foot (base plant)"),
            "torque_constant_nm_per_a": (m.kt_nm_per_a, f"{m.name} Kt"),
            "gear_ratio": (round(n, 6), f"{m.gear_ratio:g}:1 planetary x {design.belt_driven_teeth}/"
                                        f"{design.belt_driver_teeth} belt"),
            "efficiency": (round(plant.efficiency, 6), "gearbox x belt efficiency (base plant)"),
            **_spring_keys(design),
            **({"efficiency_backdriven": (round(plant.efficiency_backdriven, 6), "backdriven: the planetary's "
                                          "(hal/virtual/plant/transmission.py) x the belt's")}
               if backdriven_current else {}),
        },
        "motor": {
            "model": (m.name, f"{m.model} (profiles/motors/{m.name}.toml): the ratings below are its"),
            "peak_current_a": (m.peak_current_a, "bounds [control] and [safety] current_limit_a"),
            "rated_current_a": (m.rated_current_a, "bounds [safety] brake_current_a"),
            "torque_constant_nm_per_a": (m.kt_nm_per_a, "Kt: MIT mode's torque per ampere with gear_ratio"),
            "gear_ratio": (m.gear_ratio, "the actuator's planetary"),
            "pole_pairs": (m.pole_pairs, "ERPM = pole pairs x rotor rpm"),
            "no_load_speed_rpm": (m.no_load_speed_rpm, "at the actuator's output: bounds velocity_limit_rad_s"),
            "mit_p_max_rad": (m.p_max_rad, "CAN MIT position range"),
            "mit_v_max_rad_s": (m.v_max_rad_s, "CAN MIT velocity range"),
            "mit_t_max_nm": (m.t_max_nm, "CAN MIT torque range"),
        },
        **_ground_sensor_keys(design),
        "safety": {
            "current_limit_a": (trip, f"{SAFETY_SHARE_OF_PEAK:g} x the {m.peak_current_a:g} A peak ({m.name})"),
            "brake_current_a": (min(2.0, m.rated_current_a), f"2 A, at most the {m.rated_current_a:g} A rated"),
            "belt_ratio": (round(design.belt_ratio, 6), f"{design.belt_driven_teeth}/{design.belt_driver_teeth} teeth"),
        },
    }


def check_ratings(design: Design, ratings: object, source: str) -> None:
    """ValueError (one line) when a profile's [motor] ratings (firmware.motor_ratings.MotorRatings) are not those of
    the catalogue motor its [design] names: the firmware would bound the currents of one motor while the bench
    runs another."""
    for key, (expected, _) in derived_sections(design)["motor"].items():
        got = getattr(ratings, key)
        same = got == expected if isinstance(expected, str) else math.isclose(got, expected, rel_tol=1e-9)
        if not same:
            raise ValueError(f"{source}: [motor] {key} = {got!r} is not the catalogue's {expected!r} for the "
                             f"[design] motor {design.motor!r} (profiles/motors/{design.motor}.toml): write the "
                             "profile's motor sections with `python -m host_tools.design_profile` (docs/design.md)")


def _ground_sensor_keys(design: Design) -> dict[str, dict[str, tuple[Any, str]]]:
    """[ground_sensors] calibration for a design that fits its own ground sensor profile (none: the base profile's,
    which is the packaged cell's): the inverse of the cell's bridge sensitivity (crosstalk included) times the gains,
    as its calibration certificate gives it (6 significant digits, as the base profile's)."""
    path = design.ground_profile
    if path is None:
        return {}
    import numpy as np

    from hal.virtual.ground_sensors import load_ground_profile

    cell = load_ground_profile(path)[0]
    inverse = np.linalg.inv(np.diag([cell.force_gain, cell.moment_gain]) @ np.array(cell.sensitivity()))
    matrix = [[float(f"{x:.6g}") for x in row] for row in inverse.tolist()]
    return {"ground_sensors": {"calibration": (matrix, f"the inverse of the {path.stem} cell's sensitivity x gains "
                                                       f"({cell.rated_moment_nm:g} N m rated)")}}


def _spring_keys(design: Design) -> dict[str, tuple[Any, str]]:
    """[feedforward]'s parallel-spring keys: the controllers take its moment off what they ask of the motor."""
    spring = design.spring
    if spring is None or not design.has_spring:
        return {}
    return {"parallel_stiffness_nm_per_rad": (spring.stiffness_nm_per_rad, "the design's parallel spring"),
            "parallel_engage_deg": (spring.engage_deg, "where it engages"),
            "parallel_two_sided": (spring.sided == "two", f"{spring.sided}-sided")}


def design_profile_text(design: Design, base_profile_path: str | Path | None = None, *, header: str = "",
                        base_plant: PlantParams | None = None, controller: dict[str, Any] | None = None,
                        backdriven_current: bool = False) -> str:
    """A complete, runnable design profile: the base firmware profile with the design's values, and [design];
    ``controller``: its [controller] table (the controller and the gains chosen for the design), as given;
    ``backdriven_current``: see :func:`derived_sections`."""
    import tomlkit

    from firmware.config import DEFAULT_PROFILE

    base = Path(base_profile_path) if base_profile_path is not None else DEFAULT_PROFILE
    doc = tomlkit.parse(base.read_text(encoding="utf-8"))
    if "design" in doc:
        del doc["design"]
    for section, values in derived_sections(design, base_plant, backdriven_current).items():
        if section not in doc:
            doc[section] = tomlkit.table()
        table: Any = doc[section]
        for key, (value, why) in values.items():
            item = tomlkit.item(value)
            item.comment(f"design: {why}")
            table[key] = item
    if controller:
        doc["controller"] = tomlkit.item(dict(controller))
    table = tomlkit.table()
    for key, value in design.as_table().items():
        if key == "spring":
            spring = tomlkit.table()
            for k, v in value.items():
                spring[k] = v
            table.append("spring", spring)
        else:
            table[key] = value
    doc["design"] = table
    lines = [f"# Design profile: {design.motor}, {design.belt_driven_teeth}/{design.belt_driver_teeth} belt at "
             f"{design.belt_pitch_mm:g} mm pitch"
             + (f", parallel spring {design.spring.stiffness_nm_per_rad:g} N m/rad from "  # type: ignore[union-attr]
                f"{design.spring.engage_deg:g} deg ({design.spring.sided}-sided)" if design.has_spring else "")  # type: ignore[union-attr]
             + ".",
             f"# Written by host_tools/design_profile.py (design_profile_text) from the firmware profile {base.name};",
             "# values marked 'design:' follow the motor and the transmission (docs/design.md)."]
    lines += [f"# {line}" if line else "#" for line in header.splitlines()]
    return "\n".join(lines) + "\n" + tomlkit.dumps(doc)


def main(argv: list[str] | None = None) -> int:
    """Print the design profile of a TOML file holding a [design] table."""
    from profiles import read_toml

    args = sys.argv[1:] if argv is None else argv
    if len(args) not in (1, 2):
        print("usage: python -m host_tools.design_profile FILE.toml [HEADER.txt] (FILE has a [design] table)",
              file=sys.stderr)
        return 2
    try:
        doc = read_toml(Path(args[0]), "design file")
        design = design_from_mapping(doc.get("design", {}), args[0])
        header = Path(args[1]).read_text(encoding="utf-8") if len(args) == 2 else ""
    except (ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    backdriven = "efficiency_backdriven" in doc.get("feedforward", {})
    sys.stdout.write(design_profile_text(design, header=header, controller=doc.get("controller"),
                                         backdriven_current=backdriven))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

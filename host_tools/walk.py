"""The walking scenario's inputs: the ankle-moment curve (packaged normative, or a user's CSV) and the load."""

from __future__ import annotations

import csv
import io
from importlib import resources
from pathlib import Path

from hal.virtual.plant.ground import GroundReaction
from hal.virtual.plant.walking import WalkingLoad

__all__ = ["ADULT_FREE_PEAK_MOMENT_NM_PER_KG", "CHILD_MAX_BODY_MASS_KG", "GRF_CSV", "MOMENT_COLUMN", "POPULATIONS",
           "SCENARIOS", "adult_moment_scale", "ground_reaction", "moment_curve", "population_for", "walking_load"]

SCENARIOS = ("suspended", "walk")
SPEEDS = {"very-slow": "Very Slow", "slow": "Slow", "free": "Free", "fast": "Fast", "very-fast": "Very Fast"}
"""--speed choices -> speed_category of firmware/data/ankle_normative_all_speeds.csv (Schwartz et al. 2008)."""
ALL_SPEEDS = "ankle_normative_all_speeds.csv"
MOMENT_COLUMN = "ankle_moment_nm_per_kg_mean"
NORMATIVE = "firmware/data/ankle_normative.csv"
POPULATIONS = ("adult", "child")
"""Whose ankle moment the packaged curves give (``--population``): the measured children's, or adult-shaped."""
CHILD_MAX_BODY_MASS_KG = 50.0
"""[I] Above this body mass the walker is taken as an adult unless ``--population child`` says otherwise."""
ADULT_FREE_PEAK_MOMENT_NM_PER_KG = 1.50
"""ASSUMPTION, adult-shaped data (no adult set is packaged): the adult peak plantarflexor moment at free speed, the
middle of the 1.4-1.6 N·m/kg that adult references give at natural cadence and self-selected speed (D. A. Winter,
*The Biomechanics and Motor Control of Human Gait*, 2nd ed., Univ. of Waterloo Press 1991, ankle moment of the
natural-cadence group; Bovi G, Rabuffetti M, Mazzoleni P, Ferrarin M, "A multiple-task gait analysis approach:
kinematic, kinetic and EMG reference data for healthy young and adult subjects", Gait Posture 2011;33(1):6-13). The
children's curves of every speed group (Schwartz et al. 2008, free-speed peak 1.226) are scaled by this over the
children's free-speed peak: the shape, timing, angles, ground reaction in body weights and events stay the
children's, and so does the speed dependence between groups. Power per kg scales with the moment (same angles)."""
GRF_CSV = "grf_normative_all_speeds.csv"
"""Ground reaction forces in body weights, all speed groups (Schwartz et al. 2008): firmware/data/README.md."""


def all_speeds_path() -> Path:
    """The packaged all-speeds normative CSV (for GaitReference.from_csv with a speed_category select)."""
    return Path(str(resources.files("firmware.data").joinpath(ALL_SPEEDS)))


def population_for(body_mass_kg: float, population: str | None = None) -> str:
    """The population of a walker: the one given, else adult above CHILD_MAX_BODY_MASS_KG, else child."""
    if population is None:
        return "adult" if body_mass_kg > CHILD_MAX_BODY_MASS_KG else "child"
    if population not in POPULATIONS:
        raise ValueError(f"population {population!r} unknown: one of {', '.join(POPULATIONS)}")
    return population


def adult_moment_scale() -> float:
    """The factor from the children's packaged moment curves to the adult-shaped ones (ADULT_FREE_PEAK_...)."""
    _, moment, _ = _packaged_moment(None, None)
    return ADULT_FREE_PEAK_MOMENT_NM_PER_KG / max(moment)


def moment_curve(path: Path | None = None, speed: str | None = None,
                 population: str = "child") -> tuple[list[float], list[float], str]:
    """(percent_gait, ankle moment N m/kg, source) from a CSV shaped like the normative one ('#' lines skipped),
    or the packaged curve of a speed group (SPEEDS), adult-shaped for population "adult" (a user's CSV is taken as
    given)."""
    percent, moment, source = _packaged_moment(path, speed)
    if population == "adult" and path is None:
        k = adult_moment_scale()
        return percent, [k * m for m in moment], f"{source} (adult-shaped: x {k:.3f}, host_tools/walk.py)"
    return percent, moment, source


def _packaged_moment(path: Path | None, speed: str | None) -> tuple[list[float], list[float], str]:
    """The moment curve as the file gives it (module docstring of moment_curve)."""
    if speed is not None:
        if speed not in SPEEDS:
            raise ValueError(f"speed {speed!r} unknown: one of {list(SPEEDS)}")
        if path is not None:
            raise ValueError("--speed picks a packaged curve and --moment gives one: use one of them")
        path = all_speeds_path()
    if path is None:
        text, source = resources.files("firmware.data").joinpath("ankle_normative.csv").read_text("utf-8"), NORMATIVE
    else:
        try:
            text, source = Path(path).read_text(encoding="utf-8"), str(path)
        except OSError as e:
            raise ValueError(f"cannot read moment CSV {path}: {e.strerror or e}") from None
    columns = _columns(text, source, ("percent_gait", MOMENT_COLUMN), SPEEDS[speed] if speed is not None else None)
    return columns[0], columns[1], source


def _columns(text: str, source: str, names: tuple[str, ...], speed_category: str | None) -> list[list[float]]:
    """The named numeric columns of a CSV text ('#' lines skipped; rows of speed_category only, if given)."""
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    fields = [f.strip() for f in reader.fieldnames or []]
    reader.fieldnames = fields
    for col in names:
        if col not in fields:
            raise ValueError(f"{source}: missing column {col!r} (found columns: {fields})")
    out: list[list[float]] = [[] for _ in names]
    for row_no, row in enumerate(reader, start=2):
        if speed_category is not None and (row.get("speed_category") or "").strip() != speed_category:
            continue
        try:
            values = [float(row[col]) for col in names]
        except (TypeError, ValueError):
            raise ValueError(f"{source}: data row {row_no}: not a number in {[row.get(c) for c in names]}") from None
        for column, value in zip(out, values, strict=True):
            column.append(value)
    return out


def walking_load(body_mass_kg: float, stride_s: float, path: Path | None = None,
                 speed: str | None = None, population: str | None = None) -> WalkingLoad:
    """The ground's moment for body_mass_kg on the stride (the population's curve: population_for); ValueError
    naming a bad value or file."""
    percent, moment, source = moment_curve(path, speed, population_for(body_mass_kg, population))
    try:
        return WalkingLoad(percent, moment, body_mass_kg, stride_s)
    except ValueError as e:
        raise ValueError(f"{source}: {e}" if "moment curve" in str(e) else str(e)) from None


def ground_reaction(load: WalkingLoad, speed: str | None = None) -> GroundReaction:
    """The ground reaction under the walking load's strides: the packaged GRF of the speed group (default free),
    the CoP from the load's moment, the foot of profiles/ground_sensors.toml."""
    text = resources.files("firmware.data").joinpath(GRF_CSV).read_text("utf-8")
    percent, vertical, fore_aft = _columns(text, f"firmware/data/{GRF_CSV}",
                                           ("percent_gait", "grf_vertical_bw_mean", "grf_anterior_posterior_bw_mean"),
                                           SPEEDS[speed or "free"])
    from hal.virtual.ground_sensors import load_ground_profile  # numpy and the sensor models: only when walking

    foot = load_ground_profile()[2]
    return GroundReaction(load, percent, vertical, fore_aft, ankle_height_m=foot.ankle_height_m, heel_m=foot.heel_m,
                          toe_m=foot.toe_m)


def curve_negative_work_j(body_mass_kg: float, stride_s: float, speed: str | None = None,
                          population: str | None = None, samples: int = 2000) -> float:
    """The negative ankle work of one stride of the packaged curves (> 0, joules): -integral of min(0, P) with the
    ankle power P = -M(t) x the reference's angular velocity (M the population's plantarflexor moment x body mass,
    the velocity dorsiflexion-positive: push-off's plantarflexion under a plantarflexor moment generates)."""
    from firmware.control.reference import GaitReference

    load = walking_load(body_mass_kg, stride_s, None, speed, population)
    ref = (GaitReference.from_csv(all_speeds_path(), stride_s=stride_s, select={"speed_category": SPEEDS[speed]})
           if speed is not None else GaitReference.normative(stride_s=stride_s))
    dt = stride_s / samples
    work = 0.0
    for k in range(samples):
        t = (k + 0.5) * dt
        power = -load.moment_nm(100.0 * t / stride_s) * ref.velocity_rad_s(t)
        work += min(0.0, power) * dt
    return -work

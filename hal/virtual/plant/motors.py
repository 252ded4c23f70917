"""The motor catalogue: one profile per actuator in ``profiles/motors/<name>.toml`` and its loader.

Each profile holds the maker's figures for one quasi-direct-drive actuator (motor + built-in
planetary), every value with its source (see ``hal.virtual.plant.sourced``). Torques and speeds are at
the actuator's output (after its gearbox); Kt, Kv, R, L and the rotor inertia are motor-side, as the
maker tables print them. Adding a motor is adding one file: ``load_motor("<name>")`` finds it.

>>> m = load_motor("ak60_6")
>>> m.model, m.gear_ratio, m.pole_pairs
('CubeMars AK60-6 V1.1 KV140', 6.0, 14)
>>> round(m.peak_torque_nm / m.gear_ratio / m.peak_current_a, 3)  # the maker's own Kt at peak
0.066
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hal.virtual.plant.sourced import read_profile, read_sourced_table, resolve_profile, sourced_value

#: Directory of the catalogue inside the packaged ``profiles``.
CATALOGUE_DIR = "motors"

# table -> key -> (lowest, highest). Plausibility bounds: wide enough for any actuator an ankle could
# use, tight enough to catch a unit slip (g vs kg, mOhm vs Ohm, g*cm^2 vs kg*m^2, uH vs mH).
SPEC: dict[str, dict[str, tuple[float, float]]] = {
    "electrical": {
        "supply_voltage_v": (6.0, 100.0),
        "kv_rpm_per_v": (5.0, 2000.0),
        "kt_nm_per_a": (0.005, 2.0),
        "phase_resistance_ohm": (0.005, 20.0),
        "phase_inductance_h": (1e-6, 0.05),
        "km_nm_per_sqrt_w": (0.005, 5.0),
        "pole_pairs": (1.0, 60.0),
        "rated_current_a": (0.1, 200.0),
        "peak_current_a": (0.1, 500.0),
    },
    "mechanical": {
        "mass_kg": (0.05, 20.0),
        "gear_ratio": (1.0, 200.0),
        "rotor_inertia_kg_m2": (1e-7, 1e-2),
        "rated_torque_nm": (0.05, 500.0),
        "peak_torque_nm": (0.1, 1000.0),
        "no_load_speed_rpm": (1.0, 10000.0),
        "backdrive_torque_nm": (0.0, 50.0),
    },
    "can_mit": {
        "p_max_rad": (1.0, 1000.0),
        "v_max_rad_s": (1.0, 1000.0),
        "t_max_nm": (0.5, 1000.0),
    },
    "thermal": {
        "winding_to_housing_k_per_w": (0.01, 50.0),
        "housing_to_ambient_k_per_w": (0.01, 50.0),
        "winding_heat_capacity_j_per_k": (0.1, 1e4),
        "housing_heat_capacity_j_per_k": (1.0, 1e5),
        "copper_tempco_per_k": (0.003, 0.0045),
        "resistance_reference_c": (-40.0, 150.0),
        "max_winding_c": (60.0, 250.0),
    },
}


@dataclass(frozen=True)
class MotorSpec:
    """One catalogue actuator, in SI units; motor-side electrical constants, output-side torques."""

    name: str
    model: str
    path: Path
    supply_voltage_v: float
    kv_rpm_per_v: float
    kt_nm_per_a: float
    phase_resistance_ohm: float
    phase_inductance_h: float
    km_nm_per_sqrt_w: float
    pole_pairs: int
    rated_current_a: float
    peak_current_a: float
    mass_kg: float
    gear_ratio: float
    rotor_inertia_kg_m2: float
    rated_torque_nm: float
    peak_torque_nm: float
    no_load_speed_rpm: float
    backdrive_torque_nm: float
    p_max_rad: float
    v_max_rad_s: float
    t_max_nm: float
    winding_to_housing_k_per_w: float
    housing_to_ambient_k_per_w: float
    winding_heat_capacity_j_per_k: float
    housing_heat_capacity_j_per_k: float
    copper_tempco_per_k: float
    resistance_reference_c: float
    max_winding_c: float

    @property
    def output_torque_per_amp_nm(self) -> float:
        """Ideal output torque per ampere, Kt * gear ratio (no gearbox loss)."""
        return self.kt_nm_per_a * self.gear_ratio

    @property
    def thermal_resistance_k_per_w(self) -> float:
        """Winding-to-ambient thermal resistance (the two resistances in series)."""
        return self.winding_to_housing_k_per_w + self.housing_to_ambient_k_per_w


def motor_path(name: str) -> Path:
    """Path of catalogue motor ``name`` (e.g. ``"ak80_9"``) in the packaged profiles."""
    from profiles import profile_path

    return profile_path(f"{CATALOGUE_DIR}/{name}.toml")


def catalogue_names() -> list[str]:
    """Names of every motor in the catalogue, sorted."""
    from profiles import profile_paths

    return [p.stem for p in profile_paths(f"{CATALOGUE_DIR}/*.toml")]


def motor_from_mapping(data: dict[str, Any], path: Path) -> MotorSpec:
    """Build a MotorSpec from a parsed profile; ValueError names the file, key, value and range."""
    where = str(path)
    model = data.get("model")
    if not isinstance(model, str) or not model.strip():
        raise ValueError(f"{where}: top-level key model must be the actuator's name as a string")
    unknown = sorted(set(data) - set(SPEC) - {"model"})
    if unknown:
        raise ValueError(f"{where}: unknown table {unknown[0]} (allowed: model, {', '.join(SPEC)})")
    values: dict[str, Any] = {}
    for table, spec in SPEC.items():
        section = data.get(table)
        if not isinstance(section, dict):
            raise ValueError(f"{where}: missing table [{table}]")
        values.update(read_sourced_table(section, spec, table, where))
    pole_pairs = values["pole_pairs"]
    if pole_pairs != int(pole_pairs):
        raise ValueError(f"{where}: electrical.pole_pairs = {pole_pairs!r} must be a whole number in [1, 60]")
    values["pole_pairs"] = int(pole_pairs)
    _check_consistency(values, where)
    return MotorSpec(name=path.stem, model=model, path=path, **values)


def _check_consistency(v: dict[str, Any], where: str) -> None:
    """Cross-field rules: rated below peak, and the MIT torque range covering the motor's peak."""
    for rated, peak, table in (("rated_current_a", "peak_current_a", "electrical"),
                               ("rated_torque_nm", "peak_torque_nm", "mechanical")):
        if v[rated] > v[peak]:
            raise ValueError(
                f"{where}: {table}.{rated} = {v[rated]!r} exceeds {peak} = {v[peak]!r} "
                f"(allowed range [0, {v[peak]}])")
    if v["housing_heat_capacity_j_per_k"] < v["winding_heat_capacity_j_per_k"]:
        raise ValueError(
            f"{where}: thermal.housing_heat_capacity_j_per_k = {v['housing_heat_capacity_j_per_k']!r} is below "
            f"the winding's {v['winding_heat_capacity_j_per_k']!r} (allowed range "
            f"[{v['winding_heat_capacity_j_per_k']}, 1e5])")


def load_motor(name_or_path: str | Path) -> MotorSpec:
    """Load a catalogue motor by name (``"ak60_6"``) or a motor profile by path, fully checked."""
    path = resolve_profile(name_or_path, CATALOGUE_DIR, "motor")
    return motor_from_mapping(read_profile(path, "motor profile"), path)


def source_of(name: str, table: str, key: str) -> str:
    """The cited source of one value of catalogue motor ``name``."""
    path = motor_path(name)
    data = read_profile(path, "motor profile")
    _, source = sourced_value(data[table][key], key, table, str(path))
    return source


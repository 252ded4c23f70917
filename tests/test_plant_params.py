"""Plant profile: packaged values, derived quantities, validation errors naming key, value and range."""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from pathlib import Path

import pytest

from hal.virtual.plant import PlantParams, default_profile_path, load_plant_params
from hal.virtual.plant.params import plant_params_from_mapping


def profile_text() -> str:
    return default_profile_path().read_text(encoding="utf-8")


def write_profile(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plant.toml"
    path.write_text(text, encoding="utf-8")
    return path


def replace_value(text: str, key: str, new: str) -> str:
    out, n = re.subn(rf"^{key} = [^#\n]*", f"{key} = {new}", text, flags=re.MULTILINE)
    assert n == 1, key
    return out


def test_default_profile_is_found_relative_to_the_package_and_loads() -> None:
    path = default_profile_path()
    assert path.is_file() and path.parent.name == "profiles"
    p = load_plant_params()
    assert p == load_plant_params(path)
    assert isinstance(p, PlantParams)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.kt_nm_per_a = 1.0  # type: ignore[misc]


def test_report_numbers_and_derived_quantities() -> None:
    p = load_plant_params()
    assert (p.supply_voltage_v, p.peak_current_a, p.kt_nm_per_a, p.pole_pairs) == (24.0, 22.7, 0.078, 14)
    assert (p.phase_resistance_ohm, p.phase_inductance_h) == (0.202, 138e-6)
    assert p.rotor_inertia_kg_m2 == pytest.approx(243.5e-7)  # 243.5 g cm^2
    assert (p.foot_inertia_kg_m2, p.foot_mass_kg, p.foot_com_distance_m, p.foot_damping_nm_s_per_rad) == (
        0.0039, 1.176, 0.150, 0.5)
    assert p.current_time_constant_s == 0.00114
    diameter_ratio = p.belt_driven_pitch_diameter_m / p.belt_driver_pitch_diameter_m
    assert p.belt_ratio == pytest.approx(diameter_ratio, rel=1e-4)
    assert p.total_ratio == pytest.approx(6.0 * 140 / 30)
    assert p.spring_stiffness_nm_per_rad == pytest.approx(4.84, abs=0.005)
    # the report's loading-test target 5.068 N m = 2 k_l theta0
    assert 2 * p.spring_stiffness_nm_per_rad * p.spring_offset_rad == pytest.approx(5.068, abs=0.01)
    assert p.load_masses_kg == (0.68, 1.08, 1.48)
    # rotor inertia consistent with the maker's mechanical time constant 0.81 ms = J R / Kt^2
    tau_m = p.rotor_inertia_kg_m2 * p.phase_resistance_ohm / p.kt_nm_per_a**2
    assert tau_m == pytest.approx(0.81e-3, rel=0.02)
    assert p.phase_inductance_h / p.phase_resistance_ohm == pytest.approx(0.68e-3, rel=0.01)  # tau_e
    assert p.static_friction_nm == pytest.approx(0.2 * p.belt_ratio)
    assert p.output_inertia_kg_m2 == pytest.approx(
        0.0039 + 1.176 * 0.15**2 + p.rotor_inertia_kg_m2 * p.total_ratio**2
        + p.actuator_output_inertia_kg_m2 * p.belt_ratio**2 + p.ankle_pulley_inertia_kg_m2)
    assert p.stop_min_rad == pytest.approx(-math.pi / 6) and p.stop_max_rad == pytest.approx(math.pi / 5)


@pytest.mark.parametrize(
    ("key", "bad", "table"),
    [
        ("rotor_inertia_kg_m2", "243.5", "motor"),  # g cm^2 typed as kg m^2
        ("phase_resistance_ohm", "202.0", "motor"),  # mOhm typed as Ohm
        ("gearbox_efficiency", "1.2", "transmission"),
        ("peak_current_a", "-3.0", "motor"),
        ("stop_min_rad", "0.5", "stops"),
        ("foot_mass_kg", "nan", "foot"),
    ],
)
def test_out_of_range_value_error_names_key_value_and_range(
        tmp_path: Path, key: str, bad: str, table: str) -> None:
    path = write_profile(tmp_path, replace_value(profile_text(), key, bad))
    with pytest.raises(ValueError) as info:
        load_plant_params(path)
    message = str(info.value)
    assert f"{table}.{key}" in message
    assert bad in message
    assert "allowed range" in message and str(path) in message


def test_missing_and_unknown_keys_are_named(tmp_path: Path) -> None:
    text = profile_text()
    missing = re.sub(r"^kt_nm_per_a = .*$", "", text, flags=re.MULTILINE)
    with pytest.raises(ValueError, match=r"missing keys motor\.kt_nm_per_a"):
        load_plant_params(write_profile(tmp_path, missing))
    unknown = text.replace("[driver]\n", "[driver]\nfoo_bar = 1.0\n")
    with pytest.raises(ValueError, match=r"unknown key driver\.foo_bar"):
        load_plant_params(write_profile(tmp_path, unknown))


def test_cross_field_rules() -> None:
    p = load_plant_params()
    with pytest.raises(ValueError, match=r"coulomb_friction_nm = 2\.0.*allowed range"):
        dataclasses.replace(p, coulomb_friction_nm=2.0)
    with pytest.raises(ValueError, match=r"belt_ratio = 3\.0.*allowed range"):
        dataclasses.replace(p, belt_ratio=3.0)
    assert dataclasses.replace(p, belt_ratio=4.6).total_ratio == pytest.approx(27.6)  # the report's rounding
    with pytest.raises(ValueError, match=r"pole_pairs"):
        dataclasses.replace(p, pole_pairs=14.5)  # type: ignore[arg-type]


def test_mapping_loader_rejects_non_tables() -> None:
    data = tomllib.loads(profile_text())
    data["motor"]["pole_pairs"] = 14
    assert plant_params_from_mapping(data).pole_pairs == 14
    data["oops"] = 3
    with pytest.raises(ValueError, match="oops"):
        plant_params_from_mapping(data)

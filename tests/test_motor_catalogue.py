"""The motor catalogue (profiles/motors/): every file loads, every value cites a source, bad values fail."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from hal.virtual.plant import load_plant_params
from hal.virtual.plant.motors import SPEC, catalogue_names, load_motor, motor_path, source_of
from hal.virtual.plant.sourced import ASSUMED, read_profile, sources_of


def test_catalogue_holds_the_report_motor_and_at_least_four_more() -> None:
    names = catalogue_names()
    assert {"ak60_6", "ak70_10", "ak80_9"} <= set(names)
    assert len(names) >= 5


@pytest.mark.parametrize("name", catalogue_names())
def test_every_catalogue_file_loads_and_every_value_has_a_source(name: str) -> None:
    motor = load_motor(name)
    assert motor.name == name
    data = read_profile(motor_path(name))
    cited = sources_of(data)
    expected = {f"{table}.{key}" for table, spec in SPEC.items() for key in spec}
    assert set(cited) == expected
    for key, source in cited.items():
        assert len(source.strip()) >= 8, f"{name}: {key} has no real source: {source!r}"
        if source.startswith(ASSUMED):
            assert len(source) > len(ASSUMED) + 10, f"{name}: {key} is assumed without saying why"


@pytest.mark.parametrize("name", catalogue_names())
def test_catalogue_values_are_self_consistent(name: str) -> None:
    m = load_motor(name)
    # The maker's peak torque over its peak current and ratio is an effective Kt; it must sit within
    # a factor of two of the printed Kt (catches a motor-side/output-side or unit slip).
    kt_effective = m.peak_torque_nm / (m.gear_ratio * m.peak_current_a)
    assert 0.5 < kt_effective / m.kt_nm_per_a < 2.0
    # No-load output speed against the speed constant: Kv * V / ratio, within a factor of two.
    assert 0.5 < m.no_load_speed_rpm / (m.kv_rpm_per_v * m.supply_voltage_v / m.gear_ratio) < 2.0
    assert m.rated_current_a <= m.peak_current_a
    # The maker's motor constant is Kt / sqrt(R_ll): copper loss (Kt I / Km)^2 = R_ll I^2 (thermal.py).
    assert m.kt_nm_per_a / math.sqrt(m.phase_resistance_ohm) == pytest.approx(m.km_nm_per_sqrt_w, rel=0.05)
    assert m.thermal_resistance_k_per_w == pytest.approx(
        m.winding_to_housing_k_per_w + m.housing_to_ambient_k_per_w)


def test_the_ak60_6_entry_is_the_default_plant_motor() -> None:
    m = load_motor("ak60_6")
    p = load_plant_params()
    assert m.kt_nm_per_a == p.kt_nm_per_a
    assert m.phase_resistance_ohm == p.phase_resistance_ohm
    assert m.phase_inductance_h == p.phase_inductance_h
    assert m.rotor_inertia_kg_m2 == p.rotor_inertia_kg_m2
    assert m.pole_pairs == p.pole_pairs
    assert m.peak_current_a == p.peak_current_a
    assert m.gear_ratio == p.gearbox_ratio
    assert m.supply_voltage_v == p.supply_voltage_v
    assert m.kv_rpm_per_v == p.kv_rpm_per_v
    assert m.backdrive_torque_nm == p.actuator_backdrive_torque_nm


def test_mit_ranges_differ_per_motor() -> None:
    t_max = {name: load_motor(name).t_max_nm for name in catalogue_names()}
    assert t_max["ak60_6"] == 15.0
    assert len(set(t_max.values())) >= 4
    assert source_of("ak60_6", "can_mit", "t_max_nm").startswith("tmcc")


def _write_variant(tmp_path: Path, table: str, key: str, replacement: str) -> Path:
    text = motor_path("ak60_6").read_text()
    lines = text.splitlines()
    section = None
    for i, line in enumerate(lines):
        if line.startswith("["):
            section = line.strip("[]")
        elif section == table and line.startswith(f"{key} ="):
            lines[i] = f"{key} = {replacement}"
            break
    else:
        raise AssertionError(f"{table}.{key} not found")
    out = tmp_path / "bad_motor.toml"
    out.write_text("\n".join(lines) + "\n")
    return out


@pytest.mark.parametrize(("table", "key", "value", "lo", "hi"), [
    ("mechanical", "mass_kg", "368.0", 0.05, 20.0),          # grams written as kg
    ("electrical", "phase_resistance_ohm", "202.0", 0.005, 20.0),  # mOhm written as Ohm
    ("mechanical", "rotor_inertia_kg_m2", "243.5", 1e-7, 1e-2),    # g*cm^2 written as kg*m^2
    ("can_mit", "t_max_nm", "-15.0", 0.5, 1000.0),
    ("thermal", "max_winding_c", "nan", 60.0, 250.0),
])
def test_a_bad_value_names_file_key_value_and_range(
        tmp_path: Path, table: str, key: str, value: str, lo: float, hi: float) -> None:
    bad = _write_variant(tmp_path, table, key, f'{{ value = {value}, source = "test" }}')
    with pytest.raises(ValueError) as err:
        load_motor(bad)
    msg = str(err.value)
    assert str(bad) in msg and f"{table}.{key}" in msg and f"[{lo}, {hi}]" in msg
    assert value in msg or (value == "nan" and "nan" in msg)
    assert "\n" not in msg


def test_a_value_without_source_is_refused(tmp_path: Path) -> None:
    bad = _write_variant(tmp_path, "electrical", "kt_nm_per_a", "0.078")
    with pytest.raises(ValueError, match=r"electrical\.kt_nm_per_a must be a table"):
        load_motor(bad)
    bad = _write_variant(tmp_path, "electrical", "kt_nm_per_a", '{ value = 0.078, source = " " }')
    with pytest.raises(ValueError, match=r"electrical\.kt_nm_per_a has no source"):
        load_motor(bad)


def test_unknown_missing_and_inconsistent_keys_are_refused(tmp_path: Path) -> None:
    bad = _write_variant(tmp_path, "electrical", "kt_nm_per_a",
                         '{ value = 0.078, source = "x" }\nkt_typo = { value = 1.0, source = "x" }')
    with pytest.raises(ValueError, match=r"unknown key electrical\.kt_typo"):
        load_motor(bad)
    bad = _write_variant(tmp_path, "electrical", "rated_current_a", '{ value = 30.0, source = "x" }')
    with pytest.raises(ValueError, match=r"electrical\.rated_current_a = 30\.0 exceeds peak_current_a"):
        load_motor(bad)
    bad = _write_variant(tmp_path, "electrical", "pole_pairs", '{ value = 14.5, source = "x" }')
    with pytest.raises(ValueError, match=r"pole_pairs = 14\.5 must be a whole number"):
        load_motor(bad)
    text = "\n".join(line for line in motor_path("ak60_6").read_text().splitlines()
                     if not line.startswith("copper_tempco_per_k"))
    (tmp_path / "missing.toml").write_text(text)
    with pytest.raises(ValueError, match=r"missing key thermal\.copper_tempco_per_k"):
        load_motor(tmp_path / "missing.toml")


def test_unknown_motor_name_lists_the_catalogue() -> None:
    with pytest.raises(ValueError, match=r"motor 'ak99' is not in profiles/motors/ \(known: .*ak60_6"):
        load_motor("ak99")


def test_unreadable_profile_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "broken.toml").write_text("model = \n")
    with pytest.raises(ValueError, match="broken.toml: not valid TOML"):
        load_motor(tmp_path / "broken.toml")
    assert math.isfinite(load_motor("ak80_9").kt_nm_per_a)


@pytest.mark.parametrize("name", ["ak10_9", "ak60_6", "ak70_10", "ak80_64"])
def test_the_rotor_inertia_agrees_with_the_makers_mechanical_time_constant(name: str) -> None:
    """J = tau_m Kt^2 / R_ll (the makers' convention, as their Km = Kt / sqrt(R_ll)): within 2 % wherever the maker's
    tau_m is trusted (the AK80-9's printed tau_m equals its L/R, so its inertia is borrowed: see its profile)."""
    m = load_motor(name)
    j = m.mechanical_time_constant_s * m.kt_nm_per_a ** 2 / m.phase_resistance_ohm
    assert m.rotor_inertia_kg_m2 == pytest.approx(j, rel=0.02)


def test_the_ak80_9s_printed_time_constant_is_its_electrical_one() -> None:
    m = load_motor("ak80_9")
    assert m.mechanical_time_constant_s == pytest.approx(m.phase_inductance_h / m.phase_resistance_ohm, rel=0.01)

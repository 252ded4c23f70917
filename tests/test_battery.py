"""Battery model: OCV curve, sag under load, coulomb counting, power solve, regeneration, profiles."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from hal.virtual.plant.battery import Battery, BatteryParams, battery_names, battery_path, load_battery
from hal.virtual.plant.sourced import read_profile, sources_of


def _pack() -> BatteryParams:
    return load_battery("molicel_p42a_6s1p")


@pytest.mark.parametrize("name", battery_names())
def test_every_battery_profile_loads_and_cites_every_value(name: str) -> None:
    params = load_battery(name)
    cited = sources_of(read_profile(battery_path(name)))
    assert set(cited) == {"cell.capacity_ah", "cell.resistance_ohm", "cell.max_charge_current_a",
                          "cell.mass_kg", "pack.series", "pack.parallel", "ocv.soc", "ocv.cell_v"}
    assert all(len(s) > 8 for s in cited.values())
    assert params.capacity_wh > 0


def test_open_circuit_voltage_interpolates_the_table() -> None:
    p = _pack()
    assert p.open_circuit_v(1.0) == pytest.approx(6 * 4.1932)
    assert p.open_circuit_v(0.0) == pytest.approx(6 * 2.5061)
    mid = (0.4573 + 0.8342) / 2
    assert p.open_circuit_v(mid) == pytest.approx(6 * (3.7017 + 4.0637) / 2)
    assert p.open_circuit_v(1.5) == p.open_circuit_v(1.0)
    socs = [i / 50 for i in range(51)]
    volts = [p.open_circuit_v(s) for s in socs]
    assert volts == sorted(volts)


def test_capacity_in_wh_is_the_integral_of_the_curve() -> None:
    p = _pack()
    n = 100000
    integral = sum(p.open_circuit_v((i + 0.5) / n) for i in range(n)) / n
    assert p.capacity_wh == pytest.approx(p.capacity_ah * integral, rel=1e-6)


def test_bus_sags_by_i_r_and_coulombs_are_counted() -> None:
    p = _pack()
    b = Battery(p, soc=0.9)
    e = b.open_circuit_v()
    v = b.step_current(1.0, 10.0)
    assert v == pytest.approx(e - 10.0 * p.resistance_ohm)
    assert p.resistance_ohm == pytest.approx(6 * 0.018)
    b = Battery(p, soc=1.0)
    for _ in range(360):
        b.step_current(1.0, 4.2)          # 1C for 0.1 h
    assert b.soc == pytest.approx(0.9, abs=1e-9)
    assert b.loss_j == pytest.approx(4.2**2 * p.resistance_ohm * 360)


def test_a_sag_caps_the_emf_behind_the_pack_resistance_and_ends() -> None:
    """The supply_sag fault's hook: E is at most the sag voltage, the bus is E - R I, the charge still counts."""
    b = Battery(load_battery("molicel_p42a_6s1p"), soc=0.8)
    full = b.open_circuit_v()
    b.sag(7.0)
    assert b.open_circuit_v() == 7.0
    soc = b.soc
    assert b.step_current(1.0, 2.0) == pytest.approx(7.0 - 2.0 * b.params.resistance_ohm)
    assert b.soc < soc
    b.sag(100.0)  # above the pack's EMF: no effect
    assert b.open_circuit_v() == pytest.approx(b.params.open_circuit_v(b.soc))
    b.sag(None)
    assert b.open_circuit_v() == pytest.approx(b.params.open_circuit_v(b.soc)) and b.open_circuit_v() < full
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="sag voltage"):
            b.sag(bad)


def test_power_solve_gives_the_requested_terminal_power_and_detects_overload() -> None:
    b = Battery(_pack(), soc=0.5)
    for power in (5.0, 100.0, 400.0, -50.0):
        i = b.current_for_power(power)
        assert b.deliverable
        assert (b.open_circuit_v() - b.params.resistance_ohm * i) * i == pytest.approx(power, rel=1e-9)
    e, r = b.open_circuit_v(), b.params.resistance_ohm
    assert b.current_for_power(e * e / (4 * r) * 1.01) == pytest.approx(e / (2 * r))
    assert not b.deliverable


def test_regeneration_charges_up_to_the_limit_and_is_rejected_when_full() -> None:
    p = _pack()
    b = Battery(p, soc=0.5)
    v = b.step_current(10.0, -2.0)
    assert b.soc > 0.5 and v > b.open_circuit_v() - 1e-3
    assert b.regenerated_j == pytest.approx(-v * -2.0 * 10.0) and b.rejected_j == 0.0
    b.step_current(1.0, -50.0)            # above the 4.2 A charge limit
    assert b.current_a == pytest.approx(-p.max_charge_current_a)
    assert b.rejected_j > 0
    full = Battery(p, soc=1.0)
    full.step_current(1.0, -3.0)
    assert full.soc == 1.0 and full.current_a == 0.0 and full.rejected_j > 0


def test_energy_balance_over_a_load_cycle() -> None:
    b = Battery(_pack(), soc=0.8)
    e_start = b.soc
    for k in range(2000):
        b.step_power(0.01, 150.0 if k % 4 else -40.0)
    drawn_ah = (e_start - b.soc) * b.params.capacity_ah
    assert drawn_ah > 0
    assert b.discharged_j > b.regenerated_j > 0
    assert b.loss_j > 0


def test_bad_profile_values_name_file_key_value_and_range(tmp_path: Path) -> None:
    text = battery_path("molicel_p42a_6s1p").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("capacity_ah = { value = 4.2,", "capacity_ah = { value = 4200.0,"))
    with pytest.raises(ValueError,
                       match=r"bad.toml: cell.capacity_ah = 4200.0 is outside the allowed range \[0.05, 500.0\]"):
        load_battery(bad)
    bad.write_text(text.replace("2.5061, 2.8981", "2506.1, 2.8981"))
    with pytest.raises(ValueError, match=r"ocv.cell_v = 2506.1 is outside the allowed range \[1.5, 4.5\]"):
        load_battery(bad)
    bad.write_text(text.replace("2.5061, 2.8981", "2.9, 2.8981"))
    with pytest.raises(ValueError, match=r"ocv.cell_v must not fall with SoC"):
        load_battery(bad)
    bad.write_text(text.replace("series = { value = 6,", "series = { value = 6.5,"))
    with pytest.raises(ValueError, match=r"pack.series = 6.5 must be a whole number"):
        load_battery(bad)
    with pytest.raises(ValueError, match=r"battery 'lead_acid' is not in profiles/batteries/"):
        load_battery("lead_acid")
    with pytest.raises(ValueError, match=r"battery state of charge 1.2 is outside the allowed range \[0, 1\]"):
        Battery(_pack(), soc=1.2)
    with pytest.raises(ValueError, match="ocv.soc must run from 0.0 to 1.0"):
        dataclasses.replace(_pack(), soc_points=(0.1,) + _pack().soc_points[1:])

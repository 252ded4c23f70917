"""Physics plausibility at the boundary (issue 35, case 4): a supply the motor's driver would not take, ratings
that are not the named motor's, and energy figures where no walk was measured.

The driver model trips OVER_VOLTAGE as the VESC does (``l_max_vin``); a pack whose full voltage is above that
trip is refused before a run; a design profile whose [motor] ratings are another motor's is refused; energy per
stride and distance per charge come only from a walking run's strides completed before any fault.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest
from test_ak60 import Rig
from test_ak60_drive import values_at

from hal.virtual.faults import make_injector
from host_tools.cli import main
from host_tools.reports.thermal import battery_summary
from host_tools.runner import RunConfig, run_virtual
from protocol.vesc import FaultCode

ROOT = Path(__file__).resolve().parents[1]


def _one_line(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("pafp ")]
    assert "Traceback" not in err and len(lines) == 1, err
    return lines[0]


def test_the_driver_trips_over_voltage_above_its_limit_and_takes_a_full_6s_pack():
    rig = Rig()
    rig.motor.set_supply_voltage(25.2, 0.02)  # a full 6S Li-ion pack on the 24 V AK60-6
    assert values_at(rig, 0.03).fault == 0
    rig = Rig()
    rig.motor.set_supply_voltage(40.0, 0.02)
    v = values_at(rig, 0.03)
    assert v.fault == FaultCode.OVER_VOLTAGE and v.v_in_v == pytest.approx(40.0, abs=0.1)


def test_a_pack_above_the_drivers_over_voltage_trip_is_refused_before_the_run(tmp_path, capsys):
    pack = tmp_path / "pack30s.toml"
    text = (ROOT / "profiles" / "batteries" / "molicel_p42a_6s1p.toml").read_text()
    pack.write_text(text.replace("series = { value = 6,", "series = { value = 30,"))
    out = tmp_path / "run"
    assert main(["run", "--battery", str(pack), "--strides", "1", "--quiet", "--out", str(out)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert str(pack) in line and "over-voltage trip of 30 V" in line and "rated 24 V" in line
    assert not out.exists()


def test_a_design_profile_whose_motor_ratings_are_another_motors_is_refused(tmp_path, capsys):
    text = (ROOT / "profiles" / "designs" / "adult_80kg.toml").read_text()
    assert '\nmotor = "ak80_9"\n' in text
    profile = tmp_path / "design.toml"
    profile.write_text(text.replace('\nmotor = "ak80_9"\n', '\nmotor = "ak10_9"\n'))
    assert main(["run", "--profile", str(profile), "--strides", "1", "--quiet", "--out", str(tmp_path / "r")]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "[motor] model = 'ak80_9'" in line and "[design] motor 'ak10_9'" in line


def test_a_suspended_foot_has_no_distance_per_charge(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "--battery", "molicel_p42a_6s1p", "--strides", "1", "--quiet", "--no-plot", "--no-trace",
                 "--out", str(out)]) in (0, 1)
    printed = capsys.readouterr().out
    b = json.loads((out / "summary.json").read_text())["battery"]
    assert b["energy_per_stride_j"] is None and b["distance_per_charge_km"] is None
    assert b["strides_per_charge"] is None and "not walking" in b["energy_figures_left_out"]
    assert "km per charge" not in printed and "None" not in printed.split("molicel_p42a_6s1p")[1].splitlines()[0]


def test_a_walk_that_latched_a_fault_before_its_first_stride_has_no_energy_figures():
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    r = run_virtual(RunConfig(strides=2, trace_capacity=0, scenario="walk", battery="molicel_p42a_6s1p",
                              faults=(make_injector("imu_silent", 0.3),)))
    assert r.firmware.supervisor.tripped_at_s is not None and r.heat["log"].strides  # strides counted on
    b = battery_summary(r, r.firmware.config.stride_s, None)
    assert b["energy_per_stride_j"] is None and b["distance_per_charge_km"] is None and b["energy_strides"] == 0
    assert b["energy_figures_left_out"].startswith("no stride completed before the fault at ")

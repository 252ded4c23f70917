"""The walking scenario, the impedance controller's gait state machine and the actuator design check
(runs of two strides at a light body mass, where this actuator still carries the load)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from firmware.config import load_firmware_config
from firmware.control.impedance import PHASES, Impedance, impedance_from_config
from firmware.control.observation import Observation
from firmware.control.reference import GaitReference
from firmware.control.registry import build_controller
from hal.virtual.plant import load_plant_params
from hal.virtual.plant.walking import WalkingLoad
from host_tools.cli import main
from host_tools.reports.actuator import design_check
from host_tools.runner import RunConfig, run_virtual
from host_tools.walk import (
    ADULT_FREE_PEAK_MOMENT_NM_PER_KG,
    adult_moment_scale,
    curve_negative_work_j,
    moment_curve,
    population_for,
    walking_load,
)


def test_walking_load_is_the_normative_moment_times_mass_in_stance_only():
    percent, moment, _ = moment_curve()
    load = walking_load(60.0, 1.1, population="child")
    assert load(5.0) == 0.0  # no gait clock bound yet: nothing walks
    load.bind(lambda: 1.0)
    assert load(0.99) == 0.0
    k = percent.index(48.0)
    assert load(1.0 + 0.48 * 1.1) == pytest.approx(60.0 * moment[k])
    assert load(1.0 + 0.70 * 1.1) == 0.0 and not load.stance(1.0 + 0.70 * 1.1)  # swing
    assert load(1.0 + 1.48 * 1.1) == pytest.approx(60.0 * moment[k])  # the next stride
    with pytest.raises(ValueError, match="body mass 250 kg out of range: 20..200 kg"):
        WalkingLoad(percent, moment, 250, 1.1)


def test_impedance_state_machine_walks_through_its_phases_on_sensed_events():
    cfg = load_firmware_config()
    ctl = impedance_from_config(cfg, {"body_mass_kg": 70})
    obs = Observation()
    seen = []

    def step(stance, velocity, angle, load):
        obs.stance, obs.velocity_rad_s, obs.angle_rad, obs.load_torque_nm = stance, velocity, angle, load
        ctl.update(obs)
        seen.append(PHASES[ctl.phase])

    step(False, 0.0, 0.0, 0.0)       # swing
    step(True, -1.0, -0.05, 8.0)     # heel strike: controlled plantarflexion
    step(True, 0.5, -0.03, 20.0)     # the shank rolls over the flat foot: controlled dorsiflexion
    step(True, 0.5, 0.1, 70 * 0.95)  # the moment passes 0.9 N m/kg: powered plantarflexion
    step(False, -3.0, 0.0, 1.0)      # toe off
    assert seen == ["SWING", "EARLY_STANCE", "MID_STANCE", "LATE_STANCE", "SWING"]
    assert ctl.transitions == 4
    # late stance pushes towards plantarflexion (negative current) from a dorsiflexed angle
    obs.stance, obs.angle_rad, obs.velocity_rad_s = True, 0.15, 0.0
    ctl.phase = 3
    assert ctl.update(obs) < 0
    with pytest.raises(ValueError, match="no parameter 'stiffness'"):
        impedance_from_config(cfg, {"stiffness": 1})
    with pytest.raises(ValueError, match="body_mass_kg = 500 is not allowed"):
        impedance_from_config(cfg, {"body_mass_kg": 500})
    assert isinstance(ctl, Impedance)


def test_suspended_default_is_unchanged_by_the_scenario_option():
    a = run_virtual(RunConfig(strides=1, trace_capacity=0))
    b = run_virtual(RunConfig(strides=1, trace_capacity=0, scenario="suspended", body_mass_kg=50.0))
    assert a.telemetry == b.telemetry
    assert a.firmware.load_detector.heel_strikes == 0  # no ground, no stance sensed


@pytest.mark.parametrize("controller", ["cascade", "impedance"])
def test_walking_at_a_light_mass_senses_heel_strikes_and_toe_offs(controller):
    cfg = load_firmware_config()
    ctl = build_controller(controller, cfg, {"body_mass_kg": 20.0} if controller == "impedance" else {})
    r = run_virtual(RunConfig(strides=2, firmware=cfg, controller=ctl, scenario="walk", body_mass_kg=20.0,
                              trace_capacity=0))
    fw = r.firmware
    assert fw.supervisor.reason.name == "NONE"
    assert fw.load_detector.heel_strikes >= 2 and fw.load_detector.toe_offs >= 2
    if controller == "impedance":
        assert fw.controller.transitions >= 8  # four phases a stride


def test_design_check_saturation_grows_with_body_mass_and_the_limit_mass_is_consistent():
    params = load_plant_params()
    load = walking_load(80.0, 1.1)  # an adult's curve (above 50 kg); the other masses below scale the same curve
    ref = GaitReference.normative(stride_s=1.1)
    check = design_check(params, 12.0, load, ref, masses_kg=(20.0, 40.0, 60.0, 80.0))
    sat = [row["saturated_fraction_peak"] for row in check["by_body_mass"]]
    assert sat == sorted(sat) and sat[0] == 0.0 < sat[-1]
    peak = check["drive"]["peak_torque_nm"]
    assert peak == pytest.approx(0.078 * 22.7 * 28.0 * 0.855, rel=1e-3)
    limit_kg = check["keeps_up_to_body_mass_kg"]["peak"]
    below = design_check(params, 12.0, walking_load(limit_kg - 1, 1.1, population="adult"), ref, masses_kg=())["demand"]
    above = design_check(params, 12.0, walking_load(limit_kg + 1, 1.1, population="adult"), ref, masses_kg=())["demand"]
    assert below["saturated_fraction_peak"] == 0.0 < above["saturated_fraction_peak"]
    assert 50 <= check["demand"]["peak_speed_rpm"] <= 60  # the report designs for 55 rpm
    assert check["demand"]["peak_torque_nm"] == pytest.approx(
        80 * max(np.abs(moment_curve(population="adult")[1])), rel=1e-3)


def test_cli_walk_writes_the_actuator_check(tmp_path):
    out = tmp_path / "out"
    code = main(["run", "--quiet", "--strides", "1", "--scenario", "walk", "--controller", "impedance",
                 "--body-mass", "60", "--out", str(out)])
    s = json.loads((out / "summary.json").read_text())
    assert code == (1 if s["faults"] else 0)
    act = s["actuator"]
    assert act["demand"]["body_mass_kg"] == 60.0 and act["run"]["controller"] == "impedance"
    assert (out / "actuator.png").stat().st_size > 0
    assert "## Actuator design check (walking, 60 kg)" in (out / "report.md").read_text()


@pytest.mark.parametrize("args, needle", [
    (["--scenario", "walk", "--body-mass", "300"], "body mass 300.0 kg out of range: 20..200 kg"),
    (["--scenario", "walk", "--moment", "/nonexistent.csv"], "cannot read moment CSV /nonexistent.csv"),
])
def test_cli_bad_walk_input_is_one_line_and_exit_2(tmp_path, capsys, args, needle):
    out = tmp_path / "out"
    assert main(["run", "--quiet", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_speed_picks_the_speed_groups_moment_and_reference():
    _, slow_m, source = moment_curve(speed="very-slow")
    _, free_m, _ = moment_curve()
    assert source.endswith("ankle_normative_all_speeds.csv") and len(slow_m) == len(free_m) == 51
    assert max(slow_m) < max(free_m)  # the slowest walkers push off less (Schwartz et al. 2008)
    _, fast_file, _ = moment_curve(speed="free")
    assert fast_file == free_m  # the free group of the all-speeds file is the default curve
    a = run_virtual(RunConfig(strides=1, trace_capacity=0, speed="very-slow"))
    b = run_virtual(RunConfig(strides=1, trace_capacity=0))
    assert a.firmware.reference.sample(0.3)[0] != b.firmware.reference.sample(0.3)[0]
    with pytest.raises(ValueError, match="speed 'warp' unknown"):
        RunConfig(speed="warp")


def test_keeps_up_to_leaves_the_instants_beyond_the_no_load_speed_to_the_speed_envelope():
    """A drive whose no-load speed is below the walk's peak speed: the limit mass is the largest whose demand stays
    in the envelope at every stance instant the motor can reach (it was 0 kg: one unreachable instant gave 0)."""
    import dataclasses

    from host_tools.reports.actuator import Drive, _demand

    params = dataclasses.replace(load_plant_params(), supply_voltage_v=11.0)  # no-load 52 rpm at the ankle
    ref = GaitReference.normative(stride_s=1.1)
    check = design_check(params, 12.0, walking_load(80.0, 1.1), ref, masses_kg=())
    speed_env, keeps = check["speed_envelope"], check["keeps_up_to_body_mass_kg"]
    assert speed_env["no_load_speed_rpm"] < speed_env["peak_demand_speed_rpm"] == check["demand"]["peak_speed_rpm"]
    assert 0.0 < speed_env["stance_fraction_above_no_load"] < 0.1
    assert 0.0 < speed_env["stride_fraction_above_no_load"] < 0.1
    drive, load = Drive.from_params(params, 12.0), walking_load(80.0, 1.1)
    for name, current in (("peak", drive.peak_current_a), ("control_limit", 12.0),
                          ("continuous", drive.rated_current_a)):
        limit_kg = keeps[name]
        assert limit_kg > 0.1
        for mass, inside in ((limit_kg - 0.06, True), (limit_kg + 0.06, False)):  # the figure is rounded to 0.1 kg
            _, torque, speed = _demand(load, ref, mass)
            reach = (np.abs(torque) > 0) & (np.abs(speed) < drive.no_load_speed_rad_s)
            assert bool(np.all(np.abs(torque[reach]) <= drive.torque_nm(speed[reach], current))) == inside, (name, mass)


def test_a_drive_within_the_speed_envelope_counts_no_instant_apart():
    ref = GaitReference.normative(stride_s=1.1)
    check = design_check(load_plant_params(), 12.0, walking_load(80.0, 1.1, population="child"), ref, masses_kg=())
    assert check["speed_envelope"]["stance_fraction_above_no_load"] == 0.0
    assert check["speed_envelope"]["stride_fraction_above_no_load"] == 0.0
    assert check["keeps_up_to_body_mass_kg"]["peak"] == pytest.approx(34.6, abs=0.5)  # on the children's curve
    adult = design_check(load_plant_params(), 12.0, walking_load(80.0, 1.1), ref, masses_kg=())
    assert adult["keeps_up_to_body_mass_kg"]["peak"] == pytest.approx(34.6 / adult_moment_scale(), abs=0.5)  # 28.3


def test_adult_curves_are_the_childrens_scaled_to_the_assumed_adult_peak_and_a_users_csv_is_kept(tmp_path):
    assert population_for(50.0) == "child" and population_for(50.1) == "adult"
    assert population_for(80.0, "child") == "child"
    with pytest.raises(ValueError, match="population 'elder' unknown: one of adult, child"):
        population_for(80.0, "elder")
    k = adult_moment_scale()
    for speed in ("very-slow", "free", "fast"):
        p_child, child, _ = moment_curve(speed=speed)
        p_adult, adult, source = moment_curve(speed=speed, population="adult")
        assert p_adult == p_child and adult == pytest.approx([k * m for m in child]) and "adult-shaped" in source
    assert max(moment_curve(speed="free", population="adult")[1]) == pytest.approx(ADULT_FREE_PEAK_MOMENT_NM_PER_KG)
    own = tmp_path / "m.csv"
    own.write_text("percent_gait,ankle_moment_nm_per_kg_mean\n0,0\n50,1.3\n100,0\n", encoding="utf-8")
    assert moment_curve(own, population="adult")[1] == [0.0, 1.3, 0.0]  # a user's curve is theirs
    # the default walk (80 kg) is an adult's: its load is the adult curve
    assert walking_load(80.0, 1.1).moment_nm(48.0) == pytest.approx(80.0 * k * moment_curve()[1][24])
    # negative ankle work of the curve scales with the moment (same angles)
    assert curve_negative_work_j(80.0, 1.1, "free", "adult") == pytest.approx(
        k * curve_negative_work_j(80.0, 1.1, "free", "child"), rel=1e-9)


def test_population_without_walking_is_refused_in_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "--quiet", "--population", "adult", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--population adult is not allowed without --scenario walk" in err and len(err.strip().splitlines()) == 1

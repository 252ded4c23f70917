"""Plant-level bench tests of the report (`pafp bench`): each checked against the report's figure."""

import json
import math

import numpy as np
import pytest

from hal.virtual.plant import load_plant_params
from host_tools.benchtests import backdrive, design_point, fast_response, loading, spring_calibration, uncontrolled
from host_tools.benchtests.output import Figure
from host_tools.cli import main


@pytest.fixture(scope="module")
def loading_result():
    return loading.run(periods=1.0)


def test_uncontrolled_drop_reaches_stop_within_report_time():
    # report: the suspended foot released from pi/5 reaches the stop within 0.5 s; tolerance: none
    # beyond the bound itself. Lower bound: without damping and friction the fall takes 0.275 s, so
    # a result under 0.35 s would mean the report's losses (k = 0.5 N m s/rad, friction) were lost.
    r = uncontrolled.run()
    (row,) = r.figures
    assert 0.35 < row.emulated_value < 0.5
    assert row.basis.startswith("fitted: friction.coulomb_friction_nm")  # the friction was tuned to this test
    assert "falls from early stance to late stance within 0.5 seconds" in row.note  # the report's words


def test_pafp_bench_uncontrolled_writes_all_outputs(tmp_path, capsys):
    out = tmp_path / "tmp"
    assert main(["bench", "uncontrolled", "--out", str(out)]) == 0
    for ext in ("png", "csv", "json", "md"):
        path = out / f"uncontrolled.{ext}"
        assert path.is_file() and path.stat().st_size > 0, path
    assert (out / "uncontrolled.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads((out / "uncontrolled.json").read_text())
    assert doc["figures"][0]["report_value"] == pytest.approx(0.5)
    header = (out / "uncontrolled.csv").read_text().splitlines()[0]
    assert header == "t_s,angle_deg,velocity_deg_s"
    printed = capsys.readouterr().out
    assert "| uncontrolled [level-com] |" in printed and "< 0.5" in printed
    assert doc["readings"] == {"geometry": "level-com", "driver": "unpowered", "imu": "n/a"}


def test_bench_all_runs_every_geometry_dependent_test_under_both_geometries():
    from host_tools.benchtests import TESTS
    from host_tools.commands.bench import plan

    runs = plan("all", None)
    for name in TESTS:
        geos = [g for n, g in runs if n == name]
        assert geos in (["level-com", "hanging"], [None]), (name, geos)
    assert [g for n, g in runs if n == "uncontrolled"] == ["level-com", "hanging"]
    assert [g for n, g in runs if n == "spring-calibration"] == [None]  # arithmetic on the report's tables
    assert plan("uncontrolled", None) == [("uncontrolled", None)]  # one test: the profile's geometry
    assert plan("uncontrolled", "hanging") == [("uncontrolled", "hanging")]


def test_hanging_geometry_reproduces_the_fast_response_not_the_drop():
    # Report eq 3.55 is a pendulum hanging at 0 deg. Under it the unpowered foot released from pi/5 swings
    # back towards 0 deg and never reaches the -30 deg stop (3.6.1's "falls [...] within 0.5 s" fails),
    # while a push from rest returns it near 0 deg (4.2.2's outcome); with the COM level (the profile) the
    # drop holds and the pushed foot rests on the stop. Without friction the pendulum's damping ratio is
    # k / (2 sqrt(m g d J)) = 0.85 (issue 24's arithmetic) and the undershoot about 0.5 %.
    import dataclasses

    from hal.virtual.plant.readings import with_geometry

    level = load_plant_params()
    hanging = with_geometry(level, "hanging")
    assert hanging.com_angle_at_zero_rad == 0.0 and level.com_angle_at_zero_rad == pytest.approx(math.pi / 2)
    assert math.isnan(uncontrolled.run(params=hanging).figures[0].emulated_value)
    assert uncontrolled.run(params=level).figures[0].emulated_value < 0.5

    def fig(result, name):
        return next(f.emulated_value for f in result.figures if f.name == name)

    end = "unpowered: angle at the end"
    assert abs(fig(fast_response.run(params=hanging), end)) < 5.0  # held off 0 only by static friction
    assert fig(fast_response.run(params=level), end) == pytest.approx(-30.0, abs=0.5)
    frictionless = dataclasses.replace(hanging, actuator_backdrive_torque_nm=0.0, coulomb_friction_nm=0.0)
    r = fast_response.run(params=frictionless)
    assert abs(fig(r, end)) < 0.05
    assert 0.2 < fig(r, "unpowered: overshoot (below rest, into the stop)") < 1.0
    j, mgd = frictionless.output_inertia_kg_m2, frictionless.gravity_moment_nm
    assert frictionless.foot_damping_nm_s_per_rad / (2 * math.sqrt(mgd * j)) == pytest.approx(0.85, abs=0.01)


def test_backdrive_magnitude_supports_n_m_not_n_mm():
    # The report prints 2.06 / 2.14 "N*mm". With J_total = J_m N^2 + ... = 0.0193 kg m^2 and the
    # static friction of 0.93 N*m at the ankle, any push that moves the foot 16 deg gives tau_b of
    # order 1 N*m: the figure cannot be reproduced in N*mm. Asserted instead: the emulated mean peak is
    # within a factor 5 of the report's number read in N*m, and more than 100x the number read in N*mm.
    r = backdrive.run(seed=0, trials=3)
    rows = {f.name: f for f in r.figures}
    for name in ("dorsiflexion", "plantarflexion"):
        as_nm = rows[f"mean peak tau_b, {name}, report read as N*m"]
        as_nmm = rows[f"mean peak tau_b, {name}, report read as N*mm"]
        assert as_nm.report_value / 5 < as_nm.emulated_value < as_nm.report_value * 5
        assert as_nmm.emulated_value > 100 * as_nmm.report_value
    # whatever the push, breakaway from static to kinetic friction gives tau_b above the N*mm reading
    floor = rows["least peak tau_b at breakaway (any push)"]
    assert floor.basis == "predicted" and floor.emulated_value > 100 * 2.14e-3


def test_backdrive_encoder_alpha_matches_plant_alpha():
    # the 1 kHz encoder double difference (quantised to 2 pi/4000 rad, filtered at 20 Hz) must give
    # the plant's peak acceleration within 10 %
    r = backdrive.run(seed=1, trials=2)
    p = r.parameters
    for name in ("dorsiflexion", "plantarflexion"):
        for enc, true in zip(p["peaks_nm"][name], p["peaks_true_alpha_nm"][name], strict=True):
            assert enc == pytest.approx(true, rel=0.10)


def test_backdrive_with_the_reports_j_total_does_not_settle_the_units():
    # The report reflects only the motor and the input pulley through 4.6 (3.8.1, eqs 2.8-2.10): with that
    # J_total, 2.06 N*mm needs alpha of a few rad/s^2 (16 deg in about 0.4 s), an ordinary push, and our
    # push gives tens of mN*m: the physics does not settle the units under the report's reading.
    r = backdrive.run(seed=0, trials=2)
    rows = {f.name: f for f in r.figures}
    j_report = r.parameters["report_j_total_kg_m2"]
    p = load_plant_params()
    assert j_report == pytest.approx((p.rotor_inertia_kg_m2 + p.actuator_output_inertia_kg_m2) * 4.6**2)
    assert j_report < p.reflected_inertia_kg_m2 / 30  # the planetary's 6^2 = 36 missing
    for name in ("dorsiflexion", "plantarflexion"):
        row = rows[f"mean peak tau_b, {name}, report's J_total (no planetary)"]
        assert 0.005 < row.emulated_value < 0.1
        assert row.basis.startswith("assumed:")
        need = row.report_value * p.belt_efficiency / j_report
        assert 1.0 < need < 10.0 and math.sqrt(2 * math.radians(16) / need) < 1.0


def test_backdrive_is_seeded():
    a = backdrive.run(seed=7, trials=1).parameters["peaks_nm"]
    b = backdrive.run(seed=7, trials=1).parameters["peaks_nm"]
    c = backdrive.run(seed=8, trials=1).parameters["peaks_nm"]
    assert a == b and a != c


def test_fast_response_rises_within_report_bound_without_ringing():
    # report: rise time under 1 s, little overshoot, no oscillation. Tolerances: rise < 1 s (the
    # report's bound); overshoot into the stop < 10 % of the peak excursion ("little"); "no oscillation"
    # read as at most one bounce on the stop and settled to 2 % within 1 s of the push.
    r = fast_response.run()
    m = r.parameters
    assert 0.0 < m["rise_s"] < 1.0
    assert m["overshoot_pct"] < 10.0
    assert m["rebounds"] <= 1
    assert m["settling_s"] < 1.0
    assert math.degrees(m["peak_rad"]) > 5.0  # the push really moved the foot
    # the report's outcome (back near 0 deg) is the controlled foot's: it settles within 0.1 deg of 0
    c = m["controlled"]
    assert 0.0 < c["rise_s"] < 1.0 and c["settling_s"] < 1.0 and abs(c["final_deg"]) < 0.1
    assert all(f.basis.startswith("assumed: a pneumatic push") for f in r.figures)


def test_loading_reaches_report_targets_and_peak_torque(loading_result):
    # report: target 5.068 N*m on the spring (tolerance 2 %: the cascade tracks theta0 sin(wt), theta0
    # fitted to it), peak torque 10 N*m measured (tolerance 25 %: the emulated drive has no belt stretch
    # or cogging), heavier load -> more torque.
    rows = {f.name: f for f in loading_result.figures}
    assert rows["peak spring torque, 1.48 kg"].emulated_value == pytest.approx(5.068, rel=0.02)
    assert rows["peak spring torque, 1.48 kg"].basis.startswith("fitted: spring_bench.spring_offset_rad")
    assert rows["peak motor torque at the ankle, 1.48 kg"].emulated_value == pytest.approx(10.0, rel=0.25)
    peaks = loading_result.parameters["peak_torque_nm"]
    assert peaks["0.68"] < peaks["1.08"] < peaks["1.48"]


def test_loading_runs_at_the_reports_speed(loading_result):
    # report: ankle speed -0.05..0.05 rad/s; its 0.2534 W "initial target" is 5.068 N*m x 0.05 rad/s
    assert loading_result.parameters["omega_rad_s"] * math.pi / 6 == pytest.approx(0.05)
    v = np.abs(loading_result.columns["velocity_rad_s_1.48kg"])
    assert np.percentile(v, 90) <= 0.05 * 1.05  # stick-slip spikes aside, the speed stays in range


def test_loading_report_current_is_a_supply_current_not_the_winding_current(loading_result):
    # The report's -0.2..0.7 A and 0.39 W cannot be the motor's q-axis current and winding power:
    # holding ~8 N*m at the ankle needs i = T/(Kt N eta) ~ 4.6 A, whose copper loss alone is ~4 W.
    # Both readings are rows: the q-axis current is several amperes (> 4x the report's 0.7 A), while the
    # supply current P/V lies within the report's range.
    rows = {f.name: f for f in loading_result.figures}
    assert rows["q-axis (phase) current range, 1.48 kg"].emulated_value > 4 * 0.7
    lo, hi = loading_result.parameters["supply_current_a_1.48kg"]
    assert -0.2 <= lo < hi <= 0.7
    assert rows["mean per-period peak electrical power, 1.48 kg"].emulated_value > 5 * 0.39


def test_every_bench_row_has_a_basis():
    with pytest.raises(ValueError, match="basis"):
        Figure("x", "s", "", None, 1.0)
    with pytest.raises(ValueError, match="basis"):
        Figure("x", "s", "", None, 1.0, basis="fitted")  # the parameter must be named


def test_spring_calibration_tables_imply_far_less_than_215_n_per_m():
    # Tables B4/B5 (5 oscillations of 680 g in 5.92 s, of 1080 g in 8.36 s) give k = m (2 pi/T)^2 of
    # 19.2 and 15.3 N/m, 11.4 N/m with the spring's mass cancelled: none is near 215 or 250 N/m.
    r = spring_calibration.run()
    p = r.parameters
    assert p["k_680g_n_per_m"] == pytest.approx(0.68 * (2 * math.pi / (29.6 / 25)) ** 2)
    assert p["k_two_mass_n_per_m"] < p["k_1080g_n_per_m"] < p["k_680g_n_per_m"] < 0.1 * 215
    assert all(f.basis == "predicted" for f in r.figures)


def test_design_point_within_the_current_limit_at_the_rated_torque():
    # 14 N*m at 55 rpm needs ~7.5 A (the firmware's 12 A allows ~22 N*m) and ~13 V of the 24 V bus. It is
    # exactly the maker's rated 3 N*m x 14/3 (the report's input pulley "expected to transmit 3 Nm"); only
    # the assumed 5 % belt loss puts it above (13.3 N*m): that row is assumed, not predicted. "21 Nm at
    # 250 rpm" read at the ankle is out of reach (> 24 V); read at the input pulley it needs 11.2 A, 13.5 V.
    r = design_point.run()
    fig = {f.name: f for f in r.figures}
    rows = {f.name: f.emulated_value for f in r.figures}
    assert 7.0 < rows["current for 14 N*m at the ankle"] < 12.0
    assert rows["bus voltage for 14 N*m at 55 rpm"] < 24.0
    assert rows["ankle torque at the firmware's current limit"] == pytest.approx(22.4, abs=0.1)
    rated = fig["maker's rated (continuous) torque at the ankle"]
    assert rated.emulated_value < 14.0 and rated.basis.startswith("assumed: belt efficiency")
    assert 3.0 * load_plant_params().belt_ratio == pytest.approx(14.0)
    assert r.parameters["safety_case"]["voltage_v"] > 24.0
    sf_in = r.parameters["safety_case_input_pulley_rpm"]
    assert sf_in["current_a"] == pytest.approx(11.2, abs=0.1) and sf_in["voltage_v"] == pytest.approx(13.5, abs=0.1)
    # K_t x 6 x eta_gearbox against the maker's 3 N*m / 6.5 A at the actuator output: 9 % apart
    assert rows["actuator output torque per amp"] == pytest.approx(0.421, abs=0.001)


def test_motor_tf_shows_eq_3_39_erratum_and_the_corrected_poles():
    # Report eq 3.39: numerator K_t/(J L) = 23.21e6 from Table B2; its constant term 3.261e9 is 140.5 times
    # that, the Kv (140 rpm/V) where K_e belongs. With K_e: omega_n = 1289 rad/s, zeta = 0.57 (no viscous
    # term), DC gain about 1/K_e.
    from host_tools.benchtests import motor_tf

    r = motor_tf.run()
    p = load_plant_params()
    assert r.parameters["constant_over_numerator"] == pytest.approx(p.kv_rpm_per_v, abs=1.0)
    assert r.parameters["corrected"]["num"][0] == pytest.approx(23.21e6, rel=2e-3)
    nob = r.parameters["without_viscous"]
    assert nob["wn_rad_s"] == pytest.approx(1289, abs=3) and nob["zeta"] == pytest.approx(0.57, abs=0.01)
    assert r.parameters["eq339"]["zeta"] < 0.02  # as printed: rings
    rows = {f.name: f for f in r.figures}
    assert rows["DC gain, speed per volt"].emulated_value == pytest.approx(1 / p.ke_v_s_per_rad, rel=0.05)
    assert rows["no-load speed at 24 V"].emulated_value == pytest.approx(3360, rel=0.1)
    assert 0 < r.parameters["step_corrected"]["overshoot_pct"] < 20 < r.parameters["step_eq339"]["overshoot_pct"]


@pytest.mark.parametrize("geometry", ["level-com", "hanging"])
def test_kinematics_report_chain_moves_the_ankle_and_the_plant_matches_the_belt_chain(geometry):
    # Table 3.3 chained as a serial arm turns the foot by (1 + 1/G) theta_1, G + 1 times the ankle angle,
    # and carries the ankle axis around the input pulley; the belt drive keeps the axis fixed. The plant's
    # potential energy is m g z of the centre of mass the belt-drive chain places, under either geometry.
    from hal.virtual.plant.readings import with_geometry
    from host_tools.benchtests import kinematics

    p = with_geometry(load_plant_params(), geometry)
    r = kinematics.run(params=p)
    assert r.parameters["turn_ratio"] == pytest.approx(1 + p.belt_ratio, rel=1e-6)
    assert r.parameters["axis_travel_m"] > 0.1
    assert r.parameters["potential_error_j"] < 1e-9
    com0 = next(f.emulated_value for f in r.figures if f.name.startswith("centre of mass height"))
    assert com0 == pytest.approx(-p.foot_com_distance_m if geometry == "hanging" else 0.0, abs=1e-12)
    _, t02 = kinematics.report_chain(0.0, p.belt_ratio, 0.08, 0.21)
    assert t02[0, 3] == pytest.approx(-0.21) and t02[1, 3] == pytest.approx(-0.08)  # 90 deg + 90 deg at theta_1 = 0
    toe_x, toe_y = r.columns["dh_toe_x_m"], r.columns["belt_toe_x_m"]
    zero = int(np.argmin(np.abs(r.columns["ankle_rad"])))
    assert toe_x[zero] == pytest.approx(toe_y[zero], abs=1e-12)  # the chains agree at 0 deg only
    assert r.parameters["toe_error_m"] > 0.1


def test_open_loop_eq_3_67_is_stable_and_the_hanging_loop_brakes_through_the_windings():
    # Eq 3.67 as written is a hanging pendulum with back-EMF damping: all poles in the left half plane and
    # overdamped, so released from pi/5 it creeps back to 0 and never "falls [...] within 0.5 s" (3.6.1).
    # The bench loop under the voltage-amplifier reading shorts the windings at zero output: with the COM
    # level gravity has no restoring part (a pole at 0), hanging the slowest pole is about mgd / (K_t K_e N^2
    # eta / R) away from 0.
    from hal.virtual.plant.readings import with_geometry
    from host_tools.benchtests import open_loop

    level = open_loop.run()
    rows = {f.name: f for f in level.figures}
    assert rows["eq 3.67 as written: largest real part of its poles"].emulated_value < 0
    assert math.isnan(rows["eq 3.67 as written: release from pi/5, time to -30 deg"].emulated_value)
    assert min(level.columns["release_eq367_deg"]) > -1.0
    assert abs(level.parameters["slowest_pole_real_1_s"]) < 1e-9
    p = with_geometry(load_plant_params(), "hanging")
    hanging = open_loop.run(params=p)
    b_emf = p.output_torque_per_amp_nm * p.ke_v_s_per_rad * p.total_ratio / p.phase_resistance_ohm
    assert hanging.parameters["slowest_pole_real_1_s"] == pytest.approx(-p.gravity_moment_nm / (
        b_emf + p.foot_damping_nm_s_per_rad), rel=0.05)


def test_root_locus_reproduces_appendix_b_and_its_pick_tracks_on_the_emulator():
    # Appendix B: k = R wc / (1 - exp(-R Ts/L)), ki = 1 - exp(-R Ts/L); the PI zero cancels the winding's
    # pole and the closed-loop pole is 1 - wc = 0.372, whatever R and L.
    from host_tools.benchtests import root_locus

    g = root_locus.appendix_b_gains(**root_locus.APPENDIX_B)
    assert g["k"] == pytest.approx(0.5 * math.pi / 5, rel=1e-9) and g["ki"] == pytest.approx(1.0)
    assert g["closed_loop_pole_z"] == pytest.approx(1 - math.pi / 5)
    g2 = root_locus.appendix_b_gains(0.202, 138e-6, 1e-4, math.pi / 5)
    assert g2["pi_zero_z"] == pytest.approx(g2["plant_pole_z"]) and g2["closed_loop_pole_z"] == pytest.approx(
        1 - math.pi / 5)
    r = root_locus.run(quick=True)
    pick = r.parameters["pick_gain_per_rad"]
    assert 0 < pick < r.parameters["unstable_above_per_rad"]
    poles = [complex(s) for s in r.parameters["pick_poles"]]
    slow = min(poles, key=lambda s: -s.real)
    assert -slow.real / abs(slow) == pytest.approx(root_locus.TARGET_ZETA, abs=0.03)
    assert 0 < r.parameters["track_rms_deg"] < 3.0  # the pick follows the gait on the nonlinear plant


def test_loading_current_changes_sign_only_hanging_with_the_tables_spring(loading_result):
    # Issue 24 read the report's -0.2..0.7 A as a q current that changes sign under eq 3.55 with the spring
    # rate of Tables B4/B5. Emulated over a whole period: hanging with the tables' 11.4 N/m the current does
    # change sign (about -1.5..1.7 A with 1.48 kg, -1.0..1.1 A without a load: larger than the report's, the
    # friction and the load included); with the COM level it never does.
    from hal.virtual.plant.readings import with_geometry

    hanging = loading.run(params=with_geometry(load_plant_params(), "hanging"), periods=1.0).parameters
    for key in ("current_a_tables_spring_no_load", "current_a_tables_spring_1.48kg"):
        lo, hi = hanging[key]
        assert lo < 0 < hi and hi - lo < 4.0, key
    level = loading_result.parameters  # loading.run(periods=1.0): the level-COM geometry
    assert level["current_a_tables_spring_no_load"][0] > 0 and level["current_a_tables_spring_1.48kg"][0] > 0


def test_docs_readings_table_is_what_pafp_bench_readings_table_prints(capsys):
    # docs/bench.md carries the table `pafp bench readings-table` prints, verbatim: regenerate it when a
    # figure moves. Every row names a reproducing reading or "neither", for both geometries.
    from pathlib import Path

    assert main(["bench", "readings-table"]) == 0
    printed = capsys.readouterr().out
    doc = (Path(__file__).resolve().parents[1] / "docs" / "bench.md").read_text()
    start = doc.index("<!-- readings-table")
    block = doc[doc.index("\n", start) + 1:doc.index("<!-- /readings-table -->")]
    assert block == printed
    rows = [line for line in printed.splitlines() if line.startswith("| geometry |")]
    assert len(rows) >= 10
    verdicts = [row.rstrip(" |").rsplit("| ", 1)[1] for row in rows]
    assert any(v.startswith("level-com (") for v in verdicts) and any(v.startswith("hanging (") for v in verdicts)

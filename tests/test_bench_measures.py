"""What a run measures like a bench: four tracking figures over RUN time only, the plant drawn from its
tolerances, and the real bench's imperfections, each switchable."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hal.virtual.imperfections import NAMES, load_imperfections
from hal.virtual.plant import load_plant_params
from hal.virtual.plant.draw import draw_plant, drawn_values, load_tolerances
from host_tools.cli import main
from host_tools.reports.metrics import RUN_STATE, run_window, signal_figures
from host_tools.reports.report import summarise
from host_tools.runner import RunConfig, run_virtual

SIGNALS = ("imu", "encoder", "fused", "truth")


def _estop_at(t_s: float):
    def setup(bench, fw) -> None:
        bench.estop.set_at(int(t_s * bench.f_cpu_hz), True)
    return setup


@pytest.fixture(scope="module")
def two_strides():
    return summarise(run_virtual(RunConfig(strides=2, trace_capacity=0)))


def test_four_tracking_figures_and_the_imu_shows_degrees(two_strides):
    tr = two_strides["tracking"]
    assert tr["enough_run"] and tr["time_in_run_s"] == pytest.approx(2 * 1.1, abs=0.003)
    for name in SIGNALS:
        assert set(tr[name]) >= {"rms_deg", "max_deg", "lag_ms"}, name
        assert 0 < tr[name]["rms_deg"] <= tr[name]["max_deg"], name
    assert tr["truth"]["emulation_only"] is True
    # the IMU's 19.5 ms lag and 100 Hz frames at gait speeds: degrees, not the encoder's tenths
    assert tr["imu"]["rms_deg"] > 1.0 and tr["imu"]["rms_deg"] > 3 * tr["encoder"]["rms_deg"]
    assert tr["imu"]["lag_ms"] > 15.0
    # the top-level figures are what a bench measures (IMU, encoder), never the truth (issue 24)
    from host_tools.reports.report import HEADLINE_KEYS

    for key in HEADLINE_KEYS:
        sig, fig = key.split("_", 1)
        src = {"rms_error_deg": "rms_deg", "max_error_deg": "max_deg", "lag_ms": "lag_ms"}[fig]
        assert two_strides[key] == tr[sig][src], key
    tracking_keys = [k for k in two_strides if k.endswith(("_deg", "lag_ms")) and not isinstance(two_strides[k], dict)]
    assert sorted(tracking_keys) == sorted(HEADLINE_KEYS)
    truth = {tr["truth"][k] for k in ("rms_deg", "max_deg", "lag_ms")}
    assert not truth & {two_strides[k] for k in tracking_keys}, "a top-level tracking figure is the truth"


def test_a_run_stopped_before_one_stride_gives_no_figure():
    r = run_virtual(RunConfig(strides=2, trace_capacity=0, setup=_estop_at(1.2)))  # gait starts near 0.51 s
    s = summarise(r)
    tr = s["tracking"]
    assert s["supervisor_state"] == "SAFE"
    assert not tr["enough_run"] and 0.0 < tr["time_in_run_s"] < 1.1 and "less than one stride" in tr["note"]
    for name in SIGNALS:
        assert tr[name]["rms_deg"] is None and tr[name]["max_deg"] is None, name
    assert s["imu_rms_error_deg"] is None and s["encoder_max_error_deg"] is None


def test_figures_cover_only_the_run_state():
    r = run_virtual(RunConfig(strides=3, trace_capacity=0, setup=_estop_at(2.9)))
    s = summarise(r)
    p = r.probe.arrays()
    run = p["supervisor_state"] == RUN_STATE
    gait = (p["t_s"] >= r.gait_start_s) & (p["t_s"] < r.gait_start_s + 3 * 1.1)
    expected_s = float(np.sum(run & gait)) / 500.0
    assert s["tracking"]["time_in_run_s"] == pytest.approx(expected_s, abs=1e-6)
    assert 1.1 < expected_s < 3.3
    err = np.degrees(p["reference_rad"] - p["true_angle_rad"])[run & gait]
    assert s["tracking"]["truth"]["rms_deg"] == pytest.approx(float(np.sqrt(np.mean(err**2))), abs=1e-4)
    # the limp foot after the trip is not in the figure: over the whole window it would be far worse
    everything = np.degrees(p["reference_rad"] - p["true_angle_rad"])[gait]
    assert np.sqrt(np.mean(everything**2)) > 2 * s["tracking"]["truth"]["rms_deg"]


def test_run_window_counts_run_samples_only():
    t = np.arange(0.0, 4.0, 0.002)
    state = np.where((t > 2.0) & (t < 2.5), 2, RUN_STATE)
    w = run_window(t, state, gait_start_s=1.0, stride_s=1.0, strides=2)
    assert w.time_in_run_s == pytest.approx(1.5, abs=0.003) and w.enough
    ref = np.zeros_like(t)
    ang = np.where(state == RUN_STATE, 0.01, 1.0)  # huge error only while not in RUN
    assert signal_figures(t, ref, ang, w)["max_deg"] == pytest.approx(math.degrees(0.01), abs=1e-4)


def test_plant_draw_is_a_function_of_profile_and_seed():
    nominal = load_plant_params()
    a, b, c = draw_plant(nominal, 1), draw_plant(nominal, 1), draw_plant(nominal, 2)
    assert a == b and a != c and a != nominal
    drawn = drawn_values(nominal, a)
    for t in load_tolerances():
        lo, hi = t.bounds(getattr(nominal, t.name))
        assert lo <= getattr(a, t.name) <= hi, t.name
        assert t.name in drawn
    assert a.ke_v_s_per_rad / a.kt_nm_per_a == pytest.approx(nominal.ke_v_s_per_rad / nominal.kt_nm_per_a)
    with pytest.raises(ValueError, match="plant seed"):
        draw_plant(nominal, -1)


def test_plant_seeds_give_different_plants_and_truth_with_the_same_firmware(two_strides):
    runs = {k: summarise(run_virtual(RunConfig(strides=2, trace_capacity=0, plant_seed=k))) for k in (1, 2)}
    assert runs[1]["plant"]["drawn"] != runs[2]["plant"]["drawn"]
    assert runs[1]["tracking"]["truth"]["rms_deg"] != runs[2]["tracking"]["truth"]["rms_deg"]
    assert two_strides["plant"] == {**two_strides["plant"], "seed": None, "drawn": {}}


def test_imperfections_switch_off_one_by_one():
    imp = load_imperfections()
    assert all(imp.enabled(n) for n in NAMES)  # the default is the real device
    opts = imp.bench_options(0)
    assert opts["imu_config"].bias_sigma_rad > 0 and opts["imu_config"].bias_drift_sigma_rad > 0
    assert opts["initial_angle_rad"] != 0.0
    ideal = imp.without(["all"]).bench_options(0)
    assert ideal["initial_angle_rad"] == 0.0 and ideal["imu_config"].bias_sigma_rad == 0.0
    assert ideal["imu_config"].pitch_noise_rad == ideal["imu_config"].bias_drift_sigma_rad == 0.0
    only = imp.without(["imu_noise"]).bench_options(0)
    assert only["imu_config"].pitch_noise_rad == 0.0 and only["initial_angle_rad"] == opts["initial_angle_rad"]
    with pytest.raises(ValueError, match="imperfection 'nope' unknown"):
        imp.without(["nope"])


def test_encoder_offset_is_the_power_up_pose_and_the_imu_fixes_it():
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, ideal=("imu_bias", "imu_drift", "imu_noise")))
    s = summarise(r)
    offset = s["imperfections"]["encoder_offset_rad"]
    assert abs(math.degrees(offset)) > 0.1
    p = r.probe.arrays()
    sel = p["supervisor_state"] == RUN_STATE
    count = 2 * math.pi / 4000
    # the incremental encoder reads from where the foot was at power-up: off by the offset, to a count
    assert np.mean(p["encoder_angle_rad"][sel] - p["true_angle_rad"][sel]) == pytest.approx(-offset, abs=count)
    # the fused estimate takes its absolute angle from the (here ideal) IMU
    assert abs(np.mean(p["fused_angle_rad"][sel] - p["true_angle_rad"][sel])) < 0.5 * abs(offset)


def test_cli_prints_measured_first_and_truth_labelled(tmp_path, capsys):
    assert main(["run", "--quiet", "--strides", "1", "--plant-seed", "3", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if "tracking," in ln]
    assert [ln.split(",")[1].split()[0] for ln in lines] == ["imu", "encoder", "fused", "truth"]
    assert "emulation only" in lines[-1]
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["plant"]["seed"] == 3 and s["plant"]["drawn"]
    md = (tmp_path / "report.md").read_text()
    assert md.index("imu:") < md.index("truth:") and "emulation only" in md


@pytest.mark.parametrize("argv, text", [(["--plant-seed", "-2"], "plant seed -2 out of range"),
                                        (["--ideal", "warp"], "imperfection 'warp' unknown")])
def test_bad_plant_options_exit_2_naming_the_value(tmp_path, capsys, argv, text):
    assert main(["run", "--quiet", *argv, "--out", str(tmp_path / "x")]) == 2
    assert text in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_backlash_holds_off_torque_while_the_rotor_crosses_the_gap():
    from hal.virtual.plant import Plant, spring_bench

    p = load_plant_params()
    gap = math.radians(0.55)  # maker: at the actuator output

    def reversal(plant: Plant) -> list[float]:
        plant.set_current_command(2.0, 0.0)  # first contact: engaged at once
        currents = [plant.current_q_a(0.01)]
        for k in range(1, 21):  # then -1 A every millisecond, as the firmware commands
            plant.set_current_command(-1.0, 0.01 + (k - 1) * 1e-3)
            currents.append(plant.current_q_a(0.01 + k * 1e-3 - 1e-6))
        return currents

    slack, stiff = Plant(p, spring_bench(0.68), backlash_rad=gap), Plant(p, spring_bench(0.68))
    with_gap, without = reversal(slack), reversal(stiff)
    assert with_gap[0] > 1.9 and without[0] > 1.9
    assert without[5] < -0.9  # no gap: the reversed torque is there within a few driver time constants
    # the rotor turns 3.3 deg on its own inertia (about 6 ms at 1 A, the spring's pull helping): meanwhile
    # nothing reaches the output, afterwards the command does
    crossing = [k for k, i in enumerate(with_gap) if abs(i) < 0.05]
    assert 3 <= len(crossing) <= 8, with_gap
    assert with_gap[-1] < -0.95
    assert slack.gap_crossings == 1 and stiff.gap_crossings == 0


def test_tracking_plot_draws_the_encoder_strides_beside_the_imu_and_the_truth():
    # tracking.png's top panel: the IMU (what the report plotted), the encoder (the bench-measurable stand-in
    # for the foot) and the truth (emulation only), each stride cut from the run
    from host_tools.reports.report import tracking_of
    from host_tools.reports.tracking_stream import PLOT_STRIDES

    assert PLOT_STRIDES == ("imu", "encoder", "truth")
    strides = tracking_of(run_virtual(RunConfig(strides=2, trace_capacity=0))).strides
    assert len(strides["encoder"].angles_deg) == 2 and len(strides["imu"].angles_deg) == 2
    assert not np.allclose(strides["encoder"].angles_deg, strides["truth"].angles_deg)  # its own signal

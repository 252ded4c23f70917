"""The winding model and the battery wired into `pafp run`: summary.json's thermal and battery (issue 23)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hal.virtual.plant.battery import load_battery
from host_tools.cli import main
from host_tools.reports.report import write_outputs
from host_tools.reports.thermal import walking_speed_m_s
from host_tools.runner import RunConfig, run_virtual


def _summary(tmp_path: Path, cfg: RunConfig) -> dict:
    return write_outputs(run_virtual(cfg), tmp_path, plot=False, trace=False)


def test_the_motor_reports_the_winding_model_from_the_ambient(tmp_path: Path) -> None:
    s = _summary(tmp_path, RunConfig(strides=2, ambient_c=40.0))
    t = s["thermal"]
    assert t["ambient_c"] == 40.0 and t["model"] == "two-node" and t["emulation_only"] is True
    assert len(t["winding_c_by_stride"]) == 2
    assert all(40.0 < w <= t["winding_c_max"] for w in t["winding_c_by_stride"])  # heated by the copper loss
    assert t["housing_c_end"] >= 40.0
    # the reply's 0.1 C steps: the firmware saw the model's temperature, not the default 25 C
    assert t["motor_reported_c_max"] == pytest.approx(t["winding_c_max"], abs=0.15)
    assert t["steady_state_c"] > t["ambient_c"]
    assert t["derating_started_s"] is None and t["over_temperature_at_s"] is None
    assert s["battery"] is None  # no battery asked, no design: the ideal supply
    assert s["faults"] == []


def test_without_the_thermal_model_the_single_node_estimate_is_reported(tmp_path: Path) -> None:
    s = _summary(tmp_path, RunConfig(strides=1, thermal=False))
    assert s["thermal"]["model"] == "single-node" and s["thermal"]["steady_state_c"] is None


def test_a_battery_sags_under_load_takes_regeneration_and_gives_the_distance_per_charge(tmp_path: Path) -> None:
    s = _summary(tmp_path, RunConfig(strides=3, scenario="walk", body_mass_kg=20.0, battery="molicel_p42a_6s1p"))
    b = s["battery"]
    pack = load_battery("molicel_p42a_6s1p")
    assert b["name"] == "molicel_p42a_6s1p" and b["capacity_wh"] == pytest.approx(pack.capacity_wh, abs=0.01)
    assert b["min_bus_v"] < pack.open_circuit_v(1.0) - 0.1  # I R under load
    assert b["regenerated_j"] > 0.0 and b["soc_end"] < 1.0
    assert len(b["bus_v_by_stride"]) == 3 and len(b["bus_v_min_by_stride"]) == 3
    assert all(lo < end for lo, end in zip(b["bus_v_min_by_stride"], b["bus_v_by_stride"], strict=True))
    assert min(b["bus_v_min_by_stride"]) == pytest.approx(b["min_bus_v"], abs=1e-3)
    e = b["energy_per_stride_j"]
    assert e > 0.0
    assert b["strides_per_charge"] == pytest.approx(pack.capacity_wh * 3600.0 / e, rel=1e-3)
    speed = walking_speed_m_s(None)
    assert b["speed_m_s"] == pytest.approx(speed, abs=1e-3) and 1.3 < speed < 1.4  # free speed, 0.43 sqrt(g L)
    assert b["distance_per_charge_km"] == pytest.approx(b["strides_per_charge"] * speed * 1.1 / 1000.0, rel=1e-3)


def test_the_same_seed_gives_the_same_thermal_and_battery_figures(tmp_path: Path) -> None:
    cfg = RunConfig(strides=1, battery="molicel_p42a_6s1p", ambient_c=30.0)
    a = _summary(tmp_path / "a", cfg)
    b = _summary(tmp_path / "b", cfg)
    assert a["thermal"] == b["thermal"] and a["battery"] == b["battery"]
    assert (tmp_path / "a" / "telemetry.bin").read_bytes() == (tmp_path / "b" / "telemetry.bin").read_bytes()


@pytest.mark.parametrize("args, message", [
    (["--ambient-c", "81"], "ambient temperature 81.0 C out of range"),
    (["--battery", "no_such_pack"], "no_such_pack"),
])
def test_bad_heat_options_stop_before_the_run(tmp_path: Path, capsys, args: list[str], message: str) -> None:
    code = main(["run", "--strides", "1", "--out", str(tmp_path / "out"), *args])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_the_report_and_the_plot_show_the_walk(tmp_path: Path) -> None:
    assert main(["run", "--strides", "1", "--battery", "molicel_p42a_6s1p", "--no-trace", "--out", str(tmp_path)]) == 0
    md = (tmp_path / "report.md").read_text()
    assert "## Winding temperature and battery" in md and "energy per stride at the battery" in md
    assert (tmp_path / "thermal.png").stat().st_size > 0
    assert json.loads((tmp_path / "summary.json").read_text())["battery"]["name"] == "molicel_p42a_6s1p"


def _hot_profile(tmp_path: Path) -> Path:
    """The shipped firmware profile with thresholds a few kelvin above a 40 C ambient (the walk's heat reaches them
    within a few strides; the shipped 70/100/90 C take a long walk at 80 C ambient)."""
    from firmware.config import DEFAULT_PROFILE

    text = DEFAULT_PROFILE.read_text()
    for old, new in (("derate_start_c = 70.0", "derate_start_c = 41.0"), ("fault_c = 90.0", "fault_c = 43.0")):
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "hot.toml"
    path.write_text(text)
    return path


def test_a_hot_walk_derates_then_latches_over_temperature_and_the_summary_says_when(tmp_path: Path) -> None:
    from firmware.config import load_firmware_config
    from protocol.telemetry import FaultReason, TelemetryDecoder

    fw = load_firmware_config(_hot_profile(tmp_path))
    s = _summary(tmp_path / "out", RunConfig(strides=12, scenario="walk", body_mass_kg=20.0, ambient_c=40.0,
                                             firmware=fw))
    t = s["thermal"]
    assert s["faults"] == ["OVER_TEMPERATURE"]
    assert t["derating_started_s"] is not None and t["over_temperature_at_s"] is not None
    assert 1.5 < t["derating_started_s"] < t["over_temperature_at_s"]  # heated past 41 C first, then past 43 C
    assert t["motor_reported_c_max"] > 43.0
    assert t["steady_state_c"] > 43.0  # the strides before the trip (not the safe state after it) tend above it
    # the telemetry says it too: the supervisor in SAFE for OVER_TEMPERATURE from the trip on, the motor told zero
    # current, then the shipped safe state (graded: the phase short or the damper, no current command)
    records = TelemetryDecoder().feed((tmp_path / "out" / "telemetry.bin").read_bytes())
    f_cpu = 168e6
    after = [r for r in records if r.time_cycles / f_cpu > t["over_temperature_at_s"] + 0.002]
    assert after and all(r.fault_reason == FaultReason.OVER_TEMPERATURE for r in after)
    assert all(r.current_cmd_a == 0.0 for r in after)


def test_the_same_hot_walk_with_the_shipped_thresholds_neither_derates_nor_latches(tmp_path: Path) -> None:
    # the counterpart: the heat alone (40 C ambient, a few strides) stays below the shipped 70 C
    s = _summary(tmp_path, RunConfig(strides=3, scenario="walk", body_mass_kg=20.0, ambient_c=40.0))
    assert s["thermal"]["derating_started_s"] is None and s["thermal"]["over_temperature_at_s"] is None
    assert s["faults"] == []


@pytest.mark.parametrize("link", ["uart", "can-servo", "can-mit"])
def test_every_motor_link_carries_the_temperature_the_firmware_derates_on(tmp_path: Path, link: str) -> None:
    # 75 C ambient: above the shipped 70 C derating start, so the firmware derates as soon as a reading arrives
    from dataclasses import replace

    from firmware.config import load_firmware_config

    fw = replace(load_firmware_config(), motor_link=link)
    t = _summary(tmp_path, RunConfig(strides=1, ambient_c=75.0, firmware=fw))["thermal"]
    assert t["motor_reported_c_max"] >= 75.0
    assert t["derating_started_s"] is not None and t["derating_started_s"] < 0.5


def test_the_thermal_model_and_battery_come_from_the_design_and_battery_wins() -> None:
    # RunConfig.design (a design profile's [design] table) names the motor and the battery; --battery wins
    from types import SimpleNamespace

    from hal.virtual.bench import VirtualBench
    from hal.virtual.plant.motors import load_motor
    from hal.virtual.plant.thermal import ThermalParams
    from host_tools.runner import attach_heat

    design = SimpleNamespace(motor="ak80_9", battery="molicel_p42a_12s1p")

    def fitted(**kw) -> tuple[VirtualBench, dict]:
        bench = VirtualBench(lambda: 0, 168_000_000)
        cfg = SimpleNamespace(**{"design": design, "ambient_c": 30.0, "thermal": True, "battery": None, **kw})
        return bench, attach_heat(bench, cfg)

    bench, rec = fitted()
    assert rec["motor"] == "ak80_9" and rec["winding"].params == ThermalParams.from_motor(load_motor("ak80_9"))
    assert bench.motor.meter.winding is rec["winding"] and rec["winding"].winding_c == 30.0
    assert rec["battery"].params.name == "molicel_p42a_12s1p" and bench.motor.meter.battery is rec["battery"]
    _, rec = fitted(battery="molicel_p42a_6s1p")
    assert rec["battery"].params.name == "molicel_p42a_6s1p"
    _, rec = fitted(design=None, thermal=False)
    assert rec["motor"] == "ak60_6" and "winding" not in rec and rec["battery"] is None


def test_regeneration_is_counted_per_stride_from_the_gait_s_start() -> None:
    """What the start-up ramp (and any settling) regenerates is no stride's: each stride gets its own."""
    from types import SimpleNamespace

    from host_tools.reports.heat_log import HeatLog

    meter = SimpleNamespace(battery=None, winding=None, temp_motor_c=25.0, v_in_v=24.0, reset_v_in_min=lambda: 24.0,
                            watt_seconds=0.0, watt_seconds_charged=0.0)
    log = HeatLog(meter, SimpleNamespace(temp_motor_c=25.0), lambda: 1.0, stride_s=1.0)
    for t, drawn, back in [(0.5, 3.0, 5.0), (1.0, 4.0, 5.0), (1.5, 9.0, 6.0), (2.0, 10.0, 7.5), (3.0, 20.0, 9.5)]:
        meter.watt_seconds, meter.watt_seconds_charged = drawn, back
        log.sample(t)
    assert log.stride_regenerations_j() == [2.5, 2.0]  # the 5 J before the gait's start left out
    assert log.stride_energies_j() == [(10.0 - 7.5) - (4.0 - 5.0), (20.0 - 9.5) - (10.0 - 7.5)]

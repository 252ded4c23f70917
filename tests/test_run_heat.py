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
    assert len(b["bus_v_by_stride"]) == 3
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
    assert main(["run", "--strides", "1", "--battery", "molicel_p42a_6s1p", "--out", str(tmp_path)]) == 0
    md = (tmp_path / "report.md").read_text()
    assert "## Winding temperature and battery" in md and "energy per stride at the battery" in md
    assert (tmp_path / "thermal.png").stat().st_size > 0
    assert json.loads((tmp_path / "summary.json").read_text())["battery"]["name"] == "molicel_p42a_6s1p"

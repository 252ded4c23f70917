"""Gait events from the load cell and FSRs: latency against the scenario's true events beside today's
motor-load detector, the fallback when a sensor fails, the impedance controller on them, the outputs."""

from __future__ import annotations

import json

import pytest

from firmware.config import load_firmware_config
from firmware.control.ground_events import GroundEvents
from firmware.control.registry import build_controller
from firmware.drivers.ground_sensor_config import GroundSensorConfig
from firmware.drivers.ground_sensors import GroundSensorDriver
from hal.interfaces import Adc
from host_tools.cli import main
from host_tools.reports.gait_latency import event_summary, latencies
from host_tools.runner import RunConfig, run_virtual


def _walk(strides=3, **kw):
    cfg = load_firmware_config()
    ctl = build_controller("impedance", cfg, {"body_mass_kg": 20.0})
    return run_virtual(RunConfig(strides=strides, firmware=cfg, controller=ctl, scenario="walk", body_mass_kg=20.0,
                                 trace_capacity=0, **kw))


def test_ground_sensors_detect_heel_strike_within_20_ms_and_toe_off_within_30_ms():
    r = _walk()
    g = event_summary(r)
    assert r.firmware.supervisor.reason.name == "NONE"
    assert g["detector"] == "ground_sensors" and g["fallback"] is None
    new, old = g["ground_sensors"], g["motor_load"]
    assert new["heel_strike"]["missed"] == new["toe_off"]["missed"] == 0
    assert 0 <= new["heel_strike"]["median_ms"] <= 20
    assert abs(new["toe_off"]["median_ms"]) <= 30
    assert new["foot_flats"] >= 3 and new["heel_offs"] >= 3
    assert old["heel_strike"]["median_ms"] > 50  # today's detector: late in the loading response
    assert r.firmware.controller.transitions >= 12  # four phases a stride, switched on the sensed events
    obs = r.firmware.obs
    assert obs.ground_sensors_ok


def test_with_the_fsrs_failed_the_firmware_falls_back_to_the_motor_load_detector():
    r = _walk(sensor_faults=("fsr_heel:open", "fsr_toe:open"))
    g = event_summary(r)
    assert r.firmware.supervisor.reason.name == "NONE"
    assert g["detector"] == "motor_load"
    assert "FSR never on" in g["fallback"]["reason"]
    assert g["fallback"]["t_s"] < r.gait_start_s + 1.1  # caught in the first stride
    used = g["used"]
    assert used["heel_strike"]["missed"] == 0 and used["toe_off"]["missed"] == 0
    assert not r.firmware.obs.ground_sensors_ok
    assert r.firmware.controller.transitions >= 8


def test_a_shorted_fsr_and_a_saturated_load_cell_latch_a_fault():
    class FakeAdc(Adc):
        def __init__(self):
            super().__init__(["load_force", "load_moment", "fsr_heel", "fsr_toe"])
            self.codes = [372, 2048, 0, 0]

        def _dma_buffer(self):
            return list(self.codes)

    cfg = GroundSensorConfig(fault_samples=5)
    adc = FakeAdc()
    det = GroundEvents(GroundSensorDriver(adc, cfg, 0.001))
    for k in range(400):
        det.update(k / 1000)
    assert det.healthy and not det.stance
    adc.codes[3] = 4095  # toe divider at the supply
    for k in range(400, 404):
        det.update(k / 1000)
    assert det.healthy  # not yet fault_samples periods
    det.update(0.404)
    assert det.fault == "toe FSR shorted"
    det2 = GroundEvents(GroundSensorDriver(adc, cfg, 0.001))
    adc.codes = [372, 2048, 0, 0]
    for k in range(400):
        det2.update(k / 1000)
    adc.codes[0] = 4095
    for k in range(400, 406):
        det2.update(k / 1000)
    assert det2.fault == "load cell at an amplifier rail"
    adc.codes = [0, 0, 0, 0]  # a board that never sends: never tared, never healthy, then a fault
    det3 = GroundEvents(GroundSensorDriver(adc, cfg, 0.001))
    for k in range(800):
        det3.update(k / 1000)
    assert not det3.healthy and det3.fault == ""
    det3.update(0.801)
    assert det3.fault == "no load-cell data since boot"


def test_suspended_with_the_sensors_fitted_sees_no_ground():
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, ground_sensors=True))
    ev = r.firmware.ground_events
    assert ev is not None and ev.healthy and ev.heel_strike_s == [] and ev.driver.tared
    assert abs(ev.driver.force_n) < 5.0
    assert event_summary(r) is None  # no ground, no true events
    default = run_virtual(RunConfig(strides=1, trace_capacity=0))
    assert default.bench.board.adc is None and default.firmware.ground_events is None


def test_latency_pairs_each_true_event_with_its_first_detection():
    assert latencies([1.0, 2.0, 3.0], [0.95, 2.01, 2.02], 0.5) == ([pytest.approx(-0.05), pytest.approx(0.01)], 1)


def test_cli_walk_reports_both_detectors_and_which_one_was_used(tmp_path):
    out = tmp_path / "out"
    code = main(["run", "--quiet", "--no-plot", "--strides", "2", "--scenario", "walk", "--body-mass", "20",
                 "--controller", "impedance", "--sensor-fault", "fsr_toe:short", "--out", str(out)])
    s = json.loads((out / "summary.json").read_text())
    assert code == (1 if s["faults"] else 0)
    g = s["gait_events"]
    assert g["detector"] == "motor_load" and g["fallback"]["reason"] == "toe FSR shorted"
    md = (out / "report.md").read_text()
    assert "## Gait events (detection latency, emulation only)" in md and "motor load (today's; in this run)" in md
    assert "fallback after: toe FSR shorted" in md


def test_cli_bad_sensor_fault_is_one_line_and_exit_2(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", "--quiet", "--scenario", "walk", "--sensor-fault", "fsr_heel:melted", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "sensor fault 'fsr_heel:melted' unknown" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()

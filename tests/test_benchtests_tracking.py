"""Full-firmware bench tests (`pafp bench tracking`, `pafp bench baud-study`) against the report's claims."""

import json
import math

import pytest

from firmware.config import load_firmware_config
from host_tools.benchtests import baud_study, tracking
from host_tools.cli import main


@pytest.fixture(scope="module")
def tracking_result():
    return tracking.run(seed=0, strides=1)


def _case(result, name):
    return result.parameters["cases"][name]


def test_tuning_improves_tracking(tracking_result):
    # The report shows tracking before and after tuning as plots (Figs 4.8-4.11), with no number: its
    # claim is that the untuned run shows "delays and oscillation" and tuning visibly improves it.
    # Checked on what the report measured (the IMU pitch) and on the truth: the tuned profile (gains +
    # feed-forward) at least halves the truth RMS of the untuned run (no feed-forward, P-only), cuts the
    # IMU RMS by a quarter and the lag, and neither run misses a deadline or latches a fault.
    untuned, tuned = _case(tracking_result, "untuned"), _case(tracking_result, "tuned")
    assert tuned["truth"]["rms_deg"] < 0.5 * untuned["truth"]["rms_deg"]
    assert tuned["imu"]["rms_deg"] < 0.75 * untuned["imu"]["rms_deg"]
    assert tuned["imu"]["lag_ms"] < untuned["imu"]["lag_ms"]
    for c in (untuned, tuned):
        assert c["deadline_misses"] == 0 and c["faults"] == []
    # measured by the IMU, even the tuned run shows degrees: the sensor's own 19.5 ms lag at gait speeds
    assert tuned["imu"]["rms_deg"] > 1.0 and tuned["imu"]["lag_ms"] > 15.0


def test_butterworth_on_imu_cannot_remove_the_imus_lag(tracking_result):
    # The report's Fig 4.11 applies a Butterworth low-pass to the IMU data and calls the result better.
    # Offline (zero phase) it can only take noise out; the IMU's error here is its lag, which stays: the
    # RMS changes by under 5 % and the lag by under 2 ms. In the loop, at 10 Hz the filter's own lag
    # trips the 6 deg sensor-disagreement check (before one stride: no tracking figure at all).
    tuned = _case(tracking_result, "tuned")
    offline = tracking_result.parameters["offline_butterworth"]
    assert offline["rms_deg"] == pytest.approx(tuned["imu"]["rms_deg"], rel=0.05)
    assert abs(offline["lag_ms"] - tuned["imu"]["lag_ms"]) < 2.0
    bw = _case(tracking_result, f"tuned + Butterworth {tracking.BUTTERWORTH_HZ:g} Hz")
    low = _case(tracking_result, f"tuned + Butterworth {tracking.BUTTERWORTH_LOW_HZ:g} Hz")
    assert bw["faults"] == [] and bw["deadline_misses"] == 0
    assert low["faults"] == ["SENSOR_DISAGREEMENT"] and low["truth"]["rms_deg"] is None


def test_tracking_rows_cover_each_case(tracking_result):
    names = [f.name for f in tracking_result.figures]
    for case in tracking.tracking_cases(load_firmware_config()):
        for metric in ("IMU RMS error", "IMU max error", "IMU lag", "RMS error", "max error", "lag"):
            assert f"{case}: {metric}" in names
        assert names.index(f"{case}: IMU RMS error") < names.index(f"{case}: RMS error")  # measured first
    assert f"{tracking.OFFLINE}: IMU RMS error" in names
    lags = [f.emulated_value for f in tracking_result.figures
            if f.name.endswith("lag") and f.emulated_value is not None]
    assert all(-200.0 <= x <= 200.0 for x in lags)  # the lag search spans +-200 ms (negative: the foot leads)
    assert all(f.basis for f in tracking_result.figures)


def test_feedforward_is_its_own_row_and_tuned_rows_hold_on_seeds_not_tuned_on(tracking_result):
    # The profile's gains were tuned on seed 0: the tuned case is also run on ten other seeds (median and
    # spread), and the feed-forward the report never had is separated from the gains in its own case.
    held = tracking_result.parameters["held_out"]
    assert tracking_result.parameters["held_out_seeds"] == list(range(1, 11))
    for name in (tracking.NO_FF, "tuned"):
        for sig in ("imu", "encoder", "truth"):
            st = held[name][sig]
            assert st["n"] == 10 and st["min"] <= st["median"] <= st["max"]
    # the seed the gains were tuned on flatters them: its truth RMS is below the median of the other seeds
    no_ff, tuned = _case(tracking_result, tracking.NO_FF), _case(tracking_result, "tuned")
    assert tuned["truth"]["rms_deg"] < held["tuned"]["truth"]["median"]
    # the feed-forward is a case of its own: same gains, different run
    assert no_ff["truth"]["rms_deg"] != tuned["truth"]["rms_deg"] and no_ff["faults"] == []
    names = [f.name for f in tracking_result.figures]
    for name in (tracking.NO_FF, "tuned"):
        assert f"{name}, seeds not tuned on: encoder RMS error (median)" in names


def test_imu_model_alone_depends_on_the_reading(tracking_result):
    # Report 3.5.4's 0.0195 s read as a first-order lag costs a perfect tracker half as much again as a
    # 51 Hz sample-and-hold (emulated: 1.88 deg against 1.23 deg RMS; issue 24 estimated 2.3 and 1.1).
    model = tracking_result.parameters["imu_model_alone"]
    lag, hold = model["first-order-lag"]["rms_deg"], model["sample-hold"]["rms_deg"]
    assert 1.3 < lag / hold < 3.0
    assert 1.5 < lag < 3.0 and 0.8 < hold < 1.6


def test_tracking_under_the_sample_hold_imu_reading(tracking_result):
    # The same tuned run with the IMU model holding the pitch every 19.5 ms instead of lagging it: the run
    # names its reading, keeps running, and the IMU-measured error drops (the hold's mean delay is half an
    # interval, the lag's a whole time constant), while the foot's true error hardly moves.
    hold = tracking_result.parameters["imu_sample_hold"]
    tuned = _case(tracking_result, "tuned")
    assert hold["readings"]["imu"] == "sample-hold" and hold["faults"] == []
    assert hold["imu"]["rms_deg"] < 0.8 * tuned["imu"]["rms_deg"]
    assert hold["imu"]["lag_ms"] < tuned["imu"]["lag_ms"]
    assert hold["truth"]["rms_deg"] < 2 * tuned["truth"]["rms_deg"] + 0.2


@pytest.mark.parametrize(("baud", "mode", "expected"), [(921600, "full", (1961, 980)),
                                                        (115200, "selective", (245, 235))])
def test_wire_time_bound(baud, mode, expected):
    # 10 bit-times per byte: full round trip 10 + 6 + 78 = 94 bytes over two periods; selective mode is
    # limited by the same full round trip (its 10 + 10 + 23 = 43-byte period allows 268 Hz at 115200)
    assert tuple(round(x) for x in baud_study.analytic_max_hz(baud, mode, full_values_hz=10)) == expected


def test_analytic_bound_rejects_bad_mode():
    with pytest.raises(ValueError, match="mode"):
        baud_study.analytic_max_hz(921600, "half")


def test_baud_study_achievable_rate_matches_wire_time_bound():
    # The report names the UART communication delay as a limitation without a figure. The emulator's
    # achievable control rate (no miss, a reply to every request) must be the fastest candidate within
    # the wire-time bound: the next faster candidate lies above the bound and fails.
    candidates = (1000, 500, 200)
    r = baud_study.run(seed=0, bauds=(115200, 921600), modes=("selective",), candidates=candidates)
    achievable = r.parameters["achievable"]
    for baud in (115200, 921600):
        bound, _ = baud_study.analytic_max_hz(baud, "selective", 10)
        expected = max(c for c in candidates if c <= bound)
        assert achievable[f"{baud} selective"] == expected
    assert r.parameters["recommended"]["baud"] == 921600
    assert r.parameters["recommended"]["control_hz"] == 1000
    rows = {f.name: f for f in r.figures}
    assert rows["921600 selective: feedback rate"].emulated_value > 0.95 * 1000
    assert rows["921600 selective: worst feedback age"].emulated_value <= 2.0 + 1e-6
    # slower link, slower loop, worse tracking
    assert rows["115200 selective: RMS tracking error"].emulated_value > rows[
        "921600 selective: RMS tracking error"].emulated_value
    passed = r.columns["passed"]
    assert passed.sum() == 2 and len(passed) == 4  # 921600: 1 run; 115200: 1000 and 500 fail, 200 passes


def test_full_mode_halves_the_feedback_rate():
    run = baud_study.study_run(load_firmware_config(), 921600, "full", 1000, strides=1, seed=0)
    assert run.passed
    assert run.feedback_rate_hz == pytest.approx(500, rel=0.05)


def test_link_config_keeps_velocity_filter_below_nyquist():
    cfg = baud_study.link_config(load_firmware_config(), 100, "full")
    assert cfg.control_hz == cfg.full_values_hz == 100
    assert cfg.velocity_cutoff_hz < 50.0


def test_pafp_bench_tracking_writes_outputs(tmp_path, capsys):
    assert main(["bench", "tracking", "--quick", "--out", str(tmp_path)]) == 0
    for ext in ("png", "csv", "json", "md"):
        assert (tmp_path / f"tracking.{ext}").stat().st_size > 0
    doc = json.loads((tmp_path / "tracking.json").read_text())
    assert doc["parameters"]["strides"] == 2
    assert all(f["emulated"] is None or math.isfinite(f["emulated"]) for f in doc["figures"])
    assert all(f["basis"] for f in doc["figures"])
    assert "| tracking [level-com] | tuned: IMU RMS error |" in capsys.readouterr().out

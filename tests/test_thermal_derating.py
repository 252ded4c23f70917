"""The firmware's response to the motor's reported winding temperature: derating, OVER_TEMPERATURE, stale readings.

Thresholds are dyadic (exact in binary), so each boundary is tested at its value and at the next float beyond.
"""

from __future__ import annotations

import math

import pytest

from firmware.safety import FaultReason, SafetyInputs, Supervisor, SupervisorState, ThermalGuard
from firmware.safety_limits import ThermalLimits

LIMITS = ThermalLimits(derate_start_c=64.0, derate_end_c=96.0, fault_c=88.0, max_age_s=0.5)
NOW = 2.0


def below(x: float) -> float:
    return math.nextafter(x, -math.inf)


def above(x: float) -> float:
    return math.nextafter(x, math.inf)


def test_derating_is_full_up_to_the_start_and_zero_from_the_end() -> None:
    d = LIMITS.derating
    assert d(below(64.0)) == 1.0 and d(64.0) == 1.0
    assert d(above(64.0)) < 1.0
    assert d(72.0) == 0.75 and d(80.0) == 0.5 and d(88.0) == 0.25  # linear: (96 - T) / 32
    assert 0.0 < d(below(96.0)) < 1e-12
    assert d(96.0) == 0.0 and d(above(96.0)) == 0.0 and d(500.0) == 0.0
    assert d(math.nan) == 1.0 and d(-40.0) == 1.0


def test_the_guard_derates_the_limit_from_a_fresh_reading_and_says_when_it_began() -> None:
    g = ThermalGuard(LIMITS)
    assert g.limit_a(12.0, 64.0, NOW, NOW) == 12.0 and g.derating_since_s is None
    assert g.limit_a(12.0, 80.0, NOW, NOW + 0.25) == 6.0
    assert g.derating_since_s == NOW + 0.25 and g.factor == 0.5
    assert g.limit_a(12.0, 96.0, NOW + 1.0, NOW + 1.0) == 0.0
    assert g.derating_since_s == NOW + 0.25  # the first time, kept
    assert g.limit_a(12.0, 40.0, NOW + 2.0, NOW + 2.0) == 12.0  # cooled: the full limit again


@pytest.mark.parametrize("temp_c, received_s", [
    (150.0, None),                      # never reported (a link whose replies carry none)
    (150.0, below(NOW - 0.5)),          # older than max_age_s
    (math.nan, NOW), (math.inf, NOW),   # not a reading
])
def test_a_stale_or_missing_temperature_never_derates_or_latches(temp_c: float, received_s: float | None) -> None:
    g = ThermalGuard(LIMITS)
    assert math.isnan(g.fresh_c(temp_c, received_s, NOW))
    assert g.limit_a(12.0, temp_c, received_s, NOW) == 12.0 and g.derating_since_s is None
    s = _running()
    assert s.check(_inputs(g.fresh_c(temp_c, received_s, NOW))) is SupervisorState.RUN
    assert s.reason is FaultReason.NONE


def test_a_reading_exactly_max_age_old_is_still_fresh() -> None:
    g = ThermalGuard(LIMITS)
    assert g.fresh_c(80.0, NOW - 0.5, NOW) == 80.0
    assert g.limit_a(12.0, 80.0, NOW - 0.5, NOW) == 6.0


def _inputs(temp_c: float) -> SafetyInputs:
    return SafetyInputs(now_s=NOW, angle_rad=0.0, last_motor_reply_s=NOW, last_command_s=NOW, last_imu_frame_s=NOW,
                        motor_temp_c=temp_c)


def _running() -> Supervisor:
    s = Supervisor(thermal=LIMITS)
    x = _inputs(25.0)
    x.now_s = x.last_motor_reply_s = x.last_command_s = x.last_imu_frame_s = 1.0
    assert s.check(x) is SupervisorState.RUN
    return s


def test_over_temperature_latches_just_above_fault_c_and_not_at_it() -> None:
    s = _running()
    assert s.check(_inputs(88.0)) is SupervisorState.RUN
    assert s.check(_inputs(above(88.0))) is SupervisorState.SAFE
    assert s.reason is FaultReason.OVER_TEMPERATURE and s.tripped_at_s == NOW
    assert "motor temperature 88.0 C > 88.0 C" in s.detail
    # latched: a cool reading does not bring it back; the safe state (graded) damps, released if the drive itself
    # reports a fault
    assert s.check(_inputs(25.0)) is SupervisorState.SAFE
    assert s.safe_command(NOW, loaded=True).behaviour in ("short", "damping")
    assert s.safe_command(NOW, drive_fault=True).behaviour == "release"


def test_over_temperature_latches_before_run_too() -> None:
    s = Supervisor(thermal=LIMITS)
    assert s.check(_inputs(100.0)) is SupervisorState.SAFE and s.reason is FaultReason.OVER_TEMPERATURE


@pytest.mark.parametrize("kw, message", [
    (dict(derate_start_c=39.0), "derate_start_c = 39.0 is not allowed"),
    (dict(fault_c=181.0), "fault_c = 181.0 is not allowed"),
    (dict(derate_start_c=100.0, derate_end_c=100.0), "must be below derate_end_c"),
    (dict(fault_c=70.0), "must be above derate_start_c"),
    (dict(max_age_s=0.0), "max_age_s = 0.0 is not allowed"),
    (dict(max_age_s=5.5), "max_age_s = 5.5 is not allowed"),
])
def test_bad_thermal_limits_name_the_value_and_the_range(kw: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        ThermalLimits(**kw)


def test_the_profile_reads_the_thermal_table(tmp_path) -> None:
    from firmware.config import DEFAULT_PROFILE, load_firmware_config

    assert load_firmware_config().thermal == ThermalLimits()  # the shipped profile states the defaults
    text = DEFAULT_PROFILE.read_text().replace("fault_c = 90.0", "fault_c = 95.0")
    (tmp_path / "fw.toml").write_text(text)
    assert load_firmware_config(tmp_path / "fw.toml").thermal.fault_c == 95.0
    (tmp_path / "bad.toml").write_text(text.replace("fault_c = 95.0", "fault_k = 95.0"))
    with pytest.raises(ValueError, match=r"\[thermal\] has no key 'fault_k'"):
        load_firmware_config(tmp_path / "bad.toml")

"""Every [safety] limit has a range from the hardware: its bound is accepted, the next value beyond is refused."""

import math

import pytest

from firmware.config import FirmwareConfig
from firmware.safety_limits import (
    ANGLE_LIMIT_RAD,
    BRAKE_CURRENT_MAX_A,
    BRAKE_DELAY_MAX_S,
    MISS_STREAK_MAX,
    PEAK_CURRENT_A,
    STARTUP_GRACE_MAX_S,
    TIMEOUT_MAX_S,
    SafetyLimits,
)


def test_the_bounds_are_the_hardware_s():
    assert PEAK_CURRENT_A == 22.7  # report Table B2
    assert BRAKE_CURRENT_MAX_A == 6.5  # maker's rated current (PROTOCOLS.md section C)
    assert BRAKE_DELAY_MAX_S == 1.0  # VESC APPCONF_TIMEOUT_MSEC
    # the physics behind TIMEOUT_MAX_S: a stale peak-current command swings the foot across half a turn sooner
    alpha = 0.078 * PEAK_CURRENT_A * 28.0 * 0.855 / 0.0495
    assert 0.5 * alpha * TIMEOUT_MAX_S ** 2 > math.pi


WIDE = dict(angle_min_rad=-ANGLE_LIMIT_RAD, angle_max_rad=ANGLE_LIMIT_RAD)


@pytest.mark.parametrize(("name", "inside", "beyond", "base"), [
    ("current_limit_a", PEAK_CURRENT_A, math.nextafter(PEAK_CURRENT_A, math.inf), {}),
    ("current_limit_a", math.nextafter(0.0, 1.0), 0.0, {}),
    ("brake_current_a", BRAKE_CURRENT_MAX_A, math.nextafter(BRAKE_CURRENT_MAX_A, math.inf), {}),
    ("brake_current_a", math.nextafter(0.0, 1.0), 0.0, {}),
    ("motor_timeout_s", TIMEOUT_MAX_S, math.nextafter(TIMEOUT_MAX_S, math.inf), {}),
    ("command_timeout_s", TIMEOUT_MAX_S, math.nextafter(TIMEOUT_MAX_S, math.inf), {}),
    ("imu_timeout_s", TIMEOUT_MAX_S, math.nextafter(TIMEOUT_MAX_S, math.inf), {}),
    ("command_timeout_s", math.nextafter(0.0, 1.0), 0.0, {}),
    ("startup_grace_s", STARTUP_GRACE_MAX_S, math.nextafter(STARTUP_GRACE_MAX_S, math.inf), {}),
    ("brake_delay_s", BRAKE_DELAY_MAX_S, math.nextafter(BRAKE_DELAY_MAX_S, math.inf), {}),
    ("brake_delay_s", 0.0, -math.ulp(0.0), {}),
    ("deadline_miss_streak", MISS_STREAK_MAX, MISS_STREAK_MAX + 1, {}),
    ("deadline_miss_streak", 1, 0, {}),
    ("angle_max_rad", ANGLE_LIMIT_RAD, math.nextafter(ANGLE_LIMIT_RAD, math.inf), {}),
    ("angle_min_rad", -ANGLE_LIMIT_RAD, math.nextafter(-ANGLE_LIMIT_RAD, -math.inf), {}),
    ("disagreement_rad", 2 * ANGLE_LIMIT_RAD, math.nextafter(2 * ANGLE_LIMIT_RAD, math.inf), WIDE),
    ("disagreement_rad", math.radians(71.0), math.radians(71.0) + 1e-9, {}),  # the default limits' span
    ("disagreement_rad", math.nextafter(0.0, 1.0), 0.0, {}),
])
def test_a_limit_is_taken_up_to_its_bound_and_refused_beyond(name, inside, beyond, base):
    assert getattr(SafetyLimits(**base, **{name: inside}), name) == inside
    with pytest.raises(ValueError, match=rf"^{name} = {beyond!r} is not allowed: must be .*(\[|\().*(\]|\))"):
        SafetyLimits(**base, **{name: beyond})


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, "1", None, True])
def test_a_limit_that_is_no_number_is_refused(value):
    for name in ("current_limit_a", "brake_current_a", "command_timeout_s", "disagreement_rad", "angle_max_rad"):
        with pytest.raises(ValueError, match=f"^{name} = "):
            SafetyLimits(**{name: value})


def test_the_miss_streak_is_held_to_the_longest_age_limit_at_the_control_rate():
    FirmwareConfig(control_hz=1000, safety=SafetyLimits(deadline_miss_streak=100))
    with pytest.raises(ValueError, match=r"deadline_miss_streak = 101 is not allowed: must be an integer in \[1, 100]"):
        FirmwareConfig(control_hz=1000, safety=SafetyLimits(deadline_miss_streak=101))
    FirmwareConfig(control_hz=200, imu_poll_hz=200, logger_hz=200, watchdog_kick_hz=100,
                   velocity_cutoff_hz=40.0, safety=SafetyLimits(deadline_miss_streak=20))
    with pytest.raises(ValueError, match=r"\[1, 20\]"):
        FirmwareConfig(control_hz=200, imu_poll_hz=200, logger_hz=200, watchdog_kick_hz=100,
                       velocity_cutoff_hz=40.0, safety=SafetyLimits(deadline_miss_streak=21))


def test_the_docs_table_states_the_bounds():
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "firmware.md").read_text(encoding="utf-8")
    for row in (f"| −{math.degrees(ANGLE_LIMIT_RAD):g}…{math.degrees(ANGLE_LIMIT_RAD):g}° |",
                f"| (0, {PEAK_CURRENT_A:g}] A |", f"| (0, {BRAKE_CURRENT_MAX_A:g}] A |",
                f"| (0, {TIMEOUT_MAX_S:g}] s |", f"| (0, {STARTUP_GRACE_MAX_S:g}] s |",
                f"| [0, {BRAKE_DELAY_MAX_S:g}] s |"):
        assert row in text, row

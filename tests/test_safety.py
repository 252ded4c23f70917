"""The safety supervisor: each rule trips, trips latch, the safe command is zero current then brake."""

import math

import pytest

from firmware.safety import FaultReason, SafetyInputs, SafetyLimits, Supervisor, SupervisorState


def running(now=1.0, **kw):
    base = dict(now_s=now, angle_rad=0.0, last_motor_reply_s=now, last_imu_frame_s=now)
    base.update(kw)
    return SafetyInputs(**base)


def started() -> Supervisor:
    s = Supervisor(SafetyLimits(safe_state="brake"))  # the brake's zero-current-then-brake sequence
    assert s.check(running(0.9)) is SupervisorState.RUN
    return s


def test_init_until_both_sensors_have_spoken():
    s = Supervisor()
    assert s.check(SafetyInputs(now_s=0.1, angle_rad=0.0, last_motor_reply_s=0.1)) is SupervisorState.INIT
    assert s.check(running(0.2)) is SupervisorState.RUN


@pytest.mark.parametrize(
    "kw, reason",
    [
        (dict(estop_pressed=True), FaultReason.ESTOP),
        (dict(link_lost=True), FaultReason.LINK_LOST),
        (dict(motor_fault_code=6), FaultReason.MOTOR_FAULT),
        (dict(deadline_miss_streak=3), FaultReason.DEADLINE_MISSES),
        (dict(last_motor_reply_s=1.0 - 0.0201), FaultReason.MOTOR_TIMEOUT),
        (dict(last_imu_frame_s=1.0 - 0.0401), FaultReason.IMU_TIMEOUT),
        (dict(angle_rad=math.radians(40)), FaultReason.ANGLE_LIMIT),
        (dict(current_meas_a=25.0), FaultReason.CURRENT_LIMIT),
        (dict(disagreement_rad=math.radians(10)), FaultReason.SENSOR_DISAGREEMENT),
    ],
)
def test_each_rule_trips_and_latches(kw, reason):
    s = started()
    assert s.check(running(**kw)) is SupervisorState.SAFE
    assert s.reason is reason
    assert s.check(running(2.0)) is SupervisorState.SAFE  # latched, even with healthy inputs
    assert s.reason is reason and not s.healthy


def test_timeouts_just_inside_do_not_trip():
    s = started()
    assert s.check(running(last_motor_reply_s=1.0 - 0.0199, last_imu_frame_s=1.0 - 0.0399)) \
        is SupervisorState.RUN


def test_silent_sensor_trips_after_startup_grace_only():
    s = Supervisor()
    assert s.check(SafetyInputs(now_s=0.4, angle_rad=0.0)) is SupervisorState.INIT
    assert s.check(SafetyInputs(now_s=0.6, angle_rad=0.0, last_imu_frame_s=0.59)) is SupervisorState.SAFE
    assert s.reason is FaultReason.MOTOR_TIMEOUT


def test_safe_command_zero_current_then_brake():
    s = started()
    s.trip(FaultReason.ESTOP, 1.0)
    assert s.safe_command(1.005).brake is False and s.safe_command(1.005).current_a == 0.0
    cmd = s.safe_command(1.0 + s.limits.brake_delay_s)
    assert cmd.brake and cmd.current_a == s.limits.brake_current_a


def test_bad_limits_name_the_value():
    with pytest.raises(ValueError, match="motor_timeout_s"):
        SafetyLimits(motor_timeout_s=0)
    with pytest.raises(ValueError, match="angle limits"):
        SafetyLimits(angle_min_rad=1.0, angle_max_rad=0.0)

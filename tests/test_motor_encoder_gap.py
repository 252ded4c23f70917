"""The encoder plausibility check (firmware.safety.MotorEncoderGap, MOTOR_ENCODER_DISAGREEMENT)."""

from __future__ import annotations

import math

import pytest

from firmware.safety import FaultReason, MotorEncoderGap, SafetyInputs, SafetyLimits, Supervisor, SupervisorState


def test_the_gap_is_zero_before_the_first_reply_and_relative_after():
    gap = MotorEncoderGap(4.0, fresh_s=0.002)
    assert gap.update(0.3, 9.0, None, 0.0) == 0.0
    assert gap.update(0.3, 9.0, 0.010, 0.0105) == 0.0  # both zeroed at the first reply
    assert gap.update(0.4, 9.4, 0.011, 0.0115) == pytest.approx(0.0)  # moved together through the belt
    assert gap.update(0.4, 9.0, 0.012, 0.0125) == pytest.approx(0.1)  # encoder moved, motor did not
    assert gap.update(0.2, 9.8, 0.013, 0.0135) == pytest.approx(0.3)  # encoder back 0.1, motor forward 0.2


def test_stale_feedback_is_not_compared():
    """A reply seen before, or older than fresh_s, keeps the last gap: stale feedback is MOTOR_TIMEOUT's hazard."""
    gap = MotorEncoderGap(4.0, fresh_s=0.002)
    gap.update(0.0, 0.0, 0.010, 0.0105)
    assert gap.update(0.5, 0.0, 0.010, 0.0115) == 0.0  # the same reply again: the foot moved since
    assert gap.update(0.5, 0.0, 0.011, 0.0140) == 0.0  # a reply 3 ms old
    assert gap.update(0.5, 0.0, 0.013, 0.0140) == pytest.approx(0.5)  # a fresh one


def _supervisor_at(gap_rad: float) -> Supervisor:
    sup = Supervisor(SafetyLimits(motor_encoder_gap_rad=math.radians(3.0)))
    x = SafetyInputs(now_s=0.1, angle_rad=0.0, last_motor_reply_s=0.1, last_command_s=0.1, last_imu_frame_s=0.1)
    sup.check(x)
    assert sup.state is SupervisorState.RUN
    x.now_s, x.motor_encoder_gap_rad = 0.101, gap_rad
    x.last_motor_reply_s = x.last_command_s = x.last_imu_frame_s = 0.101
    sup.check(x)
    return sup


def test_the_check_trips_above_its_limit_only():
    assert _supervisor_at(math.radians(2.99)).state is SupervisorState.RUN
    sup = _supervisor_at(math.radians(3.01))
    assert sup.state is SupervisorState.SAFE and sup.reason is FaultReason.MOTOR_ENCODER_DISAGREEMENT
    assert sup.detail == "encoder/motor-position disagreement 3.01 deg > 3.00 deg"


def test_the_limits_refuse_a_bad_gap_or_ratio():
    with pytest.raises(ValueError, match="motor_encoder_gap_rad"):
        SafetyLimits(motor_encoder_gap_rad=0.0)
    with pytest.raises(ValueError, match="belt_ratio"):
        SafetyLimits(belt_ratio=-1.0)

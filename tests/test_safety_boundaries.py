"""Every supervisor rule on each side of its boundary, exactly: the limits and times are dyadic fractions, so
`now - last` is the timeout itself at the boundary (no float rounding), and the next float beyond trips.

Each case checks the reason, so a rule that vanished cannot hide behind another one tripping.
"""

import math

import pytest

from firmware.safety import FaultReason, SafetyInputs, SafetyLimits, Supervisor, SupervisorState

NOW = 2.0
LIMITS = SafetyLimits(angle_min_rad=-0.5, angle_max_rad=0.625, current_limit_a=20.0, motor_timeout_s=2.0 ** -6,
                      command_timeout_s=2.0 ** -5, imu_timeout_s=2.0 ** -4, disagreement_rad=0.125,
                      deadline_miss_streak=3, startup_grace_s=0.5, brake_delay_s=2.0 ** -7, brake_current_a=2.0,
                      safe_state="brake")


def below(x: float) -> float:
    return math.nextafter(x, -math.inf)


def above(x: float) -> float:
    return math.nextafter(x, math.inf)


def healthy(**kw) -> SafetyInputs:
    """Inputs with every source fresh at NOW and every value inside its limit, changed by kw."""
    base = dict(now_s=NOW, angle_rad=0.0, last_motor_reply_s=NOW, last_command_s=NOW, last_imu_frame_s=NOW)
    base.update(kw)
    return SafetyInputs(**base)


def running() -> Supervisor:
    s = Supervisor(LIMITS)
    assert s.check(healthy(now_s=1.0, last_motor_reply_s=1.0, last_command_s=1.0, last_imu_frame_s=1.0)) \
        is SupervisorState.RUN
    return s


def test_the_boundaries_are_exact_in_floating_point():
    for timeout in (LIMITS.motor_timeout_s, LIMITS.command_timeout_s, LIMITS.imu_timeout_s):
        assert NOW - (NOW - timeout) == timeout
        assert NOW - below(NOW - timeout) > timeout
    assert (1.0 + LIMITS.brake_delay_s) - 1.0 == LIMITS.brake_delay_s


# (inputs at the boundary: no trip; inputs just beyond: trip with reason)
AGES = [
    ("last_command_s", LIMITS.command_timeout_s, FaultReason.COMMAND_STALE),
    ("last_motor_reply_s", LIMITS.motor_timeout_s, FaultReason.MOTOR_TIMEOUT),
    ("last_imu_frame_s", LIMITS.imu_timeout_s, FaultReason.IMU_TIMEOUT),
]


@pytest.mark.parametrize(("field", "timeout", "reason"), AGES, ids=[a[2].name for a in AGES])
def test_an_age_equal_to_its_timeout_is_fresh_and_the_next_float_older_is_stale(field, timeout, reason):
    s = running()
    assert s.check(healthy(**{field: NOW - timeout})) is SupervisorState.RUN
    assert s.reason is FaultReason.NONE
    assert s.check(healthy(**{field: below(NOW - timeout)})) is SupervisorState.SAFE
    assert s.reason is reason


def at(t: float, **kw) -> SafetyInputs:
    """Every source last heard at t, changed by kw (None: never heard)."""
    fields = dict(last_motor_reply_s=t, last_command_s=t, last_imu_frame_s=t)
    fields.update(kw)
    return healthy(now_s=t, **fields)


@pytest.mark.parametrize(("field", "timeout", "reason"), AGES, ids=[a[2].name for a in AGES])
def test_an_age_rule_also_holds_before_run(field, timeout, reason):
    s = Supervisor(LIMITS)
    quiet = dict(last_motor_reply_s=None, last_imu_frame_s=None, last_command_s=None)
    assert s.check(at(0.25, **quiet)) is SupervisorState.INIT
    assert s.check(at(0.25, **{**quiet, field: below(0.25 - timeout)})) is SupervisorState.SAFE
    assert s.reason is reason


@pytest.mark.parametrize(("silent", "reason"), [("last_motor_reply_s", FaultReason.MOTOR_TIMEOUT),
                                                ("last_imu_frame_s", FaultReason.IMU_TIMEOUT)])
def test_a_source_never_heard_from_trips_only_after_the_grace(silent, reason):
    grace = LIMITS.startup_grace_s
    s = Supervisor(LIMITS)
    assert s.check(at(grace, **{silent: None})) is SupervisorState.INIT
    assert s.reason is FaultReason.NONE
    assert s.check(at(above(grace), **{silent: None})) is SupervisorState.SAFE
    assert s.reason is reason


def test_no_command_yet_is_not_a_stale_command():
    s = running()
    assert s.check(healthy(now_s=100.0, last_motor_reply_s=100.0, last_imu_frame_s=100.0, last_command_s=None)) \
        is SupervisorState.RUN


@pytest.mark.parametrize(("value", "tripped"), [
    (LIMITS.angle_min_rad, False), (below(LIMITS.angle_min_rad), True),
    (LIMITS.angle_max_rad, False), (above(LIMITS.angle_max_rad), True),
    (0.0, False),
])
def test_the_angle_limits_are_inclusive_on_both_sides(value, tripped):
    s = running()
    assert s.check(healthy(angle_rad=value)) is (SupervisorState.SAFE if tripped else SupervisorState.RUN)
    assert s.reason is (FaultReason.ANGLE_LIMIT if tripped else FaultReason.NONE)


@pytest.mark.parametrize(("current", "tripped"), [
    (20.0, False), (above(20.0), True), (25.0, True),  # driving
    (-20.0, False), (below(-20.0), True), (-25.0, True),  # braking or driving the other way: the same limit
])
def test_the_current_limit_holds_for_either_sign(current, tripped):
    s = running()
    assert s.check(healthy(current_meas_a=current)) is (SupervisorState.SAFE if tripped else SupervisorState.RUN)
    assert s.reason is (FaultReason.CURRENT_LIMIT if tripped else FaultReason.NONE)
    if tripped:
        assert f"current {current:.2f} A beyond 20.0 A" in s.detail


@pytest.mark.parametrize(("disagreement", "tripped"), [(0.125, False), (above(0.125), True)])
def test_the_disagreement_limit(disagreement, tripped):
    s = running()
    assert s.check(healthy(disagreement_rad=disagreement)) is (SupervisorState.SAFE if tripped
                                                               else SupervisorState.RUN)
    assert s.reason is (FaultReason.SENSOR_DISAGREEMENT if tripped else FaultReason.NONE)


@pytest.mark.parametrize("inputs", [dict(angle_rad=3.0), dict(current_meas_a=-100.0), dict(disagreement_rad=1.0)])
def test_the_run_only_rules_wait_for_run(inputs):
    """Before both sensors have spoken the angle, current and disagreement mean nothing yet."""
    s = Supervisor(LIMITS)
    assert s.check(healthy(now_s=0.25, last_motor_reply_s=0.25, last_imu_frame_s=None, **inputs)) \
        is SupervisorState.INIT
    assert s.reason is FaultReason.NONE


@pytest.mark.parametrize(("streak", "tripped"), [(2, False), (3, True), (4, True)])
def test_a_deadline_miss_streak_trips_at_its_limit(streak, tripped):
    s = running()
    assert s.check(healthy(deadline_miss_streak=streak)) is (SupervisorState.SAFE if tripped
                                                             else SupervisorState.RUN)
    assert s.reason is (FaultReason.DEADLINE_MISSES if tripped else FaultReason.NONE)


def test_on_a_host_clock_a_miss_streak_is_one_warning_per_streak():
    s = running()
    s.latch_deadline_misses = False
    for streak in (3, 4, 5, 0, 2, 3):
        assert s.check(healthy(deadline_miss_streak=streak)) is SupervisorState.RUN
    assert s.miss_streak_warnings == 2 and s.reason is FaultReason.NONE


@pytest.mark.parametrize(("inputs", "reason"), [
    (dict(estop_pressed=True), FaultReason.ESTOP),
    (dict(link_lost=True), FaultReason.LINK_LOST),
    (dict(motor_fault_code=1), FaultReason.MOTOR_FAULT),
    (dict(motor_fault_code=255), FaultReason.MOTOR_FAULT),
])
def test_the_flag_rules(inputs, reason):
    s = running()
    assert s.check(healthy(**inputs)) is SupervisorState.SAFE and s.reason is reason


def test_the_first_rule_in_rank_order_names_the_fault():
    ranked = [dict(estop_pressed=True), dict(link_lost=True), dict(motor_fault_code=3), dict(deadline_miss_streak=3),
              dict(last_command_s=0.0), dict(last_motor_reply_s=0.0), dict(last_imu_frame_s=0.0),
              dict(angle_rad=3.0), dict(current_meas_a=30.0), dict(disagreement_rad=1.0)]
    reasons = [FaultReason.ESTOP, FaultReason.LINK_LOST, FaultReason.MOTOR_FAULT, FaultReason.DEADLINE_MISSES,
               FaultReason.COMMAND_STALE, FaultReason.MOTOR_TIMEOUT, FaultReason.IMU_TIMEOUT,
               FaultReason.ANGLE_LIMIT, FaultReason.CURRENT_LIMIT, FaultReason.SENSOR_DISAGREEMENT]
    for k, reason in enumerate(reasons):
        everything_from_k = {key: v for d in ranked[k:] for key, v in d.items()}
        s = running()
        assert s.check(healthy(**everything_from_k)) is SupervisorState.SAFE
        assert s.reason is reason, (k, s.reason)


def test_the_brake_comes_exactly_at_the_brake_delay():
    s = running()
    s.trip(FaultReason.ESTOP, 1.0)
    before = s.safe_command(below(1.0 + LIMITS.brake_delay_s))
    assert before.brake is False and before.current_a == 0.0
    at = s.safe_command(1.0 + LIMITS.brake_delay_s)
    assert at.brake is True and at.current_a == LIMITS.brake_current_a
    assert s.safe_command(1.0).brake is False


def test_a_zero_brake_delay_brakes_at_once():
    s = Supervisor(SafetyLimits(brake_delay_s=0.0, safe_state="brake"))
    s.trip(FaultReason.ESTOP, 1.0)
    assert s.safe_command(1.0).brake is True

"""What the supervisor detects beyond silence (firmware/safety.py): a jammed output (by its current, motion and
reference, and by the ankle's torque balance), a frozen IMU, an IMU silence judged up to the port's last read (a
host's stall of the IMU task is not the IMU's silence)."""

from __future__ import annotations

import logging
import math

import pytest

from firmware.control.pid import parallel_spring_torque_nm
from firmware.drivers.imu import ImuDriver
from firmware.safety import (
    FaultReason,
    FrozenImu,
    JamCheck,
    JamObserver,
    SafetyInputs,
    SafetyLimits,
    Supervisor,
    SupervisorState,
)
from hal.interfaces import Uart
from hal.virtual.faults import make_injector
from hal.virtual.faults.observer import Observer
from host_tools.runner import RunConfig, run_virtual
from protocol.rvc import RvcFrame

LIMITS = SafetyLimits()


def running(**kw: object) -> SafetyInputs:
    base = dict(now_s=1.0, angle_rad=0.0, last_motor_reply_s=1.0, last_command_s=1.0, last_imu_frame_s=1.0)
    base.update(kw)
    return SafetyInputs(**base)  # type: ignore[arg-type]


def started() -> Supervisor:
    s = Supervisor()
    assert s.check(running(now_s=0.5, last_motor_reply_s=0.5, last_command_s=0.5, last_imu_frame_s=0.5)) \
        is SupervisorState.RUN
    return s


def test_jam_needs_all_three_and_restarts_on_motion_or_when_the_push_turns() -> None:
    j = JamCheck(current_share=0.5, still_rad=math.radians(0.5), reference_rad_s=0.1)
    assert j.update(0.0, 5.9, 12.0, 0.0, 1.0) == 0.0  # below half the limit
    assert j.update(0.0, 6.0, 12.0, 0.0, 1.0) == 0.0  # all three: the window opens
    assert j.dorsiflexing  # pushing towards dorsiflexion, where the reference goes
    assert j.update(0.02, 6.0, 12.0, math.radians(0.4), 1.0) == pytest.approx(0.02)  # within 0.5 deg: still
    assert j.update(0.03, 6.0, 12.0, math.radians(0.6), 1.0) == 0.0  # it moved: a new window
    assert j.update(0.05, 6.0, 12.0, math.radians(0.6), 1.0) == pytest.approx(0.02)
    assert j.update(0.06, -6.0, 12.0, math.radians(0.6), 1.0) == 0.0  # the push turned: a new window
    assert not j.dorsiflexing  # against the reference
    assert j.update(0.08, -6.0, 12.0, math.radians(0.6), -1.0) == pytest.approx(0.02)
    assert not j.dorsiflexing  # plantarflexing with the reference
    assert j.update(0.10, 6.0, 12.0, math.radians(0.6), 0.05) == 0.0  # the reference stopped


def test_a_jam_trips_after_its_time_in_swing_and_in_stance_only_when_it_dorsiflexes() -> None:
    s = started()
    assert s.check(running(jam_s=LIMITS.jam_time_s)) is SupervisorState.RUN
    # stance: a plantarflexing push-off the motor is too weak for looks alike
    assert s.check(running(jam_s=1.0, loaded=True)) is SupervisorState.RUN
    assert s.check(running(jam_s=LIMITS.jam_time_s + 1e-3)) is SupervisorState.SAFE
    assert s.reason is FaultReason.MOTOR_JAM and "swing" in s.detail
    s = started()
    assert s.check(running(jam_s=LIMITS.jam_time_s + 1e-3, loaded=True, jam_dorsiflexing=True)) is SupervisorState.SAFE
    assert s.reason is FaultReason.MOTOR_JAM and "dorsiflexing" in s.detail


# a foot model as the adult design's feedforward gives it: J, Kt N eta, backdriven share, m g d, a one-sided spring
FOOT = dict(inertia_kg_m2=0.0887, nm_per_a=2.52, backdriven_share=0.73, gravity_moment_nm=1.73,
            com_angle_rad=math.pi / 2, spring=(400.0, 0.0, False))


RESIDUAL_NM = LIMITS.jam_residual_peak_share * 2.52 * 14.8  # of the peak output torque: 14.8 A at 2.52 N m/A


def observer() -> JamObserver:
    lim = LIMITS
    return JamObserver(**FOOT, time_constant_s=lim.jam_observer_s, residual_nm=RESIDUAL_NM,  # type: ignore
                       share=lim.jam_residual_share, per_n_m=lim.jam_residual_m, slow_rad_s=lim.jam_slow_rad_s)


def _moment(current_a: float, velocity: float, angle: float, ground_nm: float) -> float:
    """The moments on the model's foot (what the observer's model says), for the free foot's integration."""
    motor = FOOT["nm_per_a"] * current_a / (FOOT["backdriven_share"] if current_a * velocity < 0 else 1.0)
    return motor + parallel_spring_torque_nm(400.0, 0.0, False, angle) + ground_nm \
        - FOOT["gravity_moment_nm"] * math.cos(angle)


def test_the_torque_balance_explains_a_free_foot_and_finds_a_jams_reaction() -> None:
    o, dt, w, angle = observer(), 1e-3, 0.0, 0.05
    worst = 0.0
    for k in range(400):  # a free foot under a swinging current and a ground moment: all of it explained
        t = k * dt
        current, ground = 8.0 * math.sin(2 * math.pi * 2.0 * t), 60.0 * math.sin(2 * math.pi * 1.0 * t)
        assert o.update(t, w, angle, current, ground, 600.0) == 0.0
        worst = max(worst, abs(o.residual))
        w += _moment(current, w, angle, ground) / FOOT["inertia_kg_m2"] * dt
        angle += w * dt
    assert worst < 0.5  # the integration's own error; the bound starts at RESIDUAL_NM (5 N m)
    o.reset()
    held = [o.update(1.0 + k * dt, 0.0, -0.1, 10.0, 0.0, 0.0) for k in range(120)]  # the motor pushes, nothing moves
    # the residual follows the jam's reaction (-(motor + weight)) with the observer's time constant (15 ms)
    assert o.residual == pytest.approx(-_moment(10.0, 0.0, -0.1, 0.0), rel=0.01)
    first = next(k for k, h in enumerate(held) if h > 0.0) - 1  # the sample it went beyond its bound
    assert abs(o.residual) > o.bound and 0 < first < 20
    assert held[-1] == pytest.approx((len(held) - 1 - first) * dt)
    # the same residual on a foot faster than jam_slow_rad_s is not judged (a jam holds the foot)
    assert o.update(1.2, 2 * LIMITS.jam_slow_rad_s, -0.1, 10.0, 0.0, 0.0) == 0.0


def test_the_torque_balances_bound_grows_with_the_measured_moments_and_the_axial_force() -> None:
    o = observer()
    o.update(0.0, 0.0, -0.1, 0.0, 0.0, 0.0)
    assert o.bound == pytest.approx(RESIDUAL_NM)
    o.update(0.001, 0.0, -0.1, 10.0, 50.0, 800.0)
    assert o.bound == pytest.approx(RESIDUAL_NM + LIMITS.jam_residual_share * (25.2 + 50.0)
                                    + LIMITS.jam_residual_m * 800.0)


def test_the_torque_balance_trips_in_stance_and_swing_after_its_time() -> None:
    for loaded in (False, True):
        s = started()
        assert s.check(running(jam_torque_s=LIMITS.jam_torque_time_s, loaded=loaded)) is SupervisorState.RUN
        assert s.check(running(jam_torque_s=LIMITS.jam_torque_time_s + 1e-3, loaded=loaded, jam_residual_nm=-20.0,
                               jam_bound_nm=8.0)) is SupervisorState.SAFE
        assert s.reason is FaultReason.MOTOR_JAM and "torque balance: -20.0 N m unexplained > 8.0 N m" in s.detail


def test_frozen_imu_counts_identical_frames_only_while_the_encoder_moves() -> None:
    f = FrozenImu(math.radians(1.0))
    assert f.update(1.00, 1.00, 0.0) == 0.0  # a change: the reference point
    assert f.update(1.00, 1.05, math.radians(0.5)) == 0.0  # identical frames, but the foot barely moved
    assert f.update(1.00, 1.05, math.radians(1.5)) == pytest.approx(0.05)  # it moved: 50 ms of identical frames
    assert f.update(1.06, 1.06, math.radians(3.0)) == 0.0  # the content changed: healthy again


def test_the_imu_driver_marks_content_changes_not_index_changes() -> None:
    class Fake(Uart):  # a Uart subclass: the compiled driver checks its argument's type
        def __init__(self) -> None:
            super().__init__(115200, "fake imu")
            self.data = b""

        def _send(self, data: bytes) -> int:
            return len(data)

        def _receive(self, max_bytes: int) -> bytes:
            n = len(self.data) if max_bytes < 0 else max_bytes
            data, self.data = self.data[:n], self.data[n:]
            return data

        def _rx_count(self) -> int:
            return len(self.data)

        def _tx_space(self) -> int:
            return 64

    uart = Fake()
    imu = ImuDriver(uart)
    frame = RvcFrame(0, 0.1, 0.2, 0.0, 0.0, 0.0, 9.8)
    uart.data = frame.encode()
    assert imu.poll(1.0) == 1 and imu.changed_s == 1.0 and imu.last_poll_s == 1.0
    uart.data = RvcFrame(1, 0.1, 0.2, 0.0, 0.0, 0.0, 9.8).encode()  # next index, same measurement
    assert imu.poll(1.01) == 1 and imu.changed_s == 1.0 and imu.last_frame_s == 1.01
    assert imu.poll(1.02) == 0 and imu.last_poll_s == 1.02 and imu.last_frame_s == 1.01
    uart.data = RvcFrame(2, 0.1, 0.21, 0.0, 0.0, 0.0, 9.8).encode()
    assert imu.poll(1.03) == 1 and imu.changed_s == 1.03


def test_imu_silence_is_judged_up_to_the_ports_last_read_and_never_beyond_twice_the_limit() -> None:
    t = LIMITS.imu_timeout_s
    # the IMU task stalled (a host's stall): last read just after the last frame, now long after: no trip yet
    assert started().check(running(last_imu_frame_s=1.0 - 1.5 * t, last_imu_poll_s=1.0 - 1.4 * t)) \
        is SupervisorState.RUN
    s = started()  # read since, and still nothing: silent
    assert s.check(running(last_imu_frame_s=1.0 - 1.5 * t, last_imu_poll_s=1.0)) is SupervisorState.SAFE
    assert s.reason is FaultReason.IMU_TIMEOUT
    s = started()  # never read again: at twice the limit it trips anyway
    assert s.check(running(last_imu_frame_s=1.0 - 2.01 * t, last_imu_poll_s=1.0 - 2.0 * t)) is SupervisorState.SAFE


def _run(name: str, onset_s: float = 1.6, duration_s: float = 0.2):
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    fault, obs = make_injector(name, onset_s, duration_s, seed=3), Observer()
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, faults=(obs, fault), duration_s=onset_s + duration_s))
    return r.firmware.supervisor, obs


def test_a_frozen_imu_trips_at_the_frame_that_completes_its_time() -> None:
    # identical frames at 100 Hz: the frozen time grows 10 ms a frame; the 4th repeat (40 ms) ends it, whatever its
    # arrival's jitter, where the 3rd (30 ms) does not
    for frozen_s, state in ((0.030, SupervisorState.RUN), (0.0399, SupervisorState.SAFE),
                            (0.040, SupervisorState.SAFE)):
        s = started()
        assert s.check(running(imu_frozen_s=frozen_s)) is state
    assert s.reason is FaultReason.IMU_FROZEN and "bit-identical for 40.0 ms" in s.detail


def test_a_frozen_imu_is_caught_while_the_foot_moves_and_reaches_the_safe_command_within_50_ms() -> None:
    sup, obs = _run("imu_frozen")
    safe_s = obs.safe_on_wire_s(sup.tripped_at_s)
    assert sup.reason is FaultReason.IMU_FROZEN and 1.6 < sup.tripped_at_s < 1.6 + 0.05
    assert safe_s is not None and safe_s - 1.6 <= 0.050


def test_a_silent_imu_reaches_the_safe_command_within_50_ms() -> None:
    sup, obs = _run("imu_silent")
    safe_s = obs.safe_on_wire_s(sup.tripped_at_s)
    assert sup.reason is FaultReason.IMU_TIMEOUT and safe_s is not None and safe_s - 1.6 <= 0.050


@pytest.mark.parametrize("duration_s", [0.05, 0.2])
def test_a_jam_at_push_off_is_caught_by_the_torque_balance(duration_s: float) -> None:
    """Walking at 20 kg, the output jams at push-off (phase 0.5 of the first stride, as the campaign's point): the
    first rule cannot tell it from a push-off the motor is too weak for; the torque balance can, the 50-ms jam too
    (its residual passes the bound as the jam lets go: with a 20 ms observer it never did)."""
    logging.getLogger("firmware.safety").setLevel(logging.ERROR)
    onset_s = 1.063  # the campaign's push-off onset walking 20 kg (gait start + 0.5 stride)
    fault, obs = make_injector("motor_stall", onset_s, duration_s, seed=0), Observer()
    r = run_virtual(RunConfig(strides=1, trace_capacity=0, scenario="walk", body_mass_kg=20.0, faults=(obs, fault),
                              duration_s=onset_s + 0.1))
    sup = r.firmware.supervisor
    assert fault.record.fired
    assert sup.reason is FaultReason.MOTOR_JAM and "torque balance" in sup.detail
    assert onset_s < sup.tripped_at_s < onset_s + 0.08

"""The motor's replies lost, on a scripted clock: the driver and the supervisor as the firmware's tasks run them.

Each 1 ms period the motor task polls what arrived and sends a command with a feedback request; a scripted motor
answers each request at once unless its replies are lost at that time; then the supervisor checks. No wall clock,
no emulator: the outcome depends on the script alone (the end-to-end case is tests/test_fault_url.py).
"""

from __future__ import annotations

from firmware.drivers.motor import FEEDBACK_MASK, MotorDriver
from firmware.safety import FaultReason, SafetyInputs, SafetyLimits, Supervisor, SupervisorState
from hal.interfaces import Uart
from protocol.vesc import Decoder, GetValues, GetValuesSelective, Values, ValuesSelective

PERIOD_S = 0.001
FLOAT_NOISE_S = 1e-9  # times are k * 1 ms in floats, as the firmware's are cycles / f_cpu
LIMITS = SafetyLimits(safe_state="brake")  # motor_timeout_s 20 ms, startup_grace_s 0.5 s; zero current, then brake


class ScriptedMotor(Uart):
    """The AK60-6 on a UART: answers every feedback request it is sent, unless `lost(now)` (the RX wire broken)."""

    def __init__(self, lost) -> None:
        super().__init__(921600, "scripted motor")
        self.lost = lost
        self.now_s = 0.0
        self.rx = b""
        self._requests = Decoder("to-motor")

    def _send(self, data: bytes) -> int:
        for msg in self._requests.feed(data):
            reply = (ValuesSelective(FEEDBACK_MASK, {"avg_iq_a": 0.5, "erpm": 0, "fault": 0, "pid_pos_rad": 0.1})
                     if isinstance(msg, GetValuesSelective) else Values() if isinstance(msg, GetValues) else None)
            if reply is not None and not self.lost(self.now_s):
                self.rx += reply.encode()
        return len(data)

    def _receive(self, max_bytes: int) -> bytes:
        data, self.rx = self.rx, b""
        return data

    def _rx_count(self) -> int:
        return len(self.rx)

    def _tx_space(self) -> int:
        return 4096


def run(lost, until_s: float) -> tuple[Supervisor, MotorDriver, list[SupervisorState]]:
    """The motor and supervisor tasks for until_s of 1 ms periods; the supervisor's state after each period."""
    motor = ScriptedMotor(lost)
    driver = MotorDriver(motor, full_every=100)
    sup = Supervisor(LIMITS)
    states = []
    for k in range(round(until_s / PERIOD_S)):
        now_s = k * PERIOD_S
        motor.now_s = now_s
        driver.poll(now_s)
        safe = sup.state is SupervisorState.SAFE
        driver.send(0.0 if not safe else sup.safe_command(now_s).current_a, now_s,
                    brake=safe and sup.safe_command(now_s).brake)
        sup.check(SafetyInputs(now_s=now_s, angle_rad=0.0, last_motor_reply_s=driver.feedback.received_s,
                               last_command_s=driver.last_command_s, last_imu_frame_s=now_s))
        states.append(sup.state)
    return sup, driver, states


def test_replies_lost_while_running_latch_motor_timeout_within_a_period_of_the_limit():
    sup, driver, _ = run(lambda t: 1.5 <= t < 2.5, 3.0)
    assert sup.reason is FaultReason.MOTOR_TIMEOUT
    last_reply_s = 1.5  # the reply to the request of 1.499 s, read at 1.500 s: the last before the loss
    limit_s = last_reply_s + LIMITS.motor_timeout_s  # an age of exactly 20 ms may compare over it by a float's ulp
    assert limit_s - FLOAT_NOISE_S <= sup.tripped_at_s <= limit_s + PERIOD_S + FLOAT_NOISE_S
    assert "motor feedback age" in sup.detail
    # the replies that came back after the window refreshed the feedback but not the latch
    assert driver.feedback.received_s > 2.5 and sup.state is SupervisorState.SAFE
    # the motor is told zero current, then the brake once brake_delay_s has passed
    assert not sup.safe_command(sup.tripped_at_s).brake
    assert sup.safe_command(sup.tripped_at_s + LIMITS.brake_delay_s).brake


def test_replies_lost_a_period_less_than_the_limit_pass_and_a_period_more_latch():
    """Requests lost from 1.000 s (the last reply read then): with the first answered one at 1.019 s the feedback
    is at most 19 ms old; at 1.021 s it is 20 ms old at 1.020 s (over by a float's ulp, or not) and 21 ms at 1.021 s."""
    gap_s = LIMITS.motor_timeout_s
    ok, _, _ = run(lambda t: 1.0 <= t < 1.0 + gap_s - 1.5 * PERIOD_S, 1.5)
    assert ok.reason is FaultReason.NONE
    tripped, _, _ = run(lambda t: 1.0 <= t < 1.0 + gap_s + 0.5 * PERIOD_S, 1.5)
    assert tripped.reason is FaultReason.MOTOR_TIMEOUT
    assert 1.020 - FLOAT_NOISE_S <= tripped.tripped_at_s <= 1.021 + FLOAT_NOISE_S


def test_replies_lost_from_boot_within_the_grace_are_the_start_up_not_a_fault():
    """The shape of the run that latched nothing (tests/test_fault_url.py, slow start-up): the replies lost over
    the firmware's first 0.4 s. Never heard from, the motor is in INIT (told zero current) until the first reply;
    within startup_grace_s that is no fault. The same loss over the grace latches MOTOR_TIMEOUT."""
    sup, driver, states = run(lambda t: t < 0.4, 1.0)
    assert sup.reason is FaultReason.NONE and sup.state is SupervisorState.RUN
    first_run = states.index(SupervisorState.RUN)
    assert set(states[:first_run]) == {SupervisorState.INIT} and 0.4 <= first_run * PERIOD_S <= 0.402
    never, _, _ = run(lambda t: t < 0.6, 1.0)
    assert never.reason is FaultReason.MOTOR_TIMEOUT
    assert LIMITS.startup_grace_s < never.tripped_at_s <= LIMITS.startup_grace_s + PERIOD_S

"""Tests of the discrete PID (eqs 3.75-3.77), its saturation and anti-windup, the cascade and feed-forward."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware.control.pid import CascadeController, FeedforwardParams, Pid, PidGains, feedforward_current_a

TS = 0.01


def report_pid(errors: list[float], kp: float, ki: float, kd: float, ts: float) -> list[float]:
    """Eqs 3.75-3.77 written as sums over the whole history (zero initial conditions, no saturation)."""
    out = []
    for k in range(len(errors)):
        e = errors[: k + 1]
        e_prev = [0.0] + e[:-1]
        integral = ki * ts / 2.0 * sum(a + b for a, b in zip(e, e_prev, strict=True))
        out.append(kp * e[k] + integral + kd * (e[k] - e_prev[k]) / ts)
    return out


def test_hand_computed_first_steps() -> None:
    pid = Pid(PidGains(kp=0.3, ki=2.0, kd=0.01), ts_s=TS)
    # k0: P 0.03, I 2*0.01/2*0.1 = 0.001, D 0.01*0.1/0.01 = 0.1
    # k1: P 0.06, I 0.001 + 0.01*0.3 = 0.004, D 0.1
    # k2: P -0.015, I 0.004 + 0.01*0.15 = 0.0055, D 0.01*(-0.25)/0.01 = -0.25
    expected = [0.131, 0.164, -0.2595]
    for e, u in zip([0.1, 0.2, -0.05], expected, strict=True):
        assert pid.update(e) == pytest.approx(u, abs=1e-12)
    assert pid.integral == pytest.approx(0.0055, abs=1e-15)


@given(st.lists(st.floats(-0.02, 0.02), min_size=1, max_size=40),
       st.floats(0.0, 5.0), st.floats(0.0, 20.0), st.floats(0.0, 0.005))
def test_matches_report_equations_when_unsaturated(errors: list[float], kp: float, ki: float,
                                                   kd: float) -> None:
    pid = Pid(PidGains(kp=kp, ki=ki, kd=kd), ts_s=TS, output_limit=1e6)
    got = [pid.update(e) for e in errors]
    assert got == pytest.approx(report_pid(errors, kp, ki, kd, TS), abs=1e-12)


def test_output_saturates_to_plus_minus_one() -> None:
    pid = Pid(PidGains(kp=10.0), ts_s=TS)
    assert pid.update(0.5) == 1.0 and pid.saturated
    assert pid.update(-0.5) == -1.0 and pid.saturated
    assert pid.update(0.05) == pytest.approx(0.5) and not pid.saturated


@given(st.lists(st.floats(-100.0, 100.0), min_size=1, max_size=200))
def test_output_and_integral_stay_bounded(errors: list[float]) -> None:
    pid = Pid(PidGains(kp=0.5, ki=50.0, kd=0.01, derivative_tau_s=0.002), ts_s=0.001)
    for e in errors:
        u = pid.update(e)
        assert -1.0 <= u <= 1.0
        assert -1.0 <= pid.integral <= 1.0


def test_anti_windup_recovery_is_immediate() -> None:
    gains = PidGains(kp=1.0, ki=10.0)
    pid = Pid(gains, ts_s=0.001)
    for _ in range(5000):  # 5 s deep in positive saturation
        assert pid.update(5.0) == 1.0
    assert abs(pid.integral) < 1e-12  # conditional integration: nothing accumulated while saturated
    # Error reverses: without anti-windup the integral (10*5*5 = 250) would hold +1 for ~50 s.
    steps = 0
    while pid.update(-0.5) >= 0.0:
        steps += 1
        assert steps < 10
    assert steps <= 1


def test_conditional_integration_keeps_increments_that_unwind() -> None:
    pid = Pid(PidGains(kp=0.0, ki=1.0, kd=1.0), ts_s=TS)
    assert pid.update(-1.0) == -1.0          # D = -100: saturated low; negative increment rejected
    assert pid.integral == 0.0
    assert pid.update(0.5) == 1.0            # D spike saturates high, but e+e_prev < 0 unwinds
    assert pid.integral == pytest.approx(1.0 * TS / 2.0 * (0.5 - 1.0))


def test_derivative_filter_first_order_decay() -> None:
    tau, kd = 0.02, 0.001
    pid = Pid(PidGains(kp=0.0, kd=kd, derivative_tau_s=tau), ts_s=TS)
    a = tau / (tau + TS)
    d0 = (1.0 - a) * kd / TS
    assert pid.update(1.0) == pytest.approx(d0)
    for k in range(1, 6):
        assert pid.update(1.0) == pytest.approx(d0 * a**k)


def test_derivative_filter_reduces_noise() -> None:
    import random

    rng = random.Random(1234)
    noise = [rng.gauss(0.0, 1e-3) for _ in range(2000)]
    raw = Pid(PidGains(kp=0.0, kd=1e-4), ts_s=0.001, output_limit=1e3)
    filt = Pid(PidGains(kp=0.0, kd=1e-4, derivative_tau_s=0.01), ts_s=0.001, output_limit=1e3)
    var_raw = sum(raw.update(e) ** 2 for e in noise)
    var_filt = sum(filt.update(e) ** 2 for e in noise)
    assert var_filt < 0.2 * var_raw


def test_reset_clears_state() -> None:
    pid = Pid(PidGains(kp=0.1, ki=5.0, kd=0.01, derivative_tau_s=0.01), ts_s=TS)
    first = [pid.update(e) for e in (0.1, 0.3, -0.2)]
    pid.reset()
    assert pid.integral == 0.0 and pid.derivative == 0.0 and pid.output == 0.0
    assert [pid.update(e) for e in (0.1, 0.3, -0.2)] == first


@pytest.mark.parametrize(("kwargs", "name"), [
    ({"kp": -1.0}, "kp"), ({"kp": 1.0, "ki": math.nan}, "ki"), ({"kp": 1.0, "kd": math.inf}, "kd"),
    ({"kp": 1.0, "derivative_tau_s": -0.1}, "derivative_tau_s"),
])
def test_gain_validation(kwargs: dict[str, float], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        PidGains(**kwargs)


@pytest.mark.parametrize("ts", [0.0, -0.001, 2.0, math.nan])
def test_ts_validation(ts: float) -> None:
    with pytest.raises(ValueError, match=r"ts_s = .* must be a finite number in \[1e-06, 1\] s"):
        Pid(PidGains(kp=1.0), ts_s=ts)


def simulate_cascade(controller: CascadeController, target_rad: float, seconds: float,
                     disturbance_nm: float = 0.0) -> list[float]:
    """Double integrator J theta'' = Kt N i + disturbance, exact ZOH integration at the control rate."""
    inertia, kt_n = 0.049, 0.078 * 27.6
    dt = controller.ts_s
    theta = omega = 0.0
    trace = []
    for _ in range(round(seconds / dt)):
        i = controller.update(target_rad, 0.0, theta, omega)
        assert abs(i) <= controller.current_limit_a
        assert abs(controller.velocity_command_rad_s) <= controller.velocity_limit_rad_s
        acc = (kt_n * i + disturbance_nm) / inertia
        theta += omega * dt + 0.5 * acc * dt * dt
        omega += acc * dt
        trace.append(theta)
    return trace


def make_cascade() -> CascadeController:
    return CascadeController(PidGains(kp=2.0, ki=0.2, kd=0.05, derivative_tau_s=0.005),
                             PidGains(kp=0.2, ki=1.0), ts_s=0.001, current_limit_a=10.0,
                             velocity_limit_rad_s=8.0)


def test_cascade_step_settles_without_oscillation() -> None:
    target = 0.2
    trace = simulate_cascade(make_cascade(), target, 1.5)
    settle = next(k for k in range(len(trace)) if all(abs(x - target) <= 0.02 * target for x in trace[k:]))
    assert settle * 0.001 < 0.4                      # within 2 % in under 0.4 s
    assert max(trace) < target * 1.01                # overshoot under 1 %
    errors = [target - x for x in trace]
    sign_changes = sum(1 for a, b in zip(errors, errors[1:], strict=False) if a * b < 0.0)
    assert sign_changes <= 1                         # no ringing


def test_cascade_integral_removes_steady_error_under_load() -> None:
    target = 0.2
    trace = simulate_cascade(make_cascade(), target, 6.0, disturbance_nm=-2.0)
    assert abs(trace[-1] - target) < 2e-3
    no_i = CascadeController(PidGains(kp=2.0), PidGains(kp=0.2), 0.001, 10.0, 8.0)
    trace_p = simulate_cascade(no_i, target, 6.0, disturbance_nm=-2.0)
    assert abs(trace_p[-1] - target) > 5e-3


def test_cascade_feedforward_paths_and_bumpless_start() -> None:
    c = make_cascade()
    assert c.update(0.3, 0.0, 0.3, 0.0, feedforward_current_a=1.25) == pytest.approx(1.25)
    c.reset()
    c.update(0.1, 2.5, 0.1, 2.5)
    assert c.velocity_command_rad_s == pytest.approx(2.5)
    assert c.current_command_a == pytest.approx(0.0)
    assert c.update(0.0, 0.0, 0.0, 0.0, feedforward_current_a=50.0) == 10.0   # clamped to the limit


@pytest.mark.parametrize(("arg", "value"), [("current_limit_a", 0.0), ("velocity_limit_rad_s", -1.0)])
def test_cascade_validation(arg: str, value: float) -> None:
    kwargs = {"current_limit_a": 10.0, "velocity_limit_rad_s": 8.0, arg: value}
    with pytest.raises(ValueError, match=arg):
        CascadeController(PidGains(1.0), PidGains(0.1), 0.001, **kwargs)


def test_feedforward_current_formula() -> None:
    p = FeedforwardParams(inertia_kg_m2=0.049, mass_kg=1.176, lever_m=0.150, torque_constant_nm_per_a=0.078,
                          gear_ratio=27.6, efficiency=0.9)
    theta, acc = math.pi / 5, 2.0
    torque = 0.049 * acc + 1.176 * 9.8 * 0.150 * math.sin(theta)
    assert feedforward_current_a(theta, acc, p) == pytest.approx(torque / (0.078 * 27.6 * 0.9), rel=1e-12)
    assert feedforward_current_a(0.0, 0.0, p) == 0.0
    with pytest.raises(ValueError, match="efficiency"):
        FeedforwardParams(0.049, 1.176, 0.15, 0.078, 27.6, efficiency=1.5)

"""Discrete PID of the report (eqs 3.75-3.77), the position -> velocity -> current cascade, and feed-forward.

The per-sample methods are plain scalar Python, written as the C firmware would run them: no numpy, no
allocation beyond floats.  See docs/control.md for the equations, the derivative filter and the
anti-windup scheme (conditional integration plus a clamp of the integral term).
"""

from __future__ import annotations

import logging
import math

from firmware.control.gains import FeedforwardParams, PidGains
from firmware.control.validation import check_range

logger = logging.getLogger(__name__)

#: Allowed range of the sample period, seconds (1 us ... 1 s).
TS_RANGE_S: tuple[float, float] = (1e-6, 1.0)


def _check_ts(ts_s: float) -> float:
    """Return ts_s if it lies in TS_RANGE_S, else ValueError."""
    return check_range("ts_s", ts_s, TS_RANGE_S[0], TS_RANGE_S[1], unit="s")


class Pid:
    """Discrete PID, eqs 3.75-3.77: trapezoidal integral, filtered backward-difference derivative.

    u[k] = Kp e[k] + Ki Ts/2 sum_j (e[j] + e[j-1]) + D[k], with
    D[k] = a D[k-1] + (1 - a) Kd (e[k] - e[k-1]) / Ts and a = tau / (tau + Ts) (tau = 0: no filter).
    The output is saturated to +-output_limit; the integral uses conditional integration
    (an increment that would push a saturated output further is discarded) and the integral term
    itself is clamped to +-output_limit.

    >>> pid = Pid(PidGains(kp=0.5, ki=2.0), ts_s=0.01)
    >>> round(pid.update(0.1), 6)   # 0.5*0.1 + 2*0.01/2*(0.1 + 0)
    0.051
    >>> round(pid.update(0.1), 6)   # 0.05 + 0.001 + 2*0.01/2*(0.1 + 0.1)
    0.053
    """

    __slots__ = (
        "gains", "ts_s", "output_limit", "_kp", "_ki_half_ts", "_kd_over_ts", "_d_alpha", "_d_beta",
        "_integral", "_deriv", "_e_prev", "_output", "_saturated",
    )

    def __init__(self, gains: PidGains, ts_s: float, output_limit: float = 1.0) -> None:
        """Build the controller for gains at sample period ts_s, output saturated to +-output_limit."""
        if not isinstance(gains, PidGains):
            raise ValueError(f"gains = {gains!r} is not allowed: must be a PidGains")
        _check_ts(ts_s)
        check_range("output_limit", output_limit, 0.0, math.inf, lo_open=True, hi_open=True)
        self.gains = gains
        self.ts_s = float(ts_s)
        self.output_limit = float(output_limit)
        self._kp = float(gains.kp)
        self._ki_half_ts = float(gains.ki) * self.ts_s / 2.0
        self._kd_over_ts = float(gains.kd) / self.ts_s
        tau = float(gains.derivative_tau_s)
        self._d_alpha = tau / (tau + self.ts_s)
        self._d_beta = 1.0 - self._d_alpha
        self._integral = 0.0
        self._deriv = 0.0
        self._e_prev = 0.0
        self._output = 0.0
        self._saturated = False

    def reset(self, previous_error: float = 0.0) -> None:
        """Clear integral, derivative filter and output; e[k-1] := previous_error (0 = the report's start)."""
        self._integral = 0.0
        self._deriv = 0.0
        self._e_prev = float(previous_error)
        self._output = 0.0
        self._saturated = False

    def update(self, error: float) -> float:
        """Run one sample with error e[k] = reference - measurement; return u[k] in +-output_limit."""
        e_prev = self._e_prev
        d_int = self._ki_half_ts * (error + e_prev)
        integral = self._integral + d_int
        deriv = self._d_alpha * self._deriv + self._d_beta * self._kd_over_ts * (error - e_prev)
        u = self._kp * error + integral + deriv
        lim = self.output_limit
        if u > lim:
            if d_int > 0.0:
                integral -= d_int
            u = lim
            self._saturated = True
        elif u < -lim:
            if d_int < 0.0:
                integral -= d_int
            u = -lim
            self._saturated = True
        else:
            self._saturated = False
        if integral > lim:
            integral = lim
        elif integral < -lim:
            integral = -lim
        self._integral = integral
        self._deriv = deriv
        self._e_prev = error
        self._output = u
        return u

    @property
    def integral(self) -> float:
        """Integral term Ki Ts/2 sum(e[j] + e[j-1]) as currently held (output units)."""
        return self._integral

    @property
    def derivative(self) -> float:
        """Filtered derivative term D[k] (output units)."""
        return self._deriv

    @property
    def output(self) -> float:
        """Last output u[k]."""
        return self._output

    @property
    def saturated(self) -> bool:
        """True when the last output was clipped to the limit."""
        return self._saturated


class Feedforward:
    """The gravity + inertia feed-forward of one :class:`FeedforwardParams`, its constants taken once.

    current_a(theta, a) = (J_total a + m g d sin(theta)) / (Kt N eta): the motor current for the foot model, driving;
    ``by_direction`` takes a moment against the motion at eta_fwd eta_back of it (``backdriven_share``).
    """

    def __init__(self, params: FeedforwardParams) -> None:
        """Take J, m g d, the output torque per motor amp Kt N eta and the parallel spring from params."""
        self.inertia_kg_m2 = params.inertia_kg_m2
        self.gravity_moment_nm = params.mass_kg * params.gravity_m_s2 * params.lever_m
        self.nm_per_a = params.torque_constant_nm_per_a * params.gear_ratio * params.efficiency
        self.spring_k = float(params.parallel_stiffness_nm_per_rad)
        self.spring_engage_rad = math.radians(params.parallel_engage_deg)
        self.spring_two_sided = bool(params.parallel_two_sided)
        self.backdriven_share = params.backdriven_share

    def by_direction(self, current_a: float, velocity_rad_s: float) -> float:
        """A current worked out with the driving efficiency, for the ankle moving at velocity_rad_s."""
        return backdriven_current_a(current_a, velocity_rad_s, self.backdriven_share)

    def spring_current_a(self, angle_rad: float) -> float:
        """The motor current the parallel spring's moment at this ankle angle stands for (0 without a spring)."""
        if self.spring_k == 0.0:
            return 0.0
        return parallel_spring_torque_nm(self.spring_k, self.spring_engage_rad, self.spring_two_sided,
                                         angle_rad) / self.nm_per_a

    def current_a(self, ref_angle_rad: float, ref_accel_rad_s2: float) -> float:
        """Motor current [A] for the reference angle [rad] and angular acceleration [rad/s^2]."""
        torque_nm = self.inertia_kg_m2 * ref_accel_rad_s2 + self.gravity_moment_nm * math.sin(ref_angle_rad)
        return torque_nm / self.nm_per_a


def backdriven_current_a(current_a: float, velocity_rad_s: float, backdriven_share: float) -> float:
    """The motor current for a moment, from the current the driving efficiency gives (moment / (Kt N eta_fwd)):
    against the ankle's motion the transmission is backdriven and the same moment takes backdriven_share of it
    (FeedforwardParams.backdriven_share; the plant switches its gain on the same sign).

    >>> [backdriven_current_a(2.0, velocity, 0.75) for velocity in (-1.0, 1.0, 0.0)]
    [1.5, 2.0, 2.0]
    """
    if current_a * velocity_rad_s < 0.0:
        return current_a * backdriven_share
    return current_a


def parallel_spring_torque_nm(k: float, engage_rad: float, two_sided: bool, angle_rad: float) -> float:
    """A parallel spring's moment at the ankle: -k (theta - theta_e) beyond theta_e (both sides if two_sided), else 0.

    >>> parallel_spring_torque_nm(100.0, 0.0, False, 0.1), parallel_spring_torque_nm(100.0, 0.0, False, -0.1)
    (-10.0, 0.0)
    >>> parallel_spring_torque_nm(100.0, 0.0, True, -0.1)
    10.0
    """
    d = angle_rad - engage_rad
    if d > 0.0 or (two_sided and d < 0.0):
        return -k * d
    return 0.0


def feedforward_current_a(ref_angle_rad: float, ref_accel_rad_s2: float, params: FeedforwardParams) -> float:
    """Motor current i_ff = (J_total a_ref + m g d sin(theta_ref)) / (Kt N eta) for the foot model.

    >>> p = FeedforwardParams(0.0, 1.0, 0.1, torque_constant_nm_per_a=0.1, gear_ratio=10.0, efficiency=1.0)
    >>> round(feedforward_current_a(math.pi / 2, 0.0, p), 6)   # 1*9.8*0.1 / (0.1*10)
    0.98
    """
    return Feedforward(params).current_a(ref_angle_rad, ref_accel_rad_s2)


class CascadeController:
    """Position PID -> velocity PI -> current command (report section 3.6.4).

    v_cmd = clamp(v_max u_pos + v_ref, +-v_max);  i_cmd = clamp(i_max u_vel + i_ff, +-i_max),
    where u_pos = PID(theta_ref - theta) and u_vel = PI(v_cmd - omega), both saturated to +-1.
    The first update after construction or reset() starts both loops bumplessly (e[k-1] := e[k]).
    """

    __slots__ = (
        "position_pid", "velocity_pid", "ts_s", "current_limit_a", "velocity_limit_rad_s",
        "velocity_command_rad_s", "current_command_a", "_fresh",
    )

    def __init__(self, position_gains: PidGains, velocity_gains: PidGains, ts_s: float,
                 current_limit_a: float, velocity_limit_rad_s: float) -> None:
        """Build both loops at sample period ts_s with the given current and velocity limits."""
        check_range("current_limit_a", current_limit_a, 0.0, math.inf, lo_open=True, hi_open=True, unit="A")
        check_range("velocity_limit_rad_s", velocity_limit_rad_s, 0.0, math.inf, lo_open=True, hi_open=True,
                    unit="rad/s")
        self.position_pid = Pid(position_gains, ts_s)
        self.velocity_pid = Pid(velocity_gains, ts_s)
        self.ts_s = float(ts_s)
        self.current_limit_a = float(current_limit_a)
        self.velocity_limit_rad_s = float(velocity_limit_rad_s)
        self.velocity_command_rad_s = 0.0
        self.current_command_a = 0.0
        self._fresh = True

    def reset(self) -> None:
        """Clear both loops; the next update starts bumplessly."""
        self.position_pid.reset()
        self.velocity_pid.reset()
        self.velocity_command_rad_s = 0.0
        self.current_command_a = 0.0
        self._fresh = True

    def update(self, ref_angle_rad: float, ref_velocity_rad_s: float, angle_rad: float,
               velocity_rad_s: float, feedforward_current_a: float = 0.0) -> float:
        """Run one control sample and return the motor current command in A (within +-current_limit_a)."""
        e_pos = ref_angle_rad - angle_rad
        pos = self.position_pid
        vel = self.velocity_pid
        if self._fresh:
            pos.reset(e_pos)
        vmax = self.velocity_limit_rad_s
        v_cmd = vmax * pos.update(e_pos) + ref_velocity_rad_s
        if v_cmd > vmax:
            v_cmd = vmax
        elif v_cmd < -vmax:
            v_cmd = -vmax
        e_vel = v_cmd - velocity_rad_s
        if self._fresh:
            vel.reset(e_vel)
            self._fresh = False
        imax = self.current_limit_a
        i_cmd = imax * vel.update(e_vel) + feedforward_current_a
        if i_cmd > imax:
            i_cmd = imax
        elif i_cmd < -imax:
            i_cmd = -imax
        self.velocity_command_rad_s = v_cmd
        self.current_command_a = i_cmd
        return i_cmd

"""The lazily integrated plant: AK60-6 motor and driver, 6:1 gearbox, belt, foot, and a bench fixture."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Final

from mypy_extensions import mypyc_attr

from hal.virtual.plant.fixtures import Fixture, Load, TorqueProfile, check_load, suspended
from hal.virtual.plant.gap import Gap
from hal.virtual.plant.imperfections import install as install_imperfections
from hal.virtual.plant.integrator import (
    Coefficients,
    Drive,
    accel,
    hermite,
    integrate,
    lag_factors,
    lag_target,
    parallel_spring,
)
from hal.virtual.plant.params import PlantParams, load_plant_params
from hal.virtual.plant.readings import check_reading
from hal.virtual.plant.state import PlantState, State, StepAhead

logger = logging.getLogger(__name__)

#: Largest integration step allowed (10 kHz).
MAX_STEP_S: Final = 1e-4
#: Input events closer than this to the committed time or a grid point are taken as happening there.
EVENT_SNAP_S: Final = 1e-10
_UNPOWERED_V_OVER_R: Final = 1e300  # no back-EMF clamp with the bridge open (current is forced to zero)


@mypyc_attr(allow_interpreted_subclasses=True)  # test doubles override the queries
class Plant:
    """Motor + transmission + foot on a fixture, integrated lazily at fixed steps up to each query time.

    Times never go back: every query and input takes a time >= the latest time seen so far.

    >>> from hal.virtual.plant import spring_bench
    >>> plant = Plant(fixture=spring_bench(0.68))
    >>> plant.set_current_command(2.0, t_s=0.0)
    >>> round(plant.current_q_a(0.00114), 4)  # 63.2 % of the step after one driver time constant
    1.2642
    """

    def __init__(self, params: PlantParams | None = None, fixture: Fixture | None = None, *,
                 initial_angle_rad: float = 0.0, initial_velocity_rad_s: float = 0.0,
                 start_time_s: float = 0.0, step_s: float = MAX_STEP_S,
                 motor_angle_offset_rad: float = 0.0, backlash_rad: float = 0.0,
                 driver: str = "current-lag", initial_current_a: float = 0.0, located_switching: bool = False) -> None:
        """Build the plant at rest-state values given; the fixture defaults to SUSPENDED.

        backlash_rad is the gearbox's free play at its (6:1) output; 0 = none (see set_current_command).
        driver is the driver reading (hal.virtual.plant.readings): "current-lag" (set_current_command: the q
        current follows the command with current_time_constant_s) or "voltage-amplifier" (set_voltage_command:
        the PID's +-1 as +-V_bus, the current towards (V - K_e N w)/R with one lag of the amplifier's time
        constant plus the winding's L/R, the two in series taken as one of the same mean delay).
        initial_current_a is the q current at the start (a simulation started mid-run, e.g. by `pafp fit`).
        located_switching places the friction's switchings inside a step (`integrator.integrate_located`: `pafp
        fit`'s model, whose cost must be continuous in the parameters); off, every run's, they act on the step grid.
        """
        self.params = params if params is not None else load_plant_params()
        self.fixture = fixture if fixture is not None else suspended()
        p = self.params
        if not (math.isfinite(step_s) and 0.0 < step_s <= MAX_STEP_S):
            raise ValueError(f"step_s = {step_s!r} outside the allowed range (0, {MAX_STEP_S}] (>= 10 kHz)")
        if not (math.isfinite(initial_angle_rad) and p.stop_min_rad <= initial_angle_rad <= p.stop_max_rad):
            raise ValueError(f"initial_angle_rad = {initial_angle_rad!r} outside the range of motion "
                             f"[{p.stop_min_rad}, {p.stop_max_rad}]")
        finite_args = {"initial_velocity_rad_s": initial_velocity_rad_s, "start_time_s": start_time_s,
                       "motor_angle_offset_rad": motor_angle_offset_rad, "backlash_rad": backlash_rad,
                       "initial_current_a": initial_current_a}
        for name, value in finite_args.items():
            _check_finite(name, value)
        if backlash_rad < 0.0:
            raise ValueError(f"backlash_rad = {backlash_rad!r} outside the allowed range [0, inf)")
        self.driver = check_reading("driver", driver)
        self._emf = 1.0 if driver == "voltage-amplifier" else 0.0
        tau = p.current_time_constant_s
        if self._emf:
            tau += p.phase_inductance_h / p.phase_resistance_ohm
        self.step_s = step_s
        self.motor_angle_offset_rad = motor_angle_offset_rad
        self._ratio = p.total_ratio  # read per query: kept here, not looked up on the interpreted params
        # backlash: half the free play at the rotor, and the rotor's place and motion in it (see _cross_gap)
        self._gap = Gap(0.5 * backlash_rad * p.gearbox_ratio, start_time_s,
                        p.kt_nm_per_a / p.rotor_inertia_kg_m2, self._ratio)
        self._peak_a = p.peak_current_a
        fx = self.fixture
        load_lever = p.load_lever_m
        self.output_inertia_kg_m2 = p.output_inertia_kg_m2 + fx.load_mass_kg * load_lever**2
        self._gravity_moment_nm = p.gravity_m_s2 * (
            p.foot_mass_kg * p.foot_com_distance_m + fx.load_mass_kg * load_lever)
        self._spring_k = p.spring_stiffness_nm_per_rad if fx.has_spring else 0.0
        self._spring_offset = (p.spring_offset_rad if fx.spring_offset_rad is None else fx.spring_offset_rad)
        inv_j = 1.0 / self.output_inertia_kg_m2
        self._c = Coefficients(
            inv_j=inv_j, kto=p.output_torque_per_amp_nm * inv_j, kbo=p.backdriven_torque_per_amp_nm * inv_j,
            ks=-self._spring_k * inv_j,
            c0=-self._spring_k * self._spring_offset * inv_j, kd=p.foot_damping_nm_s_per_rad * inv_j,
            mg=self._gravity_moment_nm * inv_j, psi0=p.com_angle_at_zero_rad,
            lo=p.stop_min_rad, hi=p.stop_max_rad,
            kst=p.stop_stiffness_nm_per_rad * inv_j, cst=p.stop_damping_nm_s_per_rad * inv_j,
            tc=p.coulomb_friction_nm * inv_j, tsx=p.static_friction_nm * inv_j, tau=tau,
            ker=p.ke_v_s_per_rad * p.total_ratio / p.phase_resistance_ohm,
            bscale=p.total_ratio / p.brake_speed_scale_rad_s, ipk=p.peak_current_a,
            kp=p.parallel_stiffness_nm_per_rad * inv_j, pe=p.parallel_engage_rad, p2=p.parallel_two_sided)
        install_imperfections(self._c, p)  # the opt-in ones the fit lacks (Stribeck, ripple, belt); none by default
        self._c.located = located_switching
        self._v_over_r = p.supply_voltage_v / p.phase_resistance_ohm
        self._grid_lag = lag_factors(step_s, self._c.tau)  # current-lag factors of one grid step
        # committed state at time self._t = self._t0 + self._k * step_s; the grid restarts at each input
        self._t0 = start_time_s
        self._k = 0
        self._t = start_time_s
        self._latest = start_time_s
        w0 = initial_velocity_rad_s
        self._x: State = (initial_angle_rad, w0, initial_current_a, (w0 > 0) - (w0 < 0), 0.0, 0.0)
        self._powered = fx.powered
        self._command_a = 0.0
        self._brake_a = 0.0
        self._drive = self._make_drive()
        # the state of the latest query and its time (NaN: none; NaN equals no time)
        self._cache_t = math.nan
        self._cache_x: State = self._x
        self._ahead: StepAhead | None = None  # None when stale
        lever = p.toe_lever_m if fx.toe_lever_m is None else fx.toe_lever_m
        self._set_load(fx.torque_nm if fx.toe_force_n is None else _scaled_load(fx.toe_force_n, lever))

    # ----------------------------------------------------------------- inputs
    def set_current_command(self, current_a: float, t_s: float) -> None:
        """From t_s on, command this q-axis current (clamped to the peak current); ignored when unpowered."""
        _check_finite("current_a", current_a)
        if self._emf:
            raise ValueError("set_current_command: this plant's driver is the voltage amplifier "
                             "(driver='voltage-amplifier'); use set_voltage_command")
        self._commit_event(t_s)
        peak = self._peak_a
        self._command_a = min(peak, max(-peak, current_a))
        self._brake_a = 0.0
        if not self._powered:
            logger.debug("current command %.3f A at %.6f s ignored: driver unpowered", current_a, t_s)
            self._command_a = 0.0
        if self._gap.half > 0.0:
            self._cross_gap(t_s)
        self._drive = self._make_drive()

    def set_voltage_command(self, duty: float, t_s: float) -> None:
        """From t_s on, the PID output duty in [-1, 1] (clamped) as duty x V_bus on the winding; voltage driver only.

        Zero duty shorts the winding through the amplifier (the back-EMF brakes the motor); unpowered, ignored.
        """
        _check_finite("duty", duty)
        if not self._emf:
            raise ValueError("set_voltage_command needs driver='voltage-amplifier' (this plant's driver is "
                             f"{self.driver!r})")
        self._commit_event(t_s)
        u = min(1.0, max(-1.0, duty))
        self._command_a = u * self._v_over_r if self._powered else 0.0
        self._brake_a = 0.0
        self._drive = self._make_drive()

    def set_brake_current(self, current_a: float, t_s: float) -> None:
        """From t_s on, brake: a current of this magnitude opposes rotation (regenerative brake)."""
        _check_finite("current_a", current_a)
        self._commit_event(t_s)
        self._brake_a = min(self._peak_a, abs(current_a)) if self._powered else 0.0
        self._command_a = 0.0
        self._drive = self._make_drive()

    def set_powered(self, on: bool, t_s: float) -> None:
        """Power the driver on or off at t_s; off opens the bridge: current 0 at once, commands ignored."""
        self._commit_event(t_s)
        self._powered = bool(on)
        self._command_a = 0.0
        self._brake_a = 0.0
        if not self._powered:
            x = self._x
            self._x = (x[0], x[1], 0.0, x[3], x[4], x[5])
        self._drive = self._make_drive()

    def set_supply_voltage(self, voltage_v: float, t_s: float) -> None:
        """From t_s on, the driver's bus is at voltage_v (a battery sagging): the back-EMF limit follows it.

        In the voltage-amplifier reading the duty held is kept: its current scales with the bus.
        """
        _check_finite("voltage_v", voltage_v)
        if voltage_v <= 0.0:
            raise ValueError(f"supply voltage {voltage_v!r} V out of range: > 0")
        self._commit_event(t_s)
        v_over_r = voltage_v / self.params.phase_resistance_ohm
        if self._emf:
            self._command_a *= v_over_r / self._v_over_r
        self._v_over_r = v_over_r
        self._drive = self._make_drive()

    def set_external_torque(self, load: Load, t_s: float) -> None:
        """From t_s on, replace the external ankle torque: None, a constant, a TorqueProfile or f(t)."""
        self._commit_event(t_s)
        self._set_load(load)

    def _cross_gap(self, t_s: float) -> None:
        """Backlash: while the rotor is inside the gearbox's free play, no torque reaches the output.

        The rotor's place and motion in the gap are `Gap`'s (hal/virtual/plant/gap.py); a command of the other
        sign than the side in contact frees the rotor, and its torque reaches the output only once the rotor has
        crossed. Called after the plant is committed to t_s; sets the command the output sees (0 while free).
        """
        cmd = self._command_a
        gap = self._gap
        if gap.command(t_s, (cmd > 0.0) - (cmd < 0.0)):
            x = self._x
            gap.free_under(cmd, accel(self._c, x[0], x[1], x[2], self._ext_value(t_s), x[3], x[4], x[5]))
            self._command_a = 0.0

    @property
    def gap_crossings(self) -> int:
        """Reversals whose command freed the rotor in the backlash."""
        return self._gap.crossings

    # ---------------------------------------------------------------- queries
    def advance_to(self, t_s: float) -> None:
        """Commit whole steps up to the last grid point <= t_s (the state at t_s itself is not committed)."""
        self._check_time(t_s)
        self._commit_grid(t_s)

    def state_at(self, t_s: float) -> PlantState:
        """All observables at time t_s (>= every time seen so far)."""
        th, w, i, s, d, dd = self._state_tuple(t_s)
        p = self.params
        ext = self._ext_value(t_s)
        a = accel(self._c, th, w, i, ext, s, d, dd)
        n = self._ratio
        lo, hi = p.stop_min_rad, p.stop_max_rad
        phi, dw = self._gap.motion(t_s)
        return PlantState(
            t_s=t_s, output_angle_rad=th, output_velocity_rad_s=w, output_accel_rad_s2=a,
            motor_angle_rad=n * (th + d) + self.motor_angle_offset_rad + phi, motor_velocity_rad_s=n * (w + dd) + dw,
            current_q_a=i,
            current_command_a=self._command_a, motor_torque_nm=p.kt_nm_per_a * i,
            output_torque_nm=p.output_torque_nm(i, s), external_torque_nm=ext,
            energy_j=self._energy(th, w, d, dd), powered=self._powered, stuck=s == 0 and a == 0.0,
            in_contact=not lo <= th <= hi)

    def output_angle_rad(self, t_s: float) -> float:
        """Ankle angle at t_s, dorsiflexion positive [rad]."""
        return self._state_tuple(t_s)[0]

    def output_velocity_rad_s(self, t_s: float) -> float:
        """Ankle angular velocity at t_s [rad/s]."""
        return self._state_tuple(t_s)[1]

    def output_accel_rad_s2(self, t_s: float) -> float:
        """Ankle angular acceleration at t_s [rad/s^2]."""
        th, w, i, s, d, dd = self._state_tuple(t_s)
        return accel(self._c, th, w, i, self._ext_value(t_s), s, d, dd)

    def motor_angle_rad(self, t_s: float) -> float:
        """Rotor mechanical angle at t_s: N * (ankle angle + belt stretch) + offset + the rotor's place in the backlash
        [rad]."""
        x = self._state_tuple(t_s)
        return self._ratio * (x[0] + x[4]) + self.motor_angle_offset_rad + self._gap.motion(t_s)[0]

    def motor_velocity_rad_s(self, t_s: float) -> float:
        """Rotor mechanical speed at t_s: N * (ankle speed + stretch rate) + the rotor's speed through the backlash
        [rad/s]."""
        x = self._state_tuple(t_s)
        return self._ratio * (x[1] + x[5]) + self._gap.motion(t_s)[1]

    def motor_sample(self, t_s: float) -> tuple[float, float, float]:
        """(q current [A], rotor speed [rad/s], rotor angle [rad]) at t_s from one state evaluation.

        The rotor's own encoder sits before the gearbox: its angle moves through the backlash at each reversal
        while the output does not (`Gap.motion`); it leads the ankle by the belt's stretch (0 with a rigid belt)."""
        th, w, i, _, d, dd = self._state_tuple(t_s)
        n = self._ratio
        phi, dw = self._gap.motion(t_s)
        return i, n * (w + dd) + dw, n * (th + d) + self.motor_angle_offset_rad + phi

    def current_q_a(self, t_s: float) -> float:
        """q-axis current at t_s [A]."""
        return self._state_tuple(t_s)[2]

    def energy_j(self, t_s: float) -> float:
        """Mechanical energy at t_s: kinetic + gravity + spring + stop-contact potential [J]."""
        x = self._state_tuple(t_s)
        return self._energy(x[0], x[1], x[4], x[5])

    @property
    def latest_time_s(self) -> float:
        """The latest time seen by a query or input; earlier times are refused."""
        return self._latest

    @property
    def powered(self) -> bool:
        """Whether the motor driver is powered."""
        return self._powered

    # -------------------------------------------------------------- internals
    def _make_drive(self) -> Drive:
        """Driver inputs for the integrator from the current mode."""
        if not self._powered:  # the bridge open: no current, whatever the driver
            return Drive(self._command_a, self._brake_a, _UNPOWERED_V_OVER_R)
        return Drive(self._command_a, self._brake_a, self._v_over_r, self._emf)

    def _set_load(self, load: Load) -> None:
        """Install an external torque load (profile segments, a function, or a constant)."""
        check_load("external torque load", load)
        self._cache_t = math.nan
        self._ahead = None
        self._fn: Callable[[float], float] | None = None
        self._profile: TorqueProfile | None = None
        self._ea, self._eb, self._t_break = 0.0, 0.0, math.inf
        if load is None:
            return
        if isinstance(load, TorqueProfile):
            self._profile = load
            self._ea, self._eb, self._t_break = load.segment(self._t)
        elif callable(load):
            self._fn = load
        else:
            self._ea = float(load)

    def _ext_value(self, t_s: float) -> float:
        """External torque at t_s [N m]."""
        if self._fn is not None:
            return float(self._fn(t_s))
        return self._ea + self._eb * t_s

    def _energy(self, th: float, w: float, d: float, dd: float) -> float:
        """Kinetic + potential energy for angle, velocity and the belt's stretch and rate."""
        p = self.params
        e = 0.5 * self.output_inertia_kg_m2 * w * w
        e -= self._gravity_moment_nm * math.cos(th + p.com_angle_at_zero_rad)
        e += 0.5 * self._spring_k * (th + self._spring_offset) ** 2
        c = self._c
        if c.kp != 0.0:  # the parallel spring: parallel_spring gives k d / J where engaged
            e += 0.5 * self.output_inertia_kg_m2 * parallel_spring(c.kp, c.pe, c.p2, th) * (th - c.pe)
        over = 0.0
        if th > p.stop_max_rad:
            over = th - p.stop_max_rad
        elif th < p.stop_min_rad:
            over = th - p.stop_min_rad
        if c.imp_energy is not None:
            e += c.imp_energy(w, d, dd)
        return e + 0.5 * p.stop_stiffness_nm_per_rad * over * over

    def _check_time(self, t_s: float) -> None:
        """Refuse non-finite times and times before the latest one seen."""
        if self._latest <= t_s < math.inf:  # false for NaN too
            self._latest = t_s
            return
        if not math.isfinite(t_s):
            raise ValueError(f"time t_s = {t_s!r} must be finite")
        raise ValueError(f"time t_s = {t_s!r} is in the past: the plant has already been queried or "
                             f"driven at {self._latest!r} s; times must be >= {self._latest!r}")

    def _state_tuple(self, t_s: float) -> State:
        """State at t_s: commit whole steps, then interpolate inside the next one (nothing committed).

        Inside a grid step the state comes from the step integrated ahead (cubic Hermite, exact current
        lag); where the friction mode is stuck or changes within the step, or a profile breakpoint comes
        before its end, it is one partial RK4 step from a copy instead.
        """
        if t_s == self._cache_t:
            return self._cache_x
        self._check_time(t_s)
        self._commit_grid(t_s)
        h = t_s - self._t
        x = self._x
        if h > 0.0:
            dt = self.step_s
            ahead = self._ahead
            if ahead is None or not ahead.starts(self._t0, self._k):
                ahead = self._step_ahead(dt)
            if ahead is not None and x[3] and ahead.x1[3] == x[3]:
                x = hermite(x, ahead.x1, ahead.a0, ahead.a1, dt, h, ahead.target_a, self._c.tau)
            else:
                x = self._partial_step(h)
        self._cache_t = t_s
        self._cache_x = x
        return x

    def _step_ahead(self, dt: float) -> StepAhead | None:
        """Integrate the next grid step from the committed state (kept for queries and the next commit).

        None when a load-profile breakpoint falls inside the step (the committed path stops there).
        """
        t = self._t
        if self._t_break < t + dt:
            return None
        c, x0 = self._c, self._x
        x1 = integrate(c, self._drive, x0, self._t0, self._k, 1, dt, self._ea, self._eb, self._fn,
                       self._grid_lag)
        t1 = self._t0 + (self._k + 1) * dt
        a0 = accel(c, x0[0], x0[1], x0[2], self._ext_value(t), x0[3], x0[4], x0[5])
        a1 = accel(c, x1[0], x1[1], x1[2], self._ext_value(t1), x1[3], x1[4], x1[5])
        self._ahead = ahead = StepAhead(self._t0, self._k, x1, a0, a1, lag_target(c, self._drive, x0[1]))
        return ahead

    def _commit_event(self, t_s: float) -> None:
        """Commit the state exactly to t_s (snapped to a grid point within EVENT_SNAP_S) before an input."""
        self._check_time(t_s)
        self._commit_grid(t_s + EVENT_SNAP_S)
        if t_s - self._t > EVENT_SNAP_S:
            self._commit_partial(t_s)
        self._cache_t = math.nan
        self._ahead = None  # the input changes the step ahead

    def _partial_step(self, h: float) -> State:
        """The state h (< one grid step) after the committed one: one RK4 step from a copy."""
        return integrate(self._c, self._drive, self._x, self._t, 0, 1, h, self._ea, self._eb, self._fn,
                         lag_factors(h, self._c.tau))

    def _commit_partial(self, t_end: float) -> None:
        """Commit one short step to t_end (< one step away) and restart the step grid there."""
        self._x = self._partial_step(t_end - self._t)
        self._t0 = self._t = t_end
        self._k = 0

    def _commit_grid(self, t_s: float) -> None:
        """Commit whole steps of the grid t0 + k*dt up to t_s, and profile breakpoints <= t_s."""
        dt = self.step_s
        while True:
            t0, k, tb = self._t0, self._k, self._t_break
            if t_s < t0 + (k + 1) * dt and t_s < tb:
                return
            limit = t_s if t_s < tb else tb
            n = int((limit - t0) / dt) - k
            while n > 0 and t0 + (k + n) * dt > limit:
                n -= 1
            while t0 + (k + n + 1) * dt <= limit:
                n += 1
            if n > 0:
                ahead = self._ahead
                if ahead is not None and ahead.starts(t0, k):  # first step done already
                    self._x = ahead.x1
                    k += 1
                    n -= 1
                if n > 0:
                    self._x = integrate(self._c, self._drive, self._x, t0, k, n, dt, self._ea, self._eb,
                                        self._fn, self._grid_lag)
                self._k = k + n
                self._t = t0 + self._k * dt
            if tb > t_s:
                return
            # a breakpoint of the load profile: commit exactly to it, restart the grid, next segment
            self._ahead = None
            if tb > self._t:
                self._commit_partial(tb)
            else:
                self._t0, self._k = self._t, 0
            assert self._profile is not None
            self._ea, self._eb, self._t_break = self._profile.segment(self._t)


def _check_finite(name: str, value: float) -> None:
    """ValueError naming the value unless it is finite."""
    if not -math.inf < value < math.inf:  # false for NaN too (compiled: no call into the math module)
        raise ValueError(f"{name} = {value!r} must be finite")


def _scaled_load(load: Load, factor: float) -> Load:
    """A toe-force load turned into an ankle-torque load by the lever arm."""
    if load is None:
        return None
    if isinstance(load, TorqueProfile):
        return load.scaled(factor)
    if callable(load):
        fn = load
        return lambda t_s: factor * fn(t_s)
    return factor * float(load)

"""What the AK60-6 driver measures between two looks at the plant: averages, counters, supply, temperatures.

The driver model samples the plant at each of its events (a request or command arriving, an inner-loop
tick, a streaming tick, the timeout). Between two samples the q-axis current follows the plant's
first-order lag towards the target held over the interval, ``i(s) = g + (i0 - g) e^(-s/tau)``, so its
integral and the integral of its square are computed exactly; products with the speed use the
trapezoidal rule. Electrical model: the report's DC equivalent, ``v_q = R i + Ke w_m``, input power
``k (R + R_fet) i^2 + Kt w_m i`` drawn from a supply of ``V_s`` behind ``R_src``, with k = 0.75 the loss of an
amplitude-invariant q current per ohm of a line-to-line resistance (``hal.virtual.plant.thermal``
COPPER_LOSS_FACTOR: three phases of RMS i/sqrt(2) through R/2 each; R_fet, two switches in series, likewise, as
each phase's current passes one switch of its leg at a time). Temperatures: one first-order node each for the
winding (``k R i^2``) and the MOSFETs (``k R_fet i^2``), exact for the interval's mean power. ``attach_thermal``
and ``attach_battery`` replace the winding node by the two-node model of ``hal.virtual.plant.thermal`` (whose
copper loss, with R at the winding's temperature, is then the input power's too) and the fixed supply by a
``hal.virtual.plant.battery`` pack (bus voltage sagging with its state of charge, regeneration into it); without
them nothing changes.
Averages are read and reset like VESC's ``mc_interface_read_reset_avg_*``: time
averages over the span since the previous read (VESC averages its 20-30 kHz samples; same thing).
"""

from __future__ import annotations

import math
from typing import Final

from hal.virtual.devices.ak60_config import Ak60Config
from hal.virtual.plant import PlantParams
from hal.virtual.plant.battery import Battery
from hal.virtual.plant.thermal import COPPER_LOSS_FACTOR, WindingThermal

__all__ = ["Ak60Meter", "tach_steps"]

_TACH_PER_E_REV: Final = 6  # tachometer steps per electrical revolution (VESC mcpwm_foc.c, 60 deg resolution)
THERMAL_STEP_S: Final = 0.01
"""The attached two-node model is stepped with the interval's mean square current once this much time has gathered
(100 Hz: 1/1700 of the AK60-6's 17 s winding time constant; the firmware reads the temperature at 10 Hz), not at
every sample, which costs a fifth of a run's time."""
_QUANTITIES = {"current": 1, "iq": 1, "input_current": 2, "vq": 3}
"""Averaged quantity -> its integral: 1 q current, 2 input current, 3 v_q."""


def tach_steps(motor_angle_rad: float, pole_pairs: int) -> int:
    """Tachometer steps of a rotor angle: 6 per electrical revolution, floor (so 0 rad is step 0).

    >>> tach_steps(2 * math.pi, 14), tach_steps(-1e-9, 14)
    (84, -1)
    """
    return math.floor(motor_angle_rad * pole_pairs * _TACH_PER_E_REV / math.tau)


class Ak60Meter:
    """Running integrals of the driver's electrical quantities between samples of the plant."""

    def __init__(self, cfg: Ak60Config, params: PlantParams, t_s: float, motor_angle_rad: float,
                 current_a: float = 0.0, motor_velocity_rad_s: float = 0.0) -> None:
        """Start at time t_s with the plant's state then; temperatures at ambient, counters at zero."""
        self.r_ohm = params.phase_resistance_ohm
        self.r_fet_ohm = cfg.fet_resistance_ohm
        self._k_copper = COPPER_LOSS_FACTOR * self.r_ohm
        """Copper loss per A^2 of q current (k R_ll; the attached winding's at its temperature)."""
        self._k_fet = COPPER_LOSS_FACTOR * self.r_fet_ohm
        self.ke = params.ke_v_s_per_rad
        # the power the rotor converts is its torque times its speed, Kt i w: energy is conserved whatever the
        # maker's Ke (the voltage constant, kept for the back-EMF in vq); Ke (from Kv, or Table B2's) is below Kt for
        # four of the five catalogue motors and about equal for the AK80-9 (the makers' Kv and Kt follow different
        # conventions), so Ke i w would draw less from the supply than the rotor delivers
        self.kt = params.kt_nm_per_a
        self.tau_s = params.current_time_constant_s
        self.pole_pairs = params.pole_pairs
        self.max_duty = cfg.max_duty
        self.r_src_ohm = cfg.source_resistance_ohm
        self.v_supply_v = params.supply_voltage_v
        self.ambient_c = cfg.ambient_c
        self._rth_w = cfg.winding_thermal_resistance_k_per_w
        self._rth_f = cfg.fet_thermal_resistance_k_per_w
        self._tau_w, self._tau_f = cfg.thermal_time_constants_s
        self.t_s = t_s
        self.current_a = current_a
        self.motor_velocity_rad_s = motor_velocity_rad_s
        self.target_a = 0.0
        """Current target held from the last sample on (set by the driver after each event)."""
        self.temp_motor_c = cfg.ambient_c
        self.temp_fet_c = cfg.ambient_c
        self.v_in_v = self.v_supply_v
        self.input_current_a = 0.0
        self.amp_seconds = 0.0
        self.amp_seconds_charged = 0.0
        self.watt_seconds = 0.0
        self.watt_seconds_charged = 0.0
        self._tach0 = tach_steps(motor_angle_rad, self.pole_pairs)
        self._tach_last = self._tach0
        self.tachometer = 0
        self.tachometer_abs = 0
        # cumulative integrals since start of time, q current, input current and v_q; averages are read
        # against the totals remembered at each quantity's previous read (each resets on its own, as
        # VESC's read-and-reset functions do)
        self._time_total = 0.0
        self._current_total = 0.0
        self._input_current_total = 0.0
        self._vq_total = 0.0
        self._marks = {quantity: _Mark(index) for quantity, index in _QUANTITIES.items()}
        self._winding: WindingThermal | None = None
        self._battery: Battery | None = None
        self._heat_s = 0.0  # time and integral of i^2 gathered for the next step of the attached winding model
        self._heat_a2s = 0.0
        self.v_in_min_v = self.v_in_v
        """The lowest input voltage since the last ``reset_v_in_min`` (every sample, for the per-stride sag)."""

    def attach_thermal(self, winding: WindingThermal) -> None:
        """From now on the reported motor temperature is this two-node model's winding temperature."""
        self._winding = winding
        self.temp_motor_c = winding.winding_c
        self._k_copper = winding.copper_loss_w(1.0)

    def attach_battery(self, battery: Battery) -> None:
        """From now on the input power is drawn from (and regenerated into) this pack, not a fixed supply."""
        self._battery = battery
        self.v_in_v = self.v_in_min_v = battery.bus_v

    @property
    def winding(self) -> WindingThermal | None:
        """The attached two-node winding model (None: the single-node estimate)."""
        return self._winding

    @property
    def battery(self) -> Battery | None:
        """The attached pack (None: the fixed supply)."""
        return self._battery

    def reset_v_in_min(self) -> float:
        """The lowest input voltage since the previous reset; from now on the present one."""
        lowest = self.v_in_min_v
        self.v_in_min_v = self.v_in_v
        return lowest

    def sample(self, t_s: float, current_a: float, motor_velocity_rad_s: float, motor_angle_rad: float) -> None:
        """Take the plant's values at t_s (>= the previous sample) and integrate the interval since then."""
        dt = t_s - self.t_s
        i1, w1 = current_a, motor_velocity_rad_s
        if dt > 0.0:
            i0, w0, g = self.current_a, self.motor_velocity_rad_s, self.target_a
            d = i0 - g
            tau = self.tau_s
            e = math.exp(-dt / tau)
            int_i = g * dt + d * tau * (1.0 - e)
            int_i2 = g * g * dt + 2.0 * g * d * tau * (1.0 - e) + d * d * 0.5 * tau * (1.0 - e * e)
            int_wi = 0.5 * dt * (w0 * i0 + w1 * i1)
            int_w = 0.5 * dt * (w0 + w1)
            mean_i2 = int_i2 / dt
            power_w = ((self._k_copper + self._k_fet) * int_i2 + self.kt * int_wi) / dt
            battery = self._battery
            if battery is None:
                i_in = self._input_current(power_w)
                v_in = self.v_supply_v - self.r_src_ohm * i_in
            else:
                v_in = battery.step_power(dt, power_w)
                i_in = battery.current_a
            self.input_current_a, self.v_in_v = i_in, v_in
            if v_in < self.v_in_min_v:
                self.v_in_min_v = v_in
            self._time_total += dt
            self._current_total += int_i
            self._input_current_total += i_in * dt
            self._vq_total += self.r_ohm * int_i + self.ke * int_w
            if i_in >= 0.0:
                self.amp_seconds += i_in * dt
                self.watt_seconds += v_in * i_in * dt
            else:
                self.amp_seconds_charged -= i_in * dt
                self.watt_seconds_charged -= v_in * i_in * dt
            winding = self._winding
            if winding is None:
                ss_w = self.ambient_c + self._k_copper * mean_i2 * self._rth_w
                self.temp_motor_c = ss_w + (self.temp_motor_c - ss_w) * math.exp(-dt / self._tau_w)
            else:
                self._heat_s += dt
                self._heat_a2s += int_i2
                if self._heat_s >= THERMAL_STEP_S:
                    winding.step(self._heat_s, math.sqrt(self._heat_a2s / self._heat_s))
                    self._heat_s = self._heat_a2s = 0.0
                    self.temp_motor_c = winding.winding_c
                    self._k_copper = winding.copper_loss_w(1.0)
            ss_f = self.ambient_c + self._k_fet * mean_i2 * self._rth_f
            self.temp_fet_c = ss_f + (self.temp_fet_c - ss_f) * math.exp(-dt / self._tau_f)
        self.t_s = max(self.t_s, t_s)
        self.current_a, self.motor_velocity_rad_s = i1, w1
        steps = tach_steps(motor_angle_rad, self.pole_pairs)
        self.tachometer_abs += abs(steps - self._tach_last)
        self._tach_last = steps
        self.tachometer = steps - self._tach0

    def _input_current(self, power_w: float) -> float:
        """Input current drawing power_w from V_s behind R_src: R i^2 - V i + P = 0, smaller root."""
        v, r = self.v_supply_v, self.r_src_ohm
        if r == 0.0:
            return power_w / v
        disc = v * v - 4.0 * r * power_w
        if disc < 0.0:  # more than the supply can deliver: the maximum-power point
            return v / (2.0 * r)
        return (v - math.sqrt(disc)) / (2.0 * r)

    @property
    def vq_v(self) -> float:
        """q-axis voltage now (DC equivalent): R i + Ke w_m."""
        return self.r_ohm * self.current_a + self.ke * self.motor_velocity_rad_s

    @property
    def duty(self) -> float:
        """Duty cycle now: v_q / v_in, limited to +-max_duty."""
        d = self.vq_v / self.v_in_v if self.v_in_v > 0.0 else 0.0
        return max(-self.max_duty, min(self.max_duty, d))

    def read_reset(self, quantity: str) -> float:
        """Time average of quantity ('current', 'input_current', 'iq', 'vq') since its last read; reset it.

        'current' and 'iq' are the same signal (i_d = 0) but, as in VESC, each has its own reset. With no
        time elapsed since the previous read the present value is returned.
        """
        mark = self._marks.get(quantity)
        if mark is None:
            raise ValueError(f"quantity {quantity!r} unknown: one of {sorted(_QUANTITIES)}")
        index = mark.index
        total = self._current_total if index == 1 else self._input_current_total if index == 2 else self._vq_total
        span0, sum0 = mark.time_total, mark.total
        mark.time_total, mark.total = self._time_total, total
        span = self._time_total - span0
        if span > 0.0:
            return (total - sum0) / span
        return self.current_a if index == 1 else self.input_current_a if index == 2 else self.vq_v


class _Mark:
    """The totals at the previous read of one averaged quantity (0 before its first read)."""

    def __init__(self, index: int) -> None:
        """Mark the quantity whose integral is number index (see ``_QUANTITIES``) at zero."""
        self.index = index
        self.time_total = 0.0
        self.total = 0.0

"""Belt compliance, an opt-in imperfection (hal/virtual/plant/imperfections.py): the timing belt as a spring with a
little damping between the motor side (rotor, gearbox, motor pulley) and the ankle side (ankle pulley, foot, load).

The rigid plant's one inertia at the ankle splits in two, both in ankle units (angles at the ankle pulley):
J_ms = J_m N^2 + J_out b^2 on the motor side and J_as = J_total - J_ms on the ankle side. The state adds the belt's
stretch d = theta_m - theta (the motor side's lead over the ankle) and its rate; the rotor's angle is
N (theta + d), so the drive's encoder and the ankle's disagree by N d under load.

    J_ms (w + dd)' = T_motor(i, s) - T_friction(s, w + dd) + ripple(theta + d) - T_b
    J_as w'        = T_b + (the rigid plant's ankle torques: load, gravity, springs, foot damping, stops)
    T_b            = k d + c dd

The actuator's friction (static, Coulomb, Stribeck) and the torque ripple act on the motor side, where they are; the
report's lumped viscous loss (foot damping) stays at the ankle. The friction mode s is the motor side's: stuck, the
motor side holds its angle and the ankle swings on the belt.

Stiffness at the ankle (PlantParams.belt_stiffness_nm_per_rad): each free span of length
L = sqrt(C^2 - (R - r)^2) is a spring EA / L along the belt; a rotation dtheta of the ankle pulley stretches one
span and relaxes the other by r_ankle dtheta. Both spans carry the installation tension, which a timing belt is
given so that the slack span never goes slack under the working load (the makers' installation procedures: SDP/SI
handbook, Technical Section; PowerGrip design manuals): the tight span's tension rises and the slack span's falls,
both by (EA / L) r dtheta, so k = 2 (EA / L) r_ankle^2. Past the torque at which the slack span unloads completely
(2 x the installation tension x r_ankle) only one span works and k halves: not modelled (the installation tension of
the shipped bench is not known), so above it the model is stiffer than the belt. The belt's length wrapped on the
pulleys and the teeth's shear compliance add compliance too: not modelled (again stiffer than the belt).

EA per mm of width (``belt_stiffness_n_per_mm``, N per unit strain per mm) [I]: 2.0 kN/mm for a neoprene belt with
glass-fibre cords, the bench imperfection's 20 kN for a 10 mm belt (profiles/bench_imperfections.toml
[belt_compliance], range 0.8-6 kN/mm). A lower bound with a source: FarmBot's incoming test of its 6 mm GT2 belt
(neoprene, fibreglass cords; genesis.farm.bot/v1.6/bom/drivetrain/belt "Component tests") accepts at most 1 % stretch
of 1000 mm under a hung 10 kg, i.e. EA >= 98.1 N / 0.01 = 9.8 kN for 6 mm, 1.6 kN/mm. No maker's figure was
reachable here (SDP/SI and Gates publish rated tensions, transmission.py, not stiffness in what could be read).
Damping ratio of the belt mode (``belt_damping_ratio``) [I]: 0.05 (range 0.02-0.1), a rubber belt's hysteresis:
c = 2 zeta sqrt(k J_red), J_red = J_ms J_as / J_total, the free-free mode's reduced inertia.

Step size: the mode's angular frequency sqrt(k / J_red) is about 300 rad/s on the AK60-6 bench (49 Hz), so the
plant's 0.1 ms RK4 step sees omega h = 0.03, which RK4 resolves far inside its stability bound (2.8); a stiffer belt
is sub-stepped so that omega h stays at most `MAX_OMEGA_H` (only with the belt on).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from hal.virtual.plant.integrator import Coefficients, Drive, lag_factors, lag_target, nominal_accel
from hal.virtual.plant.params import PlantParams
from hal.virtual.plant.state import State

__all__ = ["MAX_OMEGA_H", "BeltDynamics", "belt_figures", "motor_side_inertia_kg_m2"]

MAX_OMEGA_H = 0.25
"""Largest omega h of the belt mode per RK4 step (RK4's amplitude error per step is about (omega h)^6 / 144)."""


def motor_side_inertia_kg_m2(p: PlantParams) -> float:
    """The inertia on the motor side of the belt, at the ankle: J_m N^2 + J_out b^2."""
    return p.rotor_inertia_kg_m2 * p.total_ratio ** 2 + p.actuator_output_inertia_kg_m2 * p.belt_ratio ** 2


def belt_figures(p: PlantParams) -> dict[str, float]:
    """The belt's figures on the plant without bench load: free span [m], k at the ankle [N m/rad], the two sides'
    inertias [kg m^2], the free-free mode and the motor side's on the belt with the ankle held [Hz]."""
    k, j_ms = p.belt_stiffness_nm_per_rad, motor_side_inertia_kg_m2(p)
    j_as = p.output_inertia_kg_m2 - j_ms
    return {"span_m": p.belt_span_m, "k_nm_per_rad": k, "j_ms": j_ms, "j_as": j_as,
            "free_hz": math.sqrt(k * (1.0 / j_ms + 1.0 / j_as)) / (2.0 * math.pi),
            "held_hz": math.sqrt(k / j_ms) / (2.0 * math.pi)}


class BeltDynamics:
    """The two-mass plant's accelerations and RK4 steps (plain Python; constants divided by inertias like `c`'s)."""

    def __init__(self, c: Coefficients, p: PlantParams) -> None:
        """The constants from the rigid plant's coefficients (this fixture's inertia and loads) and the parameters."""
        self.c = c
        j_total = 1.0 / c.inv_j
        j_ms = motor_side_inertia_kg_m2(p)
        if not 0.0 < j_ms < j_total:
            raise ValueError(f"belt compliance needs a motor side inertia J_m N^2 + J_out b^2 = {j_ms!r} kg m^2 in "
                             f"the allowed range (0, {j_total!r}) (the total at the ankle)")
        self.j_ms = j_ms
        self.k_nm = p.belt_stiffness_nm_per_rad
        j_red = j_ms * (j_total - j_ms) / j_total
        self.omega_n = math.sqrt(self.k_nm / j_red)  # the free-free belt mode [rad/s]
        self.rm = j_total / j_ms  # torque / J_total -> motor-side acceleration
        self.ra = j_total / (j_total - j_ms)  # torque / J_total -> ankle acceleration
        self.kb = self.k_nm * c.inv_j
        self.cb = 2.0 * p.belt_damping_ratio * math.sqrt(self.k_nm * j_red) * c.inv_j
        self.stribeck = p.stribeck_peak_nm * c.inv_j
        self.inv_ws2 = 1.0 / p.stribeck_speed_rad_s ** 2
        self.ripple = p.ripple_amplitude_nm * c.inv_j
        self.ripple_k = p.ripple_periods_per_rev * p.total_ratio
        self.zero_speed = c.tc + self.stribeck
        self.breakaway = max(c.tsx, self.zero_speed)
        self._lags: dict[float, tuple[float, float]] = {}

    def energy(self, w: float, d: float, dd: float) -> float:
        """The energy beyond the rigid plant's 0.5 J_total w^2: the motor side's own motion and the belt's spring."""
        return self.j_ms * (w * dd + 0.5 * dd * dd) + 0.5 * self.k_nm * d * d

    def _ankle(self, th: float, w: float, ext: float) -> float:
        """The ankle side's torques but the belt's, / J_total: load (ext, N m), springs, gravity, foot damping, stops
        (the rigid model's sliding acceleration without current and friction)."""
        return nominal_accel(self.c, th, w, 0.0, ext, 1) + self.c.tc

    def _drive(self, th: float, i: float, s: int, d: float) -> float:
        """The motor side's torque but friction and belt, / J_total: the drive's (gain by power direction), ripple."""
        c = self.c
        kt = c.kbo if i * s < 0.0 else c.kto
        return kt * i + self.ripple * math.sin(self.ripple_k * (th + d))

    def _sliding(self, th: float, w: float, d: float, dd: float, i: float, x: float, s: int) -> tuple[float, float]:
        """(ankle acceleration, stretch acceleration) while the motor side slides in direction s; x the load."""
        b = self.kb * d + self.cb * dd
        aa = self.ra * (self._ankle(th, w, x) + b)
        wm = w + dd
        friction = self.c.tc + self.stribeck * math.exp(-wm * wm * self.inv_ws2)
        am = self.rm * (self._drive(th, i, s, d) - b - s * friction)
        return aa, am - aa

    def _held(self, th: float, w: float, thm: float, x: float) -> float:
        """The ankle's acceleration with the motor side held at thm (stuck)."""
        return self.ra * (self._ankle(th, w, x) + self.kb * (thm - th) - self.cb * w)

    def _static(self, th: float, i: float, d: float, dd: float) -> float:
        """The motor side's torque at rest without friction, / J_total: decides sticking and breakaway."""
        return self._drive(th, i, 0, d) - self.kb * d - self.cb * dd

    def accel(self, th: float, w: float, i: float, ext: float, s: int, d: float = 0.0, dd: float = 0.0) -> float:
        """The ankle's acceleration (it does not depend on the motor side's friction mode)."""
        return self.ra * (self._ankle(th, w, ext) + self.kb * d + self.cb * dd)

    def integrate(self, dv: Drive, state: State, t_base: float, k_first: int, n: int, h: float, ea: float, eb: float,
                  fn: Callable[[float], float] | None, exps: tuple[float, float]) -> State:
        """`integrator.integrate`'s n steps of size h (step j from t_base + (k_first + j) h) on the two-mass model,
        each in m RK4 sub-steps so that omega_n h / m <= MAX_OMEGA_H (m = 1 on the shipped belts)."""
        m = max(1, math.ceil(self.omega_n * h / MAX_OMEGA_H))
        hs = h / m
        if m > 1:
            exps = self._lags.get(hs) or self._lags.setdefault(hs, lag_factors(hs, self.c.tau))
        x = state
        for kk in range(k_first, k_first + n):
            for j in range(m):
                x = self._step(dv, x, t_base + kk * h + j * hs, hs, ea, eb, fn, exps)
        return x

    def _step(self, dv: Drive, state: State, t: float, h: float, ea: float, eb: float,
              fn: Callable[[float], float] | None, exps: tuple[float, float]) -> State:
        """One RK4 step from t: the exact current lag, the motor side's stick, breakaway and reversal rules."""
        th, w, i, s, d, dd = state
        hh = 0.5 * h
        x1, x2, x4 = ((ea + eb * t, ea + eb * (t + hh), ea + eb * (t + h)) if fn is None
                      else (fn(t), fn(t + hh), fn(t + h)))
        eh, e1 = exps
        tg = lag_target(self.c, dv, w + dd)  # back-EMF and brake from the rotor's speed
        i_m = tg + (i - tg) * eh
        i_e = tg + (i - tg) * e1
        if s == 0:
            f = self._static(th, i, d, dd)
            if -self.breakaway <= f <= self.breakaway:  # stuck: the motor side holds, the ankle swings on the belt
                thm = th + d
                a1 = self._held(th, w, thm, x1)
                th2, w2 = th + hh * w, w + hh * a1
                a2 = self._held(th2, w2, thm, x2)
                th3, w3 = th + hh * w2, w + hh * a2
                a3 = self._held(th3, w3, thm, x2)
                th4, w4 = th + h * w3, w + h * a3
                a4 = self._held(th4, w4, thm, x4)
                th += h / 6.0 * (w + 2.0 * (w2 + w3) + w4)
                w += h / 6.0 * (a1 + 2.0 * (a2 + a3) + a4)
                return th, w, i_e, 0, thm - th, -w
            s = 1 if f > 0.0 else -1
        a1, b1 = self._sliding(th, w, d, dd, i, x1, s)
        th2, w2, d2, dd2 = th + hh * w, w + hh * a1, d + hh * dd, dd + hh * b1
        a2, b2 = self._sliding(th2, w2, d2, dd2, i_m, x2, s)
        th3, w3, d3, dd3 = th + hh * w2, w + hh * a2, d + hh * dd2, dd + hh * b2
        a3, b3 = self._sliding(th3, w3, d3, dd3, i_m, x2, s)
        th4, w4, d4, dd4 = th + h * w3, w + h * a3, d + h * dd3, dd + h * b3
        a4, b4 = self._sliding(th4, w4, d4, dd4, i_e, x4, s)
        h6 = h / 6.0
        th += h6 * (w + 2.0 * (w2 + w3) + w4)
        w += h6 * (a1 + 2.0 * (a2 + a3) + a4)
        d += h6 * (dd + 2.0 * (dd2 + dd3) + dd4)
        dd += h6 * (b1 + 2.0 * (b2 + b3) + b4)
        wm = w + dd
        if wm * s <= 0.0:  # the motor side's speed reached or crossed zero inside the step: stick or reverse
            f = self._static(th, i_e, d, -w)
            if -self.breakaway <= f <= self.breakaway:
                return th, w, i_e, 0, d, -w
            s = (1 if wm > 0.0 else -1) if wm != 0.0 else (1 if f > 0.0 else -1)
        return th, w, i_e, s, d, dd

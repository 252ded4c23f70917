"""Opt-in imperfections of the plant that `pafp fit`'s model lacks: a plant to test the fit against effects it does
not model (issue 34), or a bench that has them.

Each is a set of plant-profile keys, off by default (the default profile's plant is unchanged, its runs byte for
byte). Torques are at the ankle, speeds the ankle's, like the profile's other friction figures.

- **stribeck** ([friction] ``stribeck_peak_nm``, ``stribeck_speed_rad_s``): sliding friction
  T_c + peak exp(-(w / w_s)^2) instead of T_c from the first instant of motion, the Gaussian Stribeck curve
  (B. Armstrong-Helouvry, P. Dupont, C. Canudas de Wit, "A survey of models, analysis tools and compensation
  methods for the control of machines with friction", Automatica 30(7) (1994) 1083-1138: its Stribeck curve with
  the exponent 2).
  Breakaway takes max(T_s, T_c + peak): the stuck foot needs the friction's zero-speed value to start. The
  issue's review figures, 0.83 N m at 0.02 rad/s, are this profile's static minus Coulomb friction
  (0.93 - 0.10 N m): the nominal plant's drop from breakaway to sliding friction spread over 0.02 rad/s.
- **load_friction** ([transmission] ``efficiency_backdriven``): friction that grows with the torque transmitted,
  i.e. the transmission's efficiency by power direction, the design work's model (PlantParams.
  backdriven_torque_per_amp_nm; the planetary's figure from the forward one in transmission.py). It lives in the
  nominal integrator already (its backdriven gain); without the key the plant takes one gain both ways.
- **torque_ripple** ([ripple] ``ripple_amplitude_nm``, ``ripple_periods_per_rev``): a torque
  A sin(n phi_motor) at the ankle, phi_motor = N theta the rotor's angle: cogging and the motor's torque ripple,
  n periods per rotor revolution (the least common multiple of slots and poles for cogging: Z. Q. Zhu, D. Howe,
  "Influence of design parameters on cogging torque in permanent magnet machines", IEEE Trans. Energy Conversion
  15(4) (2000) 407-412). No cogging figure is published for the AK60-6 (profiles/bench_imperfections.toml
  [torque_ripple]): 0.05 N m and 140 per revolution are the issue's review figures [I]. The ripple is integrated
  with the plant's step: at n N w / (2 pi) above about a tenth of the step rate (1 kHz at 10 kHz: w = 1.6 rad/s
  for 140 per revolution through 28:1) it is resolved coarsely.
- **belt_compliance** ([belt] ``belt_stiffness_n_per_mm``, ``belt_width_mm``, ``belt_center_distance_m``,
  ``belt_damping_ratio``): the belt as a spring between the motor side and the ankle, a second mass
  (hal/virtual/plant/belt.py has the model, its stiffness at the ankle and its sources). With it on, the Stribeck
  friction and the ripple act on the motor side in the same two-mass model.

`MISSPECIFIED` holds the issue's four recordings' settings, `OTHER_PLANTS` more (the belt); `profile_text` writes a
plant profile with one of them for `pafp run --plant FILE`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from hal.virtual.plant.integrator import Coefficients, Drive, lag_target, nominal_accel, static_accel
from hal.virtual.plant.params import PlantParams
from hal.virtual.plant.state import State

__all__ = ["MISSPECIFIED", "NAMES", "OTHER_PLANTS", "active", "install", "profile_text"]

NAMES = ("stribeck", "load_friction", "torque_ripple", "belt_compliance")
"""The imperfections a plant profile can switch on."""

MISSPECIFIED: dict[str, dict[str, dict[str, float]]] = {
    # the review figures: the static minus Coulomb friction spread over 0.02 rad/s
    "stribeck": {"friction": {"stribeck_peak_nm": 0.83, "stribeck_speed_rad_s": 0.02}},
    # 5 % of the transmitted torque lost in either power direction (driving: the ankle gets 0.95 of the rotor's
    # torque times N; backdriven: holding the rotor takes 1 / 0.95 of it)
    "load_friction": {"transmission": {"gearbox_efficiency": 1.0, "belt_efficiency": 0.95,
                                       "efficiency_backdriven": 0.95}},
    "cogging": {"ripple": {"ripple_amplitude_nm": 0.05, "ripple_periods_per_rev": 140.0}},
    # all three at half their size [I: the review did not give its milder figures]
    "all_milder": {"friction": {"stribeck_peak_nm": 0.415, "stribeck_speed_rad_s": 0.02},
                   "transmission": {"gearbox_efficiency": 1.0, "belt_efficiency": 0.975,
                                    "efficiency_backdriven": 0.975},
                   "ripple": {"ripple_amplitude_nm": 0.025, "ripple_periods_per_rev": 140.0}},
}
"""The issue's four misspecified plants (issue 34, "unmodelled effects"), as plant-profile keys over the base."""

OTHER_PLANTS: dict[str, dict[str, dict[str, float]]] = {
    # the shipped AK60-6 bench's belt (belt.py): 2 kN per mm of width [I], 10 mm wide, 80 mm centres (report 3.2.2)
    "belt": {"belt": {"belt_stiffness_n_per_mm": 2000.0, "belt_width_mm": 10.0, "belt_center_distance_m": 0.080,
                      "belt_damping_ratio": 0.05}},
}
"""Further plants with an imperfection on, beside the issue's four (kept apart: the fit's benchmark runs those)."""


def active(p: PlantParams) -> tuple[str, ...]:
    """The imperfections switched on in these parameters, in `NAMES` order."""
    on = {"stribeck": p.stribeck_peak_nm > 0.0, "load_friction": p.efficiency_backdriven is not None,
          "torque_ripple": p.ripple_amplitude_nm > 0.0, "belt_compliance": p.belt_stiffness_n_per_mm > 0.0}
    return tuple(n for n in NAMES if on[n])


def install(c: Coefficients, p: PlantParams) -> None:
    """Hand the integrator the imperfections' dynamics when the belt compliance (the two-mass model, with the others
    in it), the Stribeck friction or the ripple is on (the backdriven efficiency is the nominal integrator's own);
    otherwise leave it untouched."""
    if p.belt_stiffness_n_per_mm > 0.0:
        from hal.virtual.plant.belt import BeltDynamics

        belt = BeltDynamics(c, p)
        c.imp_accel = belt.accel
        c.imp_integrate = belt.integrate
        c.imp_energy = belt.energy
    elif p.stribeck_peak_nm > 0.0 or p.ripple_amplitude_nm > 0.0:
        dyn = ImperfectDynamics(c, p)
        c.imp_accel = dyn.accel
        c.imp_integrate = dyn.integrate


class ImperfectDynamics:
    """The ankle's acceleration and RK4 steps with the Stribeck friction and the torque ripple added to the nominal
    model (`nominal_accel`, `static_accel`): plain Python, the nominal integrator's steps one by one."""

    def __init__(self, c: Coefficients, p: PlantParams) -> None:
        """The constants, divided by the output inertia like the nominal ones (c's)."""
        self.c = c
        self.stribeck = p.stribeck_peak_nm * c.inv_j
        self.inv_ws2 = 1.0 / p.stribeck_speed_rad_s ** 2
        self.ripple = p.ripple_amplitude_nm * c.inv_j
        self.ripple_k = p.ripple_periods_per_rev * p.total_ratio  # ripple periods per ankle radian times 2 pi
        self.zero_speed = c.tc + self.stribeck  # the sliding friction at zero speed
        self.breakaway = max(c.tsx, self.zero_speed)

    def _static(self, th: float, i: float, ext: float) -> float:
        """Acceleration at rest without friction (decides sticking and breakaway), the ripple included."""
        return static_accel(self.c, th, i, ext) + self.ripple * math.sin(self.ripple_k * th)

    def _sliding(self, th: float, w: float, i: float, ext: float, s: int) -> float:
        """Acceleration while sliding in direction s."""
        return (nominal_accel(self.c, th, w, i, ext, s) + self.ripple * math.sin(self.ripple_k * th)
                - s * self.stribeck * math.exp(-w * w * self.inv_ws2))

    def accel(self, th: float, w: float, i: float, ext: float, s: int, d: float = 0.0, dd: float = 0.0) -> float:
        """Acceleration of the ankle for angle, velocity, current, external torque and friction mode (the belt is
        rigid here: its stretch d, dd is 0)."""
        if s != 0:
            return self._sliding(th, w, i, ext, s)
        a = self._static(th, i, ext)
        if -self.breakaway <= a <= self.breakaway:
            return 0.0
        return a - self.zero_speed if a > 0.0 else a + self.zero_speed

    def integrate(self, d: Drive, state: State, t_base: float, k_first: int, n: int, h: float, ea: float, eb: float,
                  fn: Callable[[float], float] | None, exps: tuple[float, float]) -> State:
        """`integrator.integrate`'s n RK4 steps (the same current lag, stick and breakaway rules) on this model."""
        th, w, i, s, bd, bdd = state
        hh, h6 = 0.5 * h, h / 6.0
        eh, e1 = exps
        for kk in range(k_first, k_first + n):
            t = t_base + kk * h
            x1, x2, x4 = ((ea + eb * t, ea + eb * (t + hh), ea + eb * (t + h)) if fn is None
                          else (fn(t), fn(t + hh), fn(t + h)))
            tg = lag_target(self.c, d, w)
            i_m = tg + (i - tg) * eh
            i_e = tg + (i - tg) * e1
            if s == 0:
                a = self._static(th, i, x1)
                if -self.breakaway <= a <= self.breakaway:
                    i = i_e
                    continue
                s = 1 if a > 0.0 else -1
            a1 = self._sliding(th, w, i, x1, s)
            th2, w2 = th + hh * w, w + hh * a1
            a2 = self._sliding(th2, w2, i_m, x2, s)
            th3, w3 = th + hh * w2, w + hh * a2
            a3 = self._sliding(th3, w3, i_m, x2, s)
            th4, w4 = th + h * w3, w + h * a3
            a4 = self._sliding(th4, w4, i_e, x4, s)
            th += h6 * (w + 2.0 * (w2 + w3) + w4)
            w += h6 * (a1 + 2.0 * (a2 + a3) + a4)
            i = i_e
            if w * s <= 0.0:  # velocity reached or crossed zero inside the step: stick or reverse
                a = self._static(th, i, x4)
                if -self.breakaway <= a <= self.breakaway:
                    s, w = 0, 0.0
                elif w != 0.0:
                    s = 1 if w > 0.0 else -1
                else:
                    s = 1 if a > 0.0 else -1
        return th, w, i, s, bd, bdd


def profile_text(name: str, base: str | Path | None = None) -> str:
    """The base plant profile's text (default: the packaged one) with the keys of `MISSPECIFIED[name]` (or
    `OTHER_PLANTS[name]`) set: a key the profile has is given the new value in place, a new one goes under its table's
    header (a new table at the end)."""
    from hal.virtual.plant.params import default_profile_path

    plants = {**MISSPECIFIED, **OTHER_PLANTS}
    if name not in plants:
        raise ValueError(f"misspecified plant {name!r} unknown: choose from {', '.join(plants)}")
    lines = Path(base if base is not None else default_profile_path()).read_text(encoding="utf-8").splitlines()
    for table, keys in plants[name].items():
        after = None
        for key, value in keys.items():
            after = _set_key(lines, table, key, value, after)
    return "\n".join(lines) + "\n"


def _set_key(lines: list[str], table: str, key: str, value: float, after: int | None) -> int | None:
    """Set `key = value` in [table] of a TOML profile's lines (tables of scalars, as plant profiles are): in place, or
    after line `after` (the previous new key's), or under the table's header, or in a new table at the end. Returns the
    line of a new key (None when set in place)."""
    entry = f"{key} = {value!r}  # misspecified (hal/virtual/plant/imperfections.py)"
    header = None
    current = ""
    for n, line in enumerate(lines):
        stripped = line.strip()
        if stripped.startswith("[") and stripped.endswith("]"):
            current = stripped[1:-1].strip()
            if current == table:
                header = n
        elif current == table and stripped.split("=")[0].strip() == key:
            lines[n] = entry
            return None
    if after is None and header is None:
        lines.extend(["", f"[{table}]"])
        after = len(lines) - 1
    at = (after if after is not None else header) + 1  # type: ignore[operator]
    lines.insert(at, entry)
    return at

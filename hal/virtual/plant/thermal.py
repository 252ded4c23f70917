"""Winding temperature: a two-node (winding, housing) thermal model driven by the copper loss.

    C_w dT_w/dt = P_cu - (T_w - T_h) / R_wh
    C_h dT_h/dt = (T_w - T_h) / R_wh - (T_h - T_a) / R_ha
    P_cu = k I^2 R(T_w),   R(T) = R_ref (1 + alpha (T - T_ref))

I is the q-axis current the driver regulates (the plant's and the VESC telemetry's "motor current") and R_ref
the maker's phase-to-phase (line-to-line) resistance. The drivers' q current is amplitude-invariant: VESC's
FOC (mcpwm_foc.c) takes i_alpha = i_a, i_beta = (i_a + 2 i_b)/sqrt(3), so |i_dq| is the phase current's
amplitude. Three phases of RMS amplitude/sqrt(2) through R_phase each dissipate

    P_cu = 3 (i_q / sqrt(2))^2 R_phase = 1.5 i_q^2 R_phase = 0.75 i_q^2 R_ll     (star winding, R_ll = 2 R_phase)

(the amplitude-invariant transform's power is 3/2 (v_d i_d + v_q i_q): P. C. Krause, O. Wasynczuk, S. D. Sudhoff,
*Analysis of Electric Machinery and Drive Systems*, 2nd ed., Wiley 2002, sec. 3.3), so k = 0.75
(``COPPER_LOSS_FACTOR``). A delta winding gives the same: R_ll = 2/3 R_delta and the phase current is
1/sqrt(3) of the line's. The makers' motor constant Km is Kt / sqrt(R_ll) for every catalogue motor, a catalogue
formula (copper loss R_ll I^2 of a DC current through two phases), not the loss of the q current the driver
regulates, which is 4/3 smaller. Iron and friction losses are left out (they heat the housing mostly and are not
published for the catalogue motors).

The step is backward Euler on the 2x2 linear system (R's temperature dependence enters linearly), so
it is stable for any step; the plant steps far below the 17 s winding time constant.

>>> from hal.virtual.plant.motors import load_motor
>>> t = WindingThermal(ThermalParams.from_motor(load_motor("ak60_6")), ambient_c=25.0)
>>> round(t.steady_state_c(6.5)[0], 1)  # rated current, from 25 C ambient
45.8
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hal.virtual.plant.motors import MotorSpec

#: Copper loss per (q-axis ampere)^2 per ohm of phase-to-phase resistance: 1.5 R_phase = 0.75 R_ll (module docstring).
COPPER_LOSS_FACTOR = 0.75
THERMAL_BOUNDS = ("nominal", "pessimistic")
"""The housing-to-ambient resistance a run takes: the motor profile's figure, or the upper end of its range."""


@dataclass(frozen=True)
class ThermalParams:
    """Thermal network and winding resistance of one motor, SI units and degrees Celsius."""

    winding_to_housing_k_per_w: float
    housing_to_ambient_k_per_w: float
    winding_heat_capacity_j_per_k: float
    housing_heat_capacity_j_per_k: float
    resistance_ohm: float
    copper_tempco_per_k: float
    resistance_reference_c: float
    max_winding_c: float
    copper_loss_factor: float = COPPER_LOSS_FACTOR

    def __post_init__(self) -> None:
        """Every parameter finite and positive (the temperatures finite)."""
        for name in ("winding_to_housing_k_per_w", "housing_to_ambient_k_per_w",
                     "winding_heat_capacity_j_per_k", "housing_heat_capacity_j_per_k",
                     "resistance_ohm", "copper_loss_factor"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"thermal parameter {name} = {value!r} must be finite and > 0")
        for name in ("copper_tempco_per_k", "resistance_reference_c", "max_winding_c"):
            value = getattr(self, name)
            if not math.isfinite(value) or (name == "copper_tempco_per_k" and value < 0.0):
                raise ValueError(f"thermal parameter {name} = {value!r} must be finite (tempco >= 0)")

    @classmethod
    def from_motor(cls, m: MotorSpec, bound: str = "nominal") -> ThermalParams:
        """The thermal parameters of a catalogue motor; bound "pessimistic": the housing resistance's upper end."""
        if bound not in THERMAL_BOUNDS:
            raise ValueError(f"thermal bound {bound!r} is not allowed: one of {', '.join(THERMAL_BOUNDS)}")
        r_ha = m.housing_to_ambient_max_k_per_w if bound == "pessimistic" else m.housing_to_ambient_k_per_w
        return cls(
            winding_to_housing_k_per_w=m.winding_to_housing_k_per_w,
            housing_to_ambient_k_per_w=r_ha,
            winding_heat_capacity_j_per_k=m.winding_heat_capacity_j_per_k,
            housing_heat_capacity_j_per_k=m.housing_heat_capacity_j_per_k,
            resistance_ohm=m.phase_resistance_ohm,
            copper_tempco_per_k=m.copper_tempco_per_k,
            resistance_reference_c=m.resistance_reference_c,
            max_winding_c=m.max_temperature_c,
        )

    def time_constants_s(self) -> tuple[float, float]:
        """(fast, slow) time constants of the network with R fixed: -1/eigenvalues of its matrix."""
        g1 = 1.0 / self.winding_to_housing_k_per_w
        g2 = 1.0 / self.housing_to_ambient_k_per_w
        a11 = -g1 / self.winding_heat_capacity_j_per_k
        a12 = g1 / self.winding_heat_capacity_j_per_k
        a21 = g1 / self.housing_heat_capacity_j_per_k
        a22 = -(g1 + g2) / self.housing_heat_capacity_j_per_k
        trace, det = a11 + a22, a11 * a22 - a12 * a21
        root = math.sqrt(trace * trace / 4.0 - det)
        fast, slow = trace / 2.0 - root, trace / 2.0 + root
        return -1.0 / fast, -1.0 / slow


class WindingThermal:
    """Winding and housing temperatures of one motor, stepped with the current it carries."""

    def __init__(self, params: ThermalParams, ambient_c: float = 25.0) -> None:
        """Start at thermal equilibrium with the ambient."""
        if not math.isfinite(ambient_c) or not -40.0 <= ambient_c <= 80.0:
            raise ValueError(f"ambient temperature {ambient_c!r} C is outside the allowed range [-40, 80]")
        self.params = params
        self.ambient_c = ambient_c
        self.winding_c = ambient_c
        self.housing_c = ambient_c
        self.copper_energy_j = 0.0
        self.amp2_seconds = 0.0  # integral of the current squared: the RMS current over any span

    def resistance_ohm(self) -> float:
        """Phase-to-phase winding resistance at the present winding temperature."""
        p = self.params
        return p.resistance_ohm * (1.0 + p.copper_tempco_per_k * (self.winding_c - p.resistance_reference_c))

    def copper_loss_w(self, current_a: float) -> float:
        """Copper loss at q-axis current ``current_a`` and the present winding temperature."""
        return self.params.copper_loss_factor * current_a * current_a * self.resistance_ohm()

    def step(self, dt_s: float, current_a: float) -> None:
        """Advance by ``dt_s`` with the q-axis current held at ``current_a`` (backward Euler)."""
        p = self.params
        kir = p.copper_loss_factor * current_a * current_a * p.resistance_ohm
        # P_cu(T_w) = a + b T_w
        b = kir * p.copper_tempco_per_k
        a = kir - b * p.resistance_reference_c
        g1 = 1.0 / p.winding_to_housing_k_per_w
        g2 = 1.0 / p.housing_to_ambient_k_per_w
        cw = p.winding_heat_capacity_j_per_k / dt_s
        ch = p.housing_heat_capacity_j_per_k / dt_s
        m11, m12 = cw - b + g1, -g1
        m21, m22 = -g1, ch + g1 + g2
        r1 = cw * self.winding_c + a
        r2 = ch * self.housing_c + g2 * self.ambient_c
        det = m11 * m22 - m12 * m21
        winding = (r1 * m22 - m12 * r2) / det
        housing = (m11 * r2 - m21 * r1) / det
        self.copper_energy_j += (a + b * winding) * dt_s
        self.amp2_seconds += current_a * current_a * dt_s
        self.winding_c, self.housing_c = winding, housing

    def steady_state_c(self, current_a: float) -> tuple[float, float]:
        """(winding, housing) temperatures at a constant current; ``inf`` if the winding runs away.

        Solves T_w - T_a = P_cu(T_w) (R_wh + R_ha): with R rising with temperature the loss grows with
        the winding temperature, and above a current I^2 >= 1/(k R_ref alpha (R_wh + R_ha)) no steady
        state exists.
        """
        p = self.params
        r_sum = p.winding_to_housing_k_per_w + p.housing_to_ambient_k_per_w
        kir = p.copper_loss_factor * current_a * current_a * p.resistance_ohm
        denominator = 1.0 - p.copper_tempco_per_k * kir * r_sum
        if denominator <= 0.0:
            return math.inf, math.inf
        rise = kir * r_sum * (1.0 + p.copper_tempco_per_k * (self.ambient_c - p.resistance_reference_c))
        rise /= denominator
        power = rise / r_sum
        return self.ambient_c + rise, self.ambient_c + power * p.housing_to_ambient_k_per_w

    def continuous_current_a(self) -> float:
        """Largest constant q-axis current whose steady winding temperature stays at ``max_winding_c``."""
        p = self.params
        r_sum = p.winding_to_housing_k_per_w + p.housing_to_ambient_k_per_w
        rise = p.max_winding_c - self.ambient_c
        if rise <= 0.0:
            return 0.0
        r_hot = p.resistance_ohm * (1.0 + p.copper_tempco_per_k * (p.max_winding_c - p.resistance_reference_c))
        return math.sqrt(rise / (r_sum * p.copper_loss_factor * r_hot))

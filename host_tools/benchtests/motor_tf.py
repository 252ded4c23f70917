"""The motor's transfer function (report 3.5.1-3.5.2, eq 3.39) against the one its Table B2 constants give.

Eq 3.39 is speed over voltage, 23.21e6 / (s^2 + 1476.1955 s + 3.261e9). Its numerator is K_t/(J L) of
Table B2 (0.078 / (2.435e-5 x 138e-6) = 23.21e6); its constant term should be K_t K_e/(J L) (eqs 3.32,
3.62), but 3.261e9 / 23.21e6 = 140.5: the Kv of the motor's name (140 rpm/V) where K_e (0.0716 V s/rad)
belongs -- an erratum. With K_e the poles are at omega_n = 1289 rad/s, zeta = 0.57 and the DC gain is
1/K_e = 14 rad/s per volt (24 V: 3200 rpm, the motor's Kv x 24 V = 3360 rpm no-load); eq 3.39 as printed
rings at 57,100 rad/s with zeta = 0.013 and settles at 0.0071 rad/s per volt. The s term's 1476.2 is R/L
(1463.8) plus B/J: a rotor viscous friction B = 3.0e-4 N m s/rad is implied, kept here.
Driver readings: eq 3.39 alone (winding voltage in), and behind eq 3.41's voltage amplifier 24/(1 + 0.00114 s)
(the report's chain, PID output in); the plant's current-lag reading has no voltage input.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from hal.virtual.plant import PlantParams, load_plant_params
from hal.virtual.plant.linear import REPORT_MOTOR_TF, motor_tf, second_order
from host_tools.benchtests.output import BenchResult, Figure

__all__ = ["READINGS", "run", "step_figures"]

#: The readings of the report this test runs under (hal.virtual.plant.readings).
READINGS = {"geometry": "n/a", "driver": "voltage-amplifier", "imu": "n/a"}
SECTION = "3.5.1-3.5.2, eq 3.39"


def step_figures(t_s: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """Final value, 10-90 % rise time and overshoot (%) of a step response."""
    final = float(y[-1])
    rise = float(t_s[np.argmax(y >= 0.9 * final)] - t_s[np.argmax(y >= 0.1 * final)])
    return {"final": final, "rise_s": rise, "overshoot_pct": float(max(0.0, y.max() / final - 1.0) * 100.0)}


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None) -> BenchResult:
    """Poles, DC gain, step and frequency response of eq 3.39 as printed and as its constants give it."""
    del seed, quick  # deterministic arithmetic
    p = params if params is not None else load_plant_params()
    num_r, den_r = REPORT_MOTOR_TF
    implied_b = (den_r[1] - p.phase_resistance_ohm / p.phase_inductance_h) * p.rotor_inertia_kg_m2
    num_c, den_c = motor_tf(p, implied_b)
    wn_r, z_r = second_order(den_r)
    wn_c, z_c = second_order(den_c)
    wn_nob, z_nob = second_order(motor_tf(p)[1])
    ratio = den_r[2] / num_r[0]
    amp = signal.TransferFunction([p.supply_voltage_v], [p.current_time_constant_s, 1.0])
    chain = signal.TransferFunction(np.polymul(amp.num, num_c), np.polymul(amp.den, den_c))
    t = np.linspace(0.0, 0.02, 2001)
    _, y_r = signal.step((num_r, den_r), T=t)
    _, y_c = signal.step((num_c, den_c), T=t)
    _, y_chain = signal.step(chain, T=t)
    st_c, st_r, st_chain = step_figures(t, y_c), step_figures(t, y_r), step_figures(t, y_chain)
    w = np.logspace(1, 6, 400)
    _, mag_r, _ = signal.bode((num_r, den_r), w)
    _, mag_c, _ = signal.bode((num_c, den_c), w)
    no_load_rpm = num_c[0] / den_c[2] * p.supply_voltage_v * 60 / (2 * math.pi)
    pred = "predicted"
    fit_b = "fitted: rotor viscous friction B = 3.0e-4 N m s/rad, from eq 3.39's s term minus R/L"
    figures = [
        Figure("eq 3.39: constant term / numerator", "-", f"3.261e9 / 23.21e6 ({SECTION})", ratio, p.kv_rpm_per_v,
               f"= {ratio:.1f}: the motor's Kv ({p.kv_rpm_per_v:g} rpm/V, emulated column) where K_e = "
               f"{p.ke_v_s_per_rad:.4f} V s/rad belongs: an erratum", basis=pred),
        Figure("natural frequency", "rad/s", f"sqrt(3.261e9) = {wn_r:.0f} ({SECTION})", wn_r, wn_c,
               f"corrected: sqrt((K_t K_e + R B) / (J L)) from Table B2; without B {wn_nob:.0f} rad/s, zeta "
               f"{z_nob:.3f}", basis=fit_b),
        Figure("damping ratio", "-", f"{z_r:.4f} ({SECTION})", z_r, z_c,
               "corrected; the report's \"oscillations [...] due to the system's natural frequency\" (3.5.2) come "
               "from the erratum", basis=fit_b),
        Figure("DC gain, speed per volt", "rad/s/V", f"23.21e6 / 3.261e9 = {num_r[0] / den_r[2]:.3g} ({SECTION})",
               num_r[0] / den_r[2], num_c[0] / den_c[2], "corrected: about 1/K_e", basis=pred),
        Figure("no-load speed at 24 V", "rpm", f"Kv x 24 V = {p.kv_rpm_per_v * p.supply_voltage_v:g} (Table B2)",
               p.kv_rpm_per_v * p.supply_voltage_v, no_load_rpm, "corrected transfer function's DC gain x 24 V",
               basis=pred),
        Figure("step: rise time 10-90 %", "ms", "Fig 3.6 (plot only)", None, 1e3 * st_c["rise_s"],
               f"eq 3.39 as printed: {1e3 * st_r['rise_s']:.3f} ms, overshoot {st_r['overshoot_pct']:.0f} %",
               basis=fit_b),
        Figure("step: overshoot", "%", "Fig 3.6 (plot only)", None, st_c["overshoot_pct"], "corrected", basis=fit_b),
        Figure("behind the voltage amplifier 24/(1 + 0.00114 s): rise time 10-90 %", "ms", "eq 3.41 (3.5.3)", None,
               1e3 * st_chain["rise_s"], f"final {st_chain['final']:.0f} rad/s per unit PID output, overshoot "
               f"{st_chain['overshoot_pct']:.1f} %", basis=fit_b),
    ]

    def plot(fig: object) -> None:
        ax1, ax2 = fig.subplots(2, 1)  # type: ignore[attr-defined]
        ax1.plot(1e3 * t, y_c / st_c["final"], label=f"Table B2 constants (ωn {wn_c:.0f} rad/s, ζ {z_c:.2f})")
        ax1.plot(1e3 * t, y_r / st_r["final"], label=f"eq 3.39 as printed (ωn {wn_r:.0f} rad/s, ζ {z_r:.3f})", lw=0.7)
        ax1.plot(1e3 * t, y_chain / st_chain["final"], label="Table B2 behind the 24/(1 + 0.00114 s) amplifier")
        ax1.set(xlabel="time [ms]", ylabel="speed / final value", title="Motor step response (report eq 3.39)")
        ax1.legend(fontsize=8)
        ax2.semilogx(w, mag_c, label="Table B2 constants")
        ax2.semilogx(w, mag_r, label="eq 3.39 as printed")
        ax2.set(xlabel="ω [rad/s]", ylabel="|speed/voltage| [dB rad/s/V]")
        ax2.legend(fontsize=8)

    columns = {"t_s": t, "speed_per_volt_corrected": y_c, "speed_per_volt_eq339": y_r,
               "speed_per_unit_pid_amplifier": y_chain, "w_rad_s": w, "mag_db_corrected": mag_c,
               "mag_db_eq339": mag_r}
    return BenchResult("motor-tf", figures, columns, plot,
                       {"eq339": {"num": list(num_r), "den": list(den_r), "wn_rad_s": wn_r, "zeta": z_r},
                        "corrected": {"num": list(num_c), "den": list(den_c), "wn_rad_s": wn_c, "zeta": z_c},
                        "implied_viscous_nm_s_per_rad": implied_b,
                        "without_viscous": {"wn_rad_s": wn_nob, "zeta": z_nob}, "constant_over_numerator": ratio,
                        "step_corrected": st_c, "step_eq339": st_r, "step_behind_amplifier": st_chain})

"""Linear models of the plant for the report's own analyses (3.5.1-3.6.3): motor transfer function, state space.

The nonlinear plant (:mod:`hal.virtual.plant.model`) is what the bench runs; these are the small-signal
models the report analysed, built from the same profile so that the two can be set side by side:

- :func:`motor_tf`: rotor speed per winding voltage of the unloaded motor (report eq 3.39, corrected);
- :func:`report_state_space`: eq 3.67 as the report writes it (T_d = K_t i at the ankle, back-EMF on the
  ankle speed, J = J_c + m d^2, hanging pendulum linearised);
- :func:`loop_state_space`: the same loop with the transmission (N, efficiency, reflected inertia), the
  geometry reading's gravity stiffness and either driver reading (hal.virtual.plant.readings).
"""

from __future__ import annotations

import math

import numpy as np

from hal.virtual.plant.params import PlantParams
from hal.virtual.plant.readings import check_reading, with_geometry

__all__ = ["REPORT_MOTOR_TF", "gravity_stiffness_nm_per_rad", "loop_state_space", "motor_tf", "report_state_space",
           "second_order"]

#: Report eq 3.39, speed over voltage: 23.21e6 / (s^2 + 1476.1955 s + 3.261e9), as (numerator, denominator).
REPORT_MOTOR_TF: tuple[tuple[float, ...], tuple[float, ...]] = ((23.21e6,), (1.0, 1476.1955, 3.261e9))


def motor_tf(p: PlantParams, viscous_nm_s_per_rad: float = 0.0) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Rotor speed [rad/s] per winding voltage [V] of the unloaded motor, from the profile's constants.

    J L s^2 + (J R + B L) s + (R B + K_t K_e) over K_t, divided through by J L (eqs 3.32, 3.62).
    """
    j, r, ind = p.rotor_inertia_kg_m2, p.phase_resistance_ohm, p.phase_inductance_h
    kt, ke, b = p.kt_nm_per_a, p.ke_v_s_per_rad, viscous_nm_s_per_rad
    return (kt / (j * ind),), (1.0, r / ind + b / j, (r * b + kt * ke) / (j * ind))


def second_order(den: tuple[float, ...]) -> tuple[float, float]:
    """(natural frequency [rad/s], damping ratio) of a monic s^2 + a s + b."""
    _, a, b = den
    wn = math.sqrt(b)
    return wn, a / (2.0 * wn)


def gravity_stiffness_nm_per_rad(p: PlantParams) -> float:
    """d(gravity restoring torque)/d(theta) at 0 deg: m g d cos(psi0) (m g d hanging, 0 with the COM level)."""
    return p.gravity_moment_nm * math.cos(p.com_angle_at_zero_rad)


def report_state_space(p: PlantParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq 3.67 as written: x = (theta, omega, i), u = winding voltage; (A, B, C)."""
    j = p.foot_output_inertia_kg_m2  # J_c + m d^2 (3.55)
    mgd, k = p.gravity_moment_nm, p.foot_damping_nm_s_per_rad
    kt, ke, r, ind = p.kt_nm_per_a, p.ke_v_s_per_rad, p.phase_resistance_ohm, p.phase_inductance_h
    a = np.array([[0.0, 1.0, 0.0], [-mgd / j, -k / j, kt / j], [0.0, -ke / ind, -r / ind]])
    return a, np.array([[0.0], [0.0], [1.0 / ind]]), np.array([[1.0, 0.0, 0.0]])


def loop_state_space(p: PlantParams, geometry: str, driver: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The linearised bench loop at 0 deg under a geometry and a driver reading; (A, B, C), output theta.

    current-lag: x = (theta, omega, i), u = current command [A], i' = (u - i)/tau.
    voltage-amplifier: x = (theta, omega, i, v), u = the PID output in [-1, 1], v' = (V_bus u - v)/tau,
    L i' = v - R i - K_e N omega (eq 3.41 before eq 3.62).
    Torque at the ankle K_t N eta i; inertia the foot's plus the reflected transmission's; friction left out.
    """
    q = with_geometry(p, geometry)
    check_reading("driver", driver)
    j = q.output_inertia_kg_m2
    kg, k = gravity_stiffness_nm_per_rad(q), q.foot_damping_nm_s_per_rad
    kto, tau = q.output_torque_per_amp_nm, q.current_time_constant_s
    if driver == "current-lag":
        a = np.array([[0.0, 1.0, 0.0], [-kg / j, -k / j, kto / j], [0.0, 0.0, -1.0 / tau]])
        return a, np.array([[0.0], [0.0], [1.0 / tau]]), np.array([[1.0, 0.0, 0.0]])
    n, r, ind, ke = q.total_ratio, q.phase_resistance_ohm, q.phase_inductance_h, q.ke_v_s_per_rad
    a = np.array([[0.0, 1.0, 0.0, 0.0], [-kg / j, -k / j, kto / j, 0.0],
                  [0.0, -ke * n / ind, -r / ind, 1.0 / ind], [0.0, 0.0, 0.0, -1.0 / tau]])
    return a, np.array([[0.0], [0.0], [0.0], [q.supply_voltage_v / tau]]), np.array([[1.0, 0.0, 0.0, 0.0]])


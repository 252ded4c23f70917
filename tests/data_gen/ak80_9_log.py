"""A bench log of a simulated CubeMars AK80-9, written the way TMotorCANControl's servo-mode manager writes one, with
none of pafp's code (numpy only): the yardstick of `pafp fit LOG.csv` (tests/test_csv_fit.py).

The bench: the motor's shaft drives a load motor (a dynamometer: its own torque steps, some damping) through an
inline torque sensor; the motor runs in current
mode under a chirp, a pseudo-random binary sequence and a slow square wave. The rotor obeys

    J dw/dt = Kt i - Tc tanh(w / w_c) - b w - T_sensor,    T_sensor = c_load w + T_dyn(t),
    di/dt = (i_command - i) / tau                          (the driver's current loop),

integrated with RK4 at 10 kHz; the host loop reads the motor and sends the next command every 1 ms +- 0.1 ms (the
command held in between). Logged at 1 kHz, TMotorCANControl's
servo columns (``pi_time``, ``motor_position`` [rad], ``motor_speed`` [rad/s], ``motor_current`` [A],
``motor_temperature`` [C]) plus the bench's ``current_command`` [A] and ``torque_sensor`` [N m], each measurement
with its noise and resolution. Kt = 0.115 N m/A is TMotorCANControl's ``Kt_actual`` for the AK80-9 (servo_can.py);
the other values are [I] of the order of a small outrunner's. The Coulomb friction is smoothed (w_c = 0.05 rad/s):
above 0.2 rad/s it is within 0.1 % of Tc.

Run ``python tests/data_gen/ak80_9_log.py OUT.csv [SEED]``: writes the log, prints the truth as JSON.
"""

from __future__ import annotations

import json
import math
import sys

import numpy as np

TRUTH = {"kt_nm_per_a": 0.115, "rotor_inertia_kg_m2": 6.0e-5, "coulomb_friction_nm": 0.025,
         "viscous_friction_nm_s_per_rad": 1.2e-4, "current_time_constant_s": 0.0008}
LOAD_NM_S_PER_RAD = 1.0e-3  # the load motor's damping behind the torque sensor
LOAD_NM = 0.12  # the load motor's torque steps (+-), 0.2 s each: a dynamometer's profile, independent of the rotor
COULOMB_SMOOTHING_RAD_S = 0.05
LOG_HZ, SUBSTEPS, DURATION_S = 1000, 10, 16.0


def command(n: int, rng: np.random.Generator) -> np.ndarray:
    """The current command at each log sample [A]: a chirp 0.5 -> 25 Hz, a PRBS of 25 ms bits, a 0.3 Hz square
    (1.2, 0.6, 1.2 A)."""
    t = np.arange(n) / LOG_HZ
    f0, f1 = 0.5, 25.0
    phase = 2 * np.pi * (f0 * t + (f1 - f0) * t ** 2 / (2 * DURATION_S))
    bits = rng.choice([-1.0, 1.0], size=n // 25 + 1).repeat(25)[:n]
    square = np.sign(np.sin(2 * np.pi * 0.3 * t) + 1e-12)
    return 1.2 * np.sin(phase) + 0.6 * bits + 1.2 * square


def simulate(i_cmd: np.ndarray, jitter: np.ndarray, load_nm: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(time, angle, speed, current) at each log sample from the rotor at rest. The host loop's k-th iteration reads
    the motor and sends i_cmd[k] at the substep SUBSTEPS k + jitter[k] (its timing jitter, a whole substep); the load
    motor's torque is load_nm[k] from there on."""
    kt, j = TRUTH["kt_nm_per_a"], TRUTH["rotor_inertia_kg_m2"]
    tc, b, tau = TRUTH["coulomb_friction_nm"], TRUTH["viscous_friction_nm_s_per_rad"], TRUTH["current_time_constant_s"]
    h = 1.0 / (LOG_HZ * SUBSTEPS)

    def deriv(w: float, i: float, u: float, load: float) -> tuple[float, float]:
        torque = kt * i - tc * math.tanh(w / COULOMB_SMOOTHING_RAD_S) - (b + LOAD_NM_S_PER_RAD) * w - load
        return torque / j, (u - i) / tau

    th = w = i = 0.0
    at = SUBSTEPS * np.arange(len(i_cmd)) + jitter
    out = np.empty((len(i_cmd), 4))
    for k, (u, m) in enumerate(zip(i_cmd, load_nm, strict=True)):
        out[k] = at[k] * h, th, w, i
        for _ in range(at[k + 1] - at[k] if k + 1 < len(at) else SUBSTEPS):
            a1, d1 = deriv(w, i, u, m)
            a2, d2 = deriv(w + 0.5 * h * a1, i + 0.5 * h * d1, u, m)
            a3, d3 = deriv(w + 0.5 * h * a2, i + 0.5 * h * d2, u, m)
            a4, d4 = deriv(w + h * a3, i + h * d3, u, m)
            th += h / 6 * (w + 2 * (w + 0.5 * h * a1) + 2 * (w + 0.5 * h * a2) + (w + h * a3))
            w += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
            i += h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
    return out[:, 0], out[:, 1], out[:, 2], out[:, 3]


def make_log(path: str, seed: int = 0) -> dict[str, float]:
    """Write the log to path; the truth."""
    rng = np.random.default_rng(seed)
    n = int(DURATION_S * LOG_HZ)
    i_cmd = command(n, rng)
    load = LOAD_NM * rng.choice([-1.0, 1.0], size=n // 200 + 1).repeat(200)[:n]
    t, th, w, i = simulate(i_cmd, rng.integers(-1, 2, n), load)  # a host loop of 1 ms +- 0.1 ms
    counts = 2 * np.pi / 2 ** 14  # a 14-bit encoder on the rotor
    rows = np.column_stack([
        t,
        np.round(th / counts) * counts,
        np.round((w + rng.normal(0, 0.3, n)) / 0.05) * 0.05,  # speed from ERPM: noisy, 0.05 rad/s steps
        np.round((i + rng.normal(0, 0.03, n)) / 0.01) * 0.01,  # the driver's 10 mA resolution
        30.0 + 0.0 * t,
        i_cmd,
        LOAD_NM_S_PER_RAD * w + load + rng.normal(0, 0.004, n),  # the load's torque
    ])
    header = "pi_time,motor_position,motor_speed,motor_current,motor_temperature,current_command,torque_sensor"
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.7g")
    return dict(TRUTH)


if __name__ == "__main__":
    print(json.dumps(make_log(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 0)))

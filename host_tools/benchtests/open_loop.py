"""The report's uncontrolled and open-loop simulations (3.6.1-3.6.2, Figs 3.13 and 3.15) on its linear models.

Fig 3.13: the system released from pi/5 without a controller ("falls from early stance to late stance within
0.5 seconds [...] further indicating instability", 3.6.1). Fig 3.15: an impulse on the driver's gate, "a
sudden change in the gate pulse of the driver which generates the voltage", from which the report reads
"the optimal sampling time is 0.9 sec" (3.6.2).
Models (hal.virtual.plant.linear): eq 3.67 as written (hanging pendulum, T_d = K_t i at the ankle, winding
voltage in), and the linearised bench loop under each geometry with the voltage-amplifier reading (eq 3.41
in front, transmission included; the bench's nonlinear drop is `pafp bench uncontrolled`). The impulse is the
PID's full output (+1) for one 1 ms control period: 24 V behind the amplifier's lag.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from hal.virtual.plant import Plant, PlantParams, load_plant_params
from hal.virtual.plant.linear import loop_state_space, report_state_space
from hal.virtual.plant.readings import geometry_of
from host_tools.benchtests.output import BenchResult, Figure

__all__ = ["READINGS", "run"]

#: The readings this test runs under; the geometry is the bench's.
READINGS = {"driver": "voltage-amplifier", "imu": "n/a"}
RELEASE_RAD = math.pi / 5
PULSE_S = 1e-3
DURATION_S = 5.0


def _free(a: np.ndarray, x0: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Angle of the unforced linear system from x0 (matrix exponential at each sample)."""
    from scipy.linalg import expm

    step = expm(a * (t[1] - t[0]))
    out = np.empty_like(t)
    x = x0.astype(float)
    for k in range(len(t)):
        out[k] = x[0]
        x = step @ x
    return out


def _pulse(a: np.ndarray, b: np.ndarray, c: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Angle response to an input of 1 for PULSE_S, then 0."""
    u = (t < PULSE_S).astype(float)
    _, y, _ = signal.lsim((a, b, c, np.zeros((1, 1))), u, t)
    return np.asarray(y, dtype=float)


def _settle(t: np.ndarray, y: np.ndarray, band: float) -> float:
    """Time after which |y - y_end| stays within band of the peak excursion (nan if never)."""
    peak = float(np.max(np.abs(y - y[-1])))
    outside = np.nonzero(np.abs(y - y[-1]) > band * peak)[0]
    return float(t[outside[-1] + 1]) if outside.size and outside[-1] + 1 < len(t) else math.nan


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None) -> BenchResult:
    """Eigenvalues, the release from pi/5 and the gate impulse of eq 3.67 and of the linearised bench loop."""
    del seed, quick  # deterministic
    p = params if params is not None else load_plant_params()
    geometry = geometry_of(p)
    t = np.linspace(0.0, DURATION_S, int(DURATION_S / 1e-3) + 1)
    a_r, b_r, c_r = report_state_space(p)
    a_l, b_l, c_l = loop_state_space(p, geometry if geometry != "custom" else "level-com", "voltage-amplifier")
    eig_r = np.linalg.eigvals(a_r)
    eig_l = np.linalg.eigvals(a_l)
    free_r = _free(a_r, np.array([RELEASE_RAD, 0.0, 0.0]), t)
    # gravity's constant part at 0 deg, -m g d sin(psi0) (all of m g d with the COM level), as a fifth state = 1
    aug = np.zeros((5, 5))
    aug[:4, :4] = a_l
    aug[1, 4] = -p.gravity_moment_nm * math.sin(p.com_angle_at_zero_rad) / p.output_inertia_kg_m2
    free_l = _free(aug, np.array([RELEASE_RAD, 0.0, 0.0, 0.0, 1.0]), t)
    pulse_r = _pulse(a_r, b_r * p.supply_voltage_v, c_r, t)  # eq 3.67's input is the voltage: 24 V
    pulse_l = _pulse(a_l, b_l, c_l, t)
    stop = p.stop_min_rad
    # the nonlinear plant with the voltage-amplifier driver at zero output (windings shorted), from pi/5
    plant = Plant(p, initial_angle_rad=RELEASE_RAD, driver="voltage-amplifier")
    plant.set_voltage_command(0.0, 0.0)
    free_p = np.array([plant.output_angle_rad(float(x)) for x in t])
    reach = np.nonzero(free_r <= stop)[0]
    t_stop_r = float(t[reach[0]]) if reach.size else math.nan
    slowest = max(e.real for e in eig_l)
    slow_text = ("a pole at 0: no restoring torque at 0 deg" if slowest > -1e-9 else
                 f"slowest time constant {-1.0 / slowest:.2f} s")
    words = "\"falls from early stance to late stance within 0.5 seconds [...] indicating instability\" (3.6.1)"
    pred = "predicted"
    lin = f"assumed: linearised at 0 deg, no friction, no stops; geometry {geometry}"
    figures = [
        Figure("eq 3.67 as written: largest real part of its poles", "1/s", "unstable (3.6.1, Fig 3.13)", None,
               float(max(e.real for e in eig_r)), "negative: eq 3.67 is a hanging pendulum, stable; the report's "
               "text calls the bench an inverted pendulum", basis=pred),
        Figure("eq 3.67 as written: release from pi/5, time to -30 deg", "s", words, 0.5, t_stop_r,
               f"lowest angle {math.degrees(float(free_r.min())):.1f} deg: overdamped (poles "
               f"{', '.join(f'{e.real:.1f}' for e in sorted(eig_r, key=lambda e: -e.real))} /s), it creeps back to 0",
               basis=pred),
        Figure(f"bench loop ({geometry}): largest real part of its poles", "1/s", "unstable (3.6.1)", None,
               float(max(e.real for e in eig_l)),
               "the windings shorted through the amplifier at 0 output brake the foot (back-EMF through N = 28)",
               basis=lin),
        Figure(f"bench loop ({geometry}): release from pi/5, angle after 0.5 s", "deg", words, None,
               math.degrees(float(free_l[int(round(0.5 / (t[1] - t[0])))])),
               slow_text + "; gravity's constant part included", basis=lin),
        Figure(f"plant, voltage amplifier at 0 ({geometry}): release from pi/5, angle after 0.5 s", "deg", words,
               None, math.degrees(float(free_p[int(round(0.5 / (t[1] - t[0])))])),
               "nonlinear (friction, stops); with the bridge open instead: pafp bench uncontrolled",
               basis=f"assumed: geometry {geometry}"),
        Figure("eq 3.67: 24 V for 1 ms, peak angle", "deg", "Fig 3.15 (plot only)", None,
               math.degrees(float(np.max(np.abs(pulse_r)))), f"2 % settling {_settle(t, pulse_r, 0.02):.2f} s",
               basis=pred),
        Figure(f"bench loop ({geometry}): gate impulse (PID +1 for 1 ms), 2 % settling time", "s",
               "\"the optimal sampling time is 0.9 sec\" (3.6.2)", 0.9, _settle(t, pulse_l, 0.02),
               f"peak {math.degrees(float(np.max(np.abs(pulse_l)))):.3f} deg; a settling time, not a sampling time",
               basis=lin),
    ]

    def plot(fig: object) -> None:
        ax1, ax2 = fig.subplots(2, 1, sharex=True)  # type: ignore[attr-defined]
        ax1.plot(t, np.degrees(free_r), label="eq 3.67 as written")
        ax1.plot(t, np.degrees(free_l), label=f"bench loop, {geometry}, voltage amplifier at 0")
        ax1.plot(t, np.degrees(free_p), label=f"plant, {geometry}, voltage amplifier at 0")
        ax1.axhline(math.degrees(stop), color="0.5", ls="--", label="plantarflexion stop")
        ax1.set(ylabel="angle [deg]", title="Released from π/5 without a controller (Fig 3.13)")
        ax1.legend(fontsize=8)
        ax2.plot(t, np.degrees(pulse_r), label="eq 3.67, 24 V for 1 ms")
        ax2.plot(t, np.degrees(pulse_l), label=f"bench loop, {geometry}, PID +1 for 1 ms")
        ax2.set(xlabel="time [s]", ylabel="angle [deg]", title="Gate impulse, open loop (Fig 3.15)")
        ax2.legend(fontsize=8)

    return BenchResult("open-loop", figures,
                       {"t_s": t, "release_eq367_deg": np.degrees(free_r), "release_loop_deg": np.degrees(free_l),
                        "release_plant_deg": np.degrees(free_p),
                        "impulse_eq367_deg": np.degrees(pulse_r), "impulse_loop_deg": np.degrees(pulse_l)}, plot,
                       {"geometry": geometry, "poles_eq367": [str(e) for e in eig_r],
                        "poles_loop": [str(e) for e in eig_l], "release_rad": RELEASE_RAD, "pulse_s": PULSE_S,
                        "slowest_pole_real_1_s": float(slowest)})

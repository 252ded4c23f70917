"""The fit's plant with its friction's switchings located inside a step (`integrator.integrate_located`,
`Plant(located_switching=True)`): continuous in the parameters where the bench's grid-switched plant jumps, and the
bench's plant where nothing switches.

The bench's plant switches its Coulomb and static friction on its 0.1 ms grid (a reversal keeps the old friction's
sign to the end of its step, a breakaway waits for the next step): as a parameter moves a switching across a grid
point its trajectory jumps. `pafp fit` minimises a cost over such trajectories; with the jumps in it, the cost was
rough at the scale of a twentieth of an interval and the fit's answer moved with the BLAS kernel's rounding
(docs/calibration.md, "Rounding").
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hal.virtual.plant import Plant, load_plant_params, suspended

BASE = load_plant_params()


def _angles(damping: float, located: bool) -> np.ndarray:
    """The suspended foot sliding up at 0.5 rad/s under a +-5 A square wave of 25 ms half-period (commands at 1 kHz,
    reversals and sticks between them), its angle every millisecond for 0.2 s."""
    plant = Plant(replace(BASE, foot_damping_nm_s_per_rad=damping), suspended(), initial_velocity_rad_s=0.5,
                  located_switching=located)
    out = []
    for k in range(200):
        plant.set_current_command(5.0 if (k // 25) % 2 == 0 else -5.0, k * 1e-3)
        out.append(plant.output_angle_rad(k * 1e-3 + 0.5e-3))
    return np.array(out)


def test_located_switching_is_continuous_in_the_parameters() -> None:
    # the damping over +-1 %: the reversals move by more than a step, so the grid-switched plant's last angle has
    # jumps in it (what this test is about: asserted, else the scan proves nothing); the located one is smooth to
    # far below an encoder count (1.6e-3 rad)
    xs = np.linspace(0.99, 1.01, 41) * BASE.foot_damping_nm_s_per_rad
    rough = {}
    for located in (False, True):
        last = np.array([_angles(x, located)[-1] for x in xs])
        rough[located] = float(np.abs(last - np.polyval(np.polyfit(xs, last, 3), xs)).max())
    assert rough[False] > 2e-6, rough  # measured 1.8e-5 rad
    assert rough[True] < 2e-7, rough  # measured 1.3e-8 rad
    assert rough[True] < rough[False] / 50, rough


def test_located_switching_is_the_bench_plant_between_switchings() -> None:
    # the first 25 ms slide one way without a reversal: the two integrators take the same RK4 steps (in
    # another order of the same terms) and agree to rounding; after the first reversal they differ by at most the
    # grid's switching error (an angle of order T_c h^2 / J)
    grid, located = _angles(BASE.foot_damping_nm_s_per_rad, False), _angles(BASE.foot_damping_nm_s_per_rad, True)
    assert np.abs(located[:25] - grid[:25]).max() < 1e-12
    assert 0.0 < np.abs(located - grid).max() < 1e-4  # measured 9.4e-6 rad


# the fit's cost along each parameter whose answer moved most with the BLAS kernel before the switchings were located
SCANNED = ("foot_damping_nm_s_per_rad", "coulomb_friction_nm", "output_inertia_kg_m2", "gravity_moment_nm",
           "static_friction_nm")
SCAN_STEP_HW = 0.01  # a fifth of the kernels' agreement goal (0.05 half-widths)


def test_the_fits_cost_is_smooth_at_the_scale_of_its_rounding_goal(handmade_fit) -> None:
    """The shared fit's cost (its own weights) about its solution, one parameter at a time in steps of a hundredth of
    its 95 % half-width: its first differences follow a line (the cost's slope and curvature; a kink bends it) to
    within half a unit (an interval spans 1.92), no step. With the friction switching on the plant's grid the same
    scans stepped by up to 4.7 units (the gravity moment); about another solution of the same recording, the
    backlash's blend passing half a command to a rotor that ends its crossing on the command's wrong side stepped the
    damping's by 1.9 (`fit_gap.GapShare.share`; docs/calibration.md, "Rounding")."""
    from host_tools.calibration.fit_data import load_experiment
    from host_tools.calibration.fit_model import base_values, load_base, residuals
    from host_tools.calibration.plant_fit import fit_parts

    s = handmade_fit["json"]
    base, fit_part = load_base(None), fit_parts(load_experiment(handmade_fit["run"]))[0]
    ns = s["noise_scales"]
    scales = {"angle": np.radians(ns["angle_deg"]), "current": ns["current_a"], "imu": np.radians(ns["imu_deg"])}
    v = {**base_values(base), **{n: p["value"] for n, p in s["params"].items()}}
    worst = {}
    for name in SCANNED:
        h = SCAN_STEP_HW * s["params"][name]["ci95_half_width"]
        cost = [0.5 * float(np.sum(residuals(base, {**v, name: v[name] + k * h}, fit_part, scales) ** 2))
                for k in range(-3, 4)]
        d1, k = np.diff(cost), np.arange(6)
        worst[name] = float(np.abs(d1 - np.polyval(np.polyfit(k, d1, 1), k)).max())
    assert max(worst.values()) < 0.5, worst

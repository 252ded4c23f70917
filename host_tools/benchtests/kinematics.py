"""Forward kinematics (report 3.7, DH Table 3.3, eqs 3.78-3.81) against the plant's geometry.

Table 3.3 chains two revolute joints: 0-1 (theta = 90 deg + theta_1, r = l1) and 1-2 (theta = 90 deg +
theta_2, r = l2), with theta_2 = theta_1 / G (eq 3.78) and T_02 = A_01 A_12 (eq 3.81). Written as a serial
arm, joint 2's axis (the ankle) sits at the end of link 1 and turns with theta_1: over the ankle's range
of motion the ankle axis would travel around the input pulley and the foot would turn by (1 + 1/G) theta_1,
G + 1 times the ankle angle. A belt drive keeps both axes fixed and turns the foot by theta_1 / G only. The
test evaluates the report's chain as written and the belt drive's (the ankle fixed, the foot at theta), and
checks the plant's potential energy against the centre of mass the belt drive's chain places (m g z_com), under
the geometry reading the bench runs (level COM, or hanging as eq 3.55).
l1: the pulleys' centre distance, 80 mm (3.2.2); l2: the plant's ankle-to-toe lever (0.21 m, assumed).
"""

from __future__ import annotations

import math

import numpy as np

from hal.virtual.plant import Plant, PlantParams, load_plant_params
from hal.virtual.plant.readings import geometry_of
from host_tools.benchtests.output import BenchResult, Figure

__all__ = ["CENTRE_DISTANCE_M", "READINGS", "dh", "report_chain", "run"]

#: The readings of the report this test runs under; the geometry is the bench's.
READINGS = {"driver": "n/a", "imu": "n/a"}
#: Report 3.2.2: "a center distance of 80 mm between the pulleys".
CENTRE_DISTANCE_M = 0.080
SECTION = "3.7, Table 3.3"


def dh(theta_rad: float, r_m: float) -> np.ndarray:
    """A planar DH transform with alpha = 0 and d = 0: Rot_z(theta) Trans_x(r) (the form of eqs 3.79-3.80)."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    return np.array([[c, -s, 0.0, r_m * c], [s, c, 0.0, r_m * s], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def report_chain(theta1_rad: float, gear: float, l1_m: float, l2_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(T_01, T_02) of Table 3.3 as written: joint angles 90 deg + theta_1 and 90 deg + theta_1 / G."""
    a01 = dh(math.pi / 2 + theta1_rad, -l1_m)  # r = -l1 (Table 3.3): joint 2 below joint 1 at theta_1 = 0
    return a01, a01 @ dh(math.pi / 2 + theta1_rad / gear, l2_m)


def run(seed: int = 0, quick: bool = False, params: PlantParams | None = None) -> BenchResult:
    """The report's DH chain and the belt drive's over the range of motion; the plant's potential checked."""
    del seed, quick  # deterministic
    p = params if params is not None else load_plant_params()
    gear, l1, l2 = p.belt_ratio, CENTRE_DISTANCE_M, p.toe_lever_m
    ankle = np.radians(np.arange(math.degrees(p.stop_min_rad), math.degrees(p.stop_max_rad) + 1e-9, 1.0))
    rows = []
    for th in ankle:
        theta1 = gear * th  # the input pulley turns G times the ankle
        t01, t02 = report_chain(theta1, gear, l1, l2)
        foot_angle = math.atan2(t02[1, 0], t02[0, 0])
        # the belt drive: ankle fixed at (0, -l1) below the input pulley, the foot along 180 deg + theta
        # (the report's chain's direction at theta_1 = 0), the toe l2 along it
        toe = np.array([-l2 * math.cos(th), -l1 - l2 * math.sin(th)])
        z_com = -p.foot_com_distance_m * math.cos(th + p.com_angle_at_zero_rad)
        energy = Plant(p, initial_angle_rad=float(th)).energy_j(0.0)
        rows.append((th, t01[0, 3], t01[1, 3], t02[0, 3], t02[1, 3], foot_angle, toe[0], toe[1], z_com, energy))
    a = np.array(rows)
    th0 = a[np.argmin(np.abs(a[:, 0]))]
    axis_travel = float(np.max(np.hypot(a[:, 1] - th0[1], a[:, 2] - th0[2])))
    unwrapped = np.unwrap(a[:, 5])
    turn_ratio = float(np.polyfit(a[:, 0], unwrapped, 1)[0])
    toe_err = float(np.max(np.hypot(a[:, 3] - a[:, 6], a[:, 4] - a[:, 7])))
    mgz = p.gravity_moment_nm / p.foot_com_distance_m * a[:, 8]
    potential_err = float(np.max(np.abs(a[:, 9] - mgz))) if p.foot_com_distance_m else 0.0
    geometry = geometry_of(p)
    pred = "predicted"
    lever = f"assumed: l1 = {l1 * 1000:g} mm (3.2.2 centre distance), l2 = toe lever {l2:g} m (plant profile)"
    figures = [
        Figure("report's chain: ankle-axis travel over the range of motion", "m", f"0 for a belt drive ({SECTION})",
               0.0, axis_travel, f"theta_1 = G theta over {math.degrees(p.stop_min_rad):.0f}..."
               f"{math.degrees(p.stop_max_rad):.0f} deg: the chain moves joint 2 with joint 1", basis=lever),
        Figure("report's chain: foot rotation per ankle rotation", "-", f"1 ({SECTION}, eq 3.78)", 1.0, turn_ratio,
               f"1 + G = {1 + gear:.3f}: T_02 adds theta_1 to theta_1 / G", basis=pred),
        Figure("report's chain vs belt drive: largest toe-position difference", "m", f"0 ({SECTION})", 0.0, toe_err,
               "over the range of motion", basis=lever),
        Figure(f"belt-drive chain vs plant potential energy ({geometry})", "J", "m g z_com (3.5.6, eq 3.48)", 0.0,
               potential_err, "plant energy at rest against m g z of the chain's centre of mass: the plant's geometry "
               "is the chain's", basis=pred),
        Figure(f"centre of mass height at 0 deg ({geometry})", "m", "-d (eq 3.48: hanging)",
               -p.foot_com_distance_m, float(th0[8]), "0 with the COM level (the profile), -d hanging",
               basis=pred),
    ]

    def plot(fig: object) -> None:
        ax1, ax2 = fig.subplots(1, 2)  # type: ignore[attr-defined]
        ax1.plot(a[:, 3], a[:, 4], label="report's DH chain: toe")
        ax1.plot(a[:, 1], a[:, 2], label="report's DH chain: joint 2 (ankle)")
        ax1.plot(a[:, 6], a[:, 7], label="belt drive: toe")
        ax1.plot([0.0], [-l1], "k+", label="belt drive: ankle axis")
        ax1.set(xlabel="x [m]", ylabel="y [m]", title=f"Toe over {math.degrees(p.stop_min_rad):.0f}..."
                f"{math.degrees(p.stop_max_rad):.0f} deg at the ankle")
        ax1.set_aspect("equal", adjustable="datalim")
        ax1.legend(fontsize=7)
        ax2.plot(np.degrees(a[:, 0]), a[:, 9], label="plant energy at rest")
        ax2.plot(np.degrees(a[:, 0]), mgz, ls="--", label="m g z_com (chain)")
        ax2.set(xlabel="ankle angle [deg]", ylabel="potential [J]", title=f"geometry: {geometry}")
        ax2.legend(fontsize=7)

    names = ("ankle_rad", "dh_joint2_x_m", "dh_joint2_y_m", "dh_toe_x_m", "dh_toe_y_m", "dh_foot_angle_rad",
             "belt_toe_x_m", "belt_toe_y_m", "com_z_m", "plant_energy_j")
    return BenchResult("kinematics", figures, {n: a[:, k] for k, n in enumerate(names)}, plot,
                       {"l1_m": l1, "l2_m": l2, "gear": gear, "geometry": geometry, "axis_travel_m": axis_travel,
                        "turn_ratio": turn_ratio, "toe_error_m": toe_err, "potential_error_j": potential_err})

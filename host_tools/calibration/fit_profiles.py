"""`pafp fit`'s profiles: the backlash's and the rotor side's (Kt/J_m), the two parameters whose residuals move in
steps (each reversal's crossing ends on a whole command period) that a secant Jacobian sees as jumps; each is found on
a grid of the cost instead (docs/calibration.md, Backlash, The rotor side, by its profile)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hal.virtual.plant import PlantParams
from host_tools.calibration.fit_consider import Solution, moved_solution
from host_tools.calibration.fit_data import Experiment
from host_tools.calibration.fit_model import PARAMS, residuals, rotor_side_sd

__all__ = ["BACKLASH_ABS_CI_DEG", "RotorProfile", "backlash_profile", "backlash_valley", "cost_unit", "parabola_vertex",
           "rotor_profile"]

BACKLASH_ABS_CI_DEG = 0.5  # the backlash is identified when its profile's 95 % half-width is at most this
LEVEL_95 = 0.5 * 3.841  # a profile's 95 % interval: its cost within chi-square(1)'s 95 % quantile / 2 (in `cost_unit`s)


ROTOR_STEP = 0.05  # the rotor side's profile grid (relative Kt/J_m)
ROTOR_POINTS = 9  # at most this many profile points (the base's, 1.0, included)


def cost_unit(r: np.ndarray, n: int) -> float:
    """One unit of chi-square in the least-squares cost (0.5 sum r^2) at residuals r with n parameters: the residual
    variance, inflated for the residuals' lag-1 correlation (m samples of AR(1) residuals carry m (1 - rho) /
    (1 + rho) of information), as the Jacobian's intervals are."""
    m = len(r)
    s2 = float(np.dot(r, r)) / max(1, m - n)
    rho = float(np.clip(np.dot(r[1:], r[:-1]) / max(float(np.dot(r, r)), 1e-300), 0.0, 0.999))
    return s2 * (1.0 + rho) / (1.0 - rho)


def parabola_vertex(x: np.ndarray, y: np.ndarray) -> float:
    """The vertex of the parabola through three points (x ascending), within them; the middle one's x when it is
    not convex."""
    a, b, _ = np.polyfit(x, y, 2)
    return float(np.clip(-b / (2 * a), x[0], x[2])) if a > 0 else float(x[1])


@dataclass
class RotorProfile:
    """`rotor_profile`'s result: the rotor's Kt/J_m relative to the base's, its 95 % half-width, whether it is
    identified, the other parameters' values there, and their shift at the interval's farther-moving end (one
    vector over the solution's names)."""

    best: float
    half: float
    identified: bool
    values: dict[str, float]
    shift95: np.ndarray


def rotor_profile(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                   sol: Solution) -> RotorProfile:
    """The rotor's acceleration per ampere (Kt / J_m, relative to the base's) from the cost's profile over it.

    The rotor alone carries itself across the backlash at each reversal, so Kt/J_m shapes the current there, and
    the least squares cannot follow it: with the backlash it makes a narrow valley whose floor moves in steps (each
    crossing ends on a whole command period; docs/calibration.md, The rotor side). A profile can: at each point of a
    grid (ROTOR_STEP) the other parameters are the solution moved to that Kt/J_m (`moved_solution` from the
    base's solution: the backlash's valley searched, the others by a trust region on the solution's Jacobian). The
    tolerance table's spread (`rotor_side_sd`) is a prior: its penalty, in units of the cost's chi-square
    (`cost_unit`), is added, so a record that cannot tell the rotor side keeps about the base's. The grid walks
    from the base's on outwards while an end of it is within the interval (where the penalised cost is within the
    95 % quantile of chi-square(1) / 2 of its least), at most ROTOR_POINTS points. The best is the vertex of the
    parabola through the best point and its neighbours; the others there, and at the interval's ends, lie linearly
    between the grid's moved solutions. The interval's ends are where the cost crosses its level, linearly between
    points, and at least half a grid step from the best (the profile is sampled no finer). It is identified when
    the cost without the prior closes such an interval inside the grid. The others' shift to the interval's ends
    (the larger of the two, its sign with it) is what `fit_plant` carries into their intervals.
    """
    sd = rotor_side_sd(base)

    points = {0: (sol.r0, dict(v))}  # grid index -> (residuals, moved values)

    def add(k: int) -> bool:
        scale = 1.0 + k * ROTOR_STEP
        if k in points or not PARAMS["rotor_accel_scale"].lo <= scale <= PARAMS["rotor_accel_scale"].hi \
                or len(points) >= ROTOR_POINTS:
            return False
        moved = {"rotor_accel_scale": scale}
        w, r = moved_solution(sol, v, lambda w: residuals(base, {**w, **moved}, part, scales),
                               lambda w: backlash_valley(base, {**w, **moved}, part, scales))
        points[k] = (r, w)
        return True

    unit = cost_unit(sol.r0, len(sol.names))

    def penalised(k: int) -> float:
        return 0.5 * float(np.dot(points[k][0], points[k][0])) + 0.5 * unit * (k * ROTOR_STEP / sd) ** 2

    def within(k: int) -> bool:
        return penalised(k) - min(penalised(j) for j in points) <= LEVEL_95 * unit

    add(-1)
    add(1)
    # on outwards while an end of the grid is within the interval: first in the units of the base's residuals, then
    # of the best point's (the base's carry the misfit of a rotor side that is off)
    for _ in range(2):
        while True:
            ks = sorted(points)
            if not ((within(ks[0]) and add(ks[0] - 1)) or (within(ks[-1]) and add(ks[-1] + 1))):
                break
        unit = cost_unit(points[min(points, key=penalised)][0], len(sol.names))
    best = min(points, key=penalised)
    offset = best * ROTOR_STEP
    if best - 1 in points and best + 1 in points:
        offset = parabola_vertex(np.array([(best + d) * ROTOR_STEP for d in (-1, 0, 1)]),
                           np.array([penalised(best + d) for d in (-1, 0, 1)]))
    ks = sorted(points)
    grid = np.array([k * ROTOR_STEP for k in ks])
    along = np.array([[points[k][1][n] for n in sol.names] for k in ks])

    def at(x: float) -> dict[str, float]:  # the others along the grid's moved solutions, linearly between points
        return {**v, **{n: float(np.interp(x, grid, along[:, j])) for j, n in enumerate(sol.names)}}

    def data(k: int) -> float:
        return 0.5 * float(np.dot(points[k][0], points[k][0]))

    def end(step: int, cost=penalised) -> tuple[float, bool]:
        """Where `cost` crosses its interval's level on that side, linearly between points; False: not in the grid."""
        low = min(points, key=cost)
        level = cost(low) + LEVEL_95 * unit
        k = low
        while k + step in points and cost(k + step) <= level:
            k += step
        if k + step not in points:
            return k * ROTOR_STEP, False
        y0, y1 = cost(k), cost(k + step)
        return (k + step * (level - y0) / (y1 - y0)) * ROTOR_STEP, True

    (lower, _), (upper, _) = end(-1), end(1)
    # the profile is sampled every ROTOR_STEP: a best between samples is known to about half a step either way
    lower, upper = min(lower, offset - ROTOR_STEP / 2), max(upper, offset + ROTOR_STEP / 2)
    half = max(offset - lower, upper - offset)
    there = at(offset)
    ends = [np.array([at(x)[n] - there[n] for n in sol.names]) for x in (upper, lower)]
    shift95 = np.where(np.abs(ends[0]) >= np.abs(ends[1]), ends[0], ends[1])
    # identified when the data alone (the cost without the prior) close an interval inside the walked grid
    identified = end(-1, data)[1] and end(1, data)[1]
    return RotorProfile(1.0 + offset, half, bool(identified), there, shift95)


VALLEY_GRIDS = ((0.04, 4), (0.01, 4))  # `backlash_valley`'s grids: (step in deg, steps either side of the best)


def backlash_cost(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                   backlash_deg: float) -> float:
    """The least-squares cost with the backlash at `backlash_deg` and the other parameters held at v."""
    return 0.5 * float(np.sum(residuals(base, {**v, "backlash_deg": backlash_deg}, part, scales) ** 2))


def backlash_valley(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                     grids: tuple[tuple[float, int], ...] = VALLEY_GRIDS) -> float:
    """The backlash of least cost about v's, the other parameters held at v (a coarse-to-fine grid, then the vertex of
    the parabola through the finest grid's best and its neighbours).

    The backlash's valley is narrow: each reversal's crossing ends on a whole command period, and the measured
    current, which resolves the crossing's length, moves the cost in steps a few hundredths of a degree wide (on
    `--plant-seed 7`'s default experiment the cost doubles 0.06 deg from its floor). The least squares' secant step
    (BACKLASH_STEP_DEG) cannot follow it and stops on the valley's wall, where the current lag and the Coulomb
    friction make up for the crossings it times wrong (docs/calibration.md)."""
    def cost(b: float) -> float:
        return backlash_cost(base, v, part, scales, b)

    best = float(v["backlash_deg"])
    costs = {best: cost(best)}
    for step, points in grids:
        centre = best
        for k in range(-points, points + 1):
            b = round(centre + k * step, 6)
            if 0.0 < b <= PARAMS["backlash_deg"].hi and b not in costs:
                costs[b] = cost(b)
        best = min(costs, key=costs.__getitem__)
    # the parabola through the best and its neighbours on the finest grid: a best that rounding moves from one point to
    # the next where two cost the same moves the vertex little (a grid point is a step of 0.01 deg)
    step = grids[-1][0]
    near = [round(best + k * step, 6) for k in (-1, 0, 1)]
    if all(b in costs for b in near):
        return parabola_vertex(np.array(near), np.array([costs[b] for b in near]))
    return best


BACKLASH_GRID_DEG = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 5.0)


def backlash_profile(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float], n: int,
                      around: float | None = None) -> tuple[float, float, bool]:
    """(best backlash, 95 % half-width, identified) from the cost over a grid of backlash values, the other
    parameters held at `v` (a conditional profile: the others are fitted again at the best, not at each point).

    Backlash acts through a dead time at each reversal: the simulation error moves in steps as it grows, which
    a finite-difference Jacobian sees as zero or as a spurious slope; a scan over the whole range does not.
    The interval is where the cost stays within the 95 % quantile of chi-square(1) / 2, in units of the
    residual variance inflated for the residuals' lag-1 correlation (as the Jacobian's intervals); identified
    when that interval closes inside the grid and is no wider than BACKLASH_ABS_CI_DEG.
    """
    grid = np.array(BACKLASH_GRID_DEG if around is None else
                    sorted(set(np.clip(around + np.linspace(-0.5, 0.5, 11), 0.0, PARAMS["backlash_deg"].hi))))
    cost = np.array([backlash_cost(base, v, part, scales, float(b)) for b in grid])
    k = int(np.argmin(cost))
    threshold = LEVEL_95 * cost_unit(residuals(base, v, part, scales), n)
    best = float(grid[k])
    if 0 < k < len(grid) - 1:  # the parabola through the best and its neighbours
        best = parabola_vertex(grid[k - 1:k + 2], cost[k - 1:k + 2])
    inside = cost - cost[k] <= threshold
    lo_i, hi_i = k, k
    while lo_i > 0 and inside[lo_i - 1]:
        lo_i -= 1
    while hi_i < len(grid) - 1 and inside[hi_i + 1]:
        hi_i += 1
    closed = (lo_i > 0 or grid[0] == 0.0) and hi_i < len(grid) - 1
    lower = float(grid[lo_i - 1]) if lo_i > 0 else float(grid[0])  # the interval reaches the first point outside it
    upper = float(grid[hi_i + 1]) if hi_i < len(grid) - 1 else float(grid[-1])
    half = max(best - lower, upper - best)
    return best, half, bool(closed and half <= BACKLASH_ABS_CI_DEG)

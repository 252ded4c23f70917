"""`pafp fit`'s consider terms and moved solutions: what the record leaves unknown carried into the intervals.

A consider term is the shift of the least-squares solution (`plant_fit.fit_plant`'s) when something the fit takes as
given moves within what the record allows: the writes' arrival through serial mode (`timing_term`), the encoder's
count at the windows that start stuck (`stuck_starts_term`), each the mean outer product of the linear shifts over
seeded draws (`drawn_term`); the rotor side's (`fit_profiles.rotor_profile`) moves the solution by `moved_solution`
instead, which follows the residuals where they are not linear (docs/calibration.md)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hal.virtual.plant import PlantParams
from host_tools.calibration import fit_solver as solver
from host_tools.calibration.fit_data import Experiment
from host_tools.calibration.fit_model import encoder_step, residuals, stuck_starts

__all__ = ["Solution", "drawn_term", "linear_shift", "moved_solution", "stuck_starts_term", "timing_term"]

MOVED_NFEV = 20  # at most this many simulations per trust-region pass of `moved_solution` (two passes a point)
# their cost and relative step tolerance (`fit_solver`; the solution's own is SOLVER_TOL): a few thousandths of a
# half-width at most, so that the profile's points, and the solution taken between them, do not hang on the path
MOVED_TOL = 1e-6


@dataclass
class Solution:
    """What the consider terms reuse from the least-squares solution: its parameters, their secant Jacobian,
    (J'J)^-1, the residuals there and the bounds."""

    names: tuple[str, ...]
    jac: np.ndarray
    bread: np.ndarray
    r0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def linear_shift(sol: Solution, v: dict[str, float], fun) -> np.ndarray:
    """The linear shift -(J'J)^-1 J' (r_p(x) - r(x)) of the least-squares solution when the residuals become
    `fun`'s (`fun(values)`: the perturbed problem's residuals at those parameter values), kept within the bounds."""
    x = np.array([v[n] for n in sol.names])
    dr = fun(v) - sol.r0
    return np.clip(x - sol.bread @ (sol.jac.T @ dr), sol.lo, sol.hi) - x


def moved_solution(sol: Solution, start: dict[str, float], fun, valley=None) -> tuple[dict[str, float], np.ndarray]:
    """(the least-squares solution when the residuals become `fun`'s, found by few simulations; its residuals).

    A trust-region least squares (scipy's "trf", within the bounds, at most MOVED_NFEV simulations) over the
    solution's parameters but the backlash, on the solution's own secant Jacobian (not recomputed: a simulation a
    step), from `start`; then the backlash's valley on its grid (`valley(values)`: the backlash of least cost with
    the others at those values) and the same least squares again from there. On residuals linear in the parameters
    it is the least-squares solution; where they are not, each accepted step lowers the moved problem's cost, so it
    never ends where a Newton step on the solution's Jacobian alone would have taken it uphill. The backlash's
    column is made of steps (each reversal's crossing ends on a whole period): the valley's grid follows it, a
    secant step cannot.
    """
    free = [k for k, n in enumerate(sol.names) if n != "backlash_deg"]
    names = tuple(sol.names[k] for k in free)
    jac, lo, hi = sol.jac[:, free], sol.lo[free], sol.hi[free]

    def solve(w: dict[str, float]) -> tuple[dict[str, float], np.ndarray]:
        x0 = np.clip(np.array([w[n] for n in names]), lo, hi)
        res = solver.solve(lambda x: fun({**w, **{n: float(a) for n, a in zip(names, x, strict=True)}}), x0, lo, hi,
                           lambda x: jac, MOVED_NFEV, MOVED_TOL)
        return {**w, **{n: float(a) for n, a in zip(names, res.x, strict=True)}}, np.asarray(res.fun)

    w, r = dict(start), None
    if names:
        w, r = solve(w)
    if valley is not None and "backlash_deg" in sol.names:
        w["backlash_deg"] = valley(w)
        w, r = solve(w) if names else (w, None)
    return w, (fun(w) if r is None else r)


DRAWS = 16  # draws of each drawn consider term (`drawn_term`): its half-widths' part to about 18 % (sqrt(1/2K))
TIMING_SEED = 21  # the seeds of the draws: the same recording gives the same intervals
STUCK_SEED = 22


def drawn_term(sol: Solution, v: dict[str, float], draws) -> np.ndarray:
    """The covariance a consider term adds: the mean outer product of the least-squares solution's linear shift
    (`linear_shift`) over `draws`, residual functions each of one draw of what the record leaves unknown (the
    draws' mean included: the record cannot exclude it)."""
    out = np.zeros((len(sol.names), len(sol.names)))
    for fun in draws:
        shift = linear_shift(sol, v, fun)
        out += np.outer(shift, shift)
    return out / DRAWS


def timing_term(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
            sol: Solution) -> np.ndarray:
    """The covariance the writes' unknown arrival adds to the fitted parameters (zeros when the timing is exact).

    Through serial mode the record dates each write (a command and the request after it) at COMMAND_DELAY_S after
    its job, later when a late reply shows it (`fit_data._late_commands`), and bounds it only to a window
    (`fit_data.arrival_bounds`: about 0.6 ms through a pty) within which the link's per-frame delay is unknown.
    Each of DRAWS draws puts every write at an independent uniform point of its window (the least the record says):
    `drawn_term`.
    """
    if part.bounds is None or not np.any(part.bounds[:, 1] > part.bounds[:, 0]):
        return np.zeros((len(sol.names), len(sol.names)))
    rng = np.random.default_rng(TIMING_SEED)
    lo, hi = part.bounds[:, 0], part.bounds[:, 1]
    # writes whose windows overlap (a stall: each may have waited behind the one before) are one burst, late together
    burst = np.r_[0, np.cumsum(part.t_cmd[1:] + lo[1:] > np.maximum.accumulate(part.t_cmd + hi)[:-1])]
    drawn = [part.shifted(lo + rng.uniform(0.0, 1.0, int(burst[-1]) + 1)[burst] * (hi - lo)) for _ in range(DRAWS)]
    return drawn_term(sol, v, (lambda w, d=d: residuals(base, w, d, scales) for d in drawn))


def stuck_starts_term(base: PlantParams, v: dict[str, float], part: Experiment, scales: dict[str, float],
                  sol: Solution) -> np.ndarray:
    """The covariance the encoder's count at the windows that start stuck adds to the fitted parameters.

    A window that starts stuck (`fit_model.stuck_starts`) starts at its encoder reading, which places the foot only
    to its count (`fit_model.encoder_step`: 0.09 deg for 4000 counts a turn); where in it the foot sits moves the
    angle after the breakaway and, through gravity, the breakaway itself, by up to a count, and the record does not
    say where (docs/calibration.md, The encoder's count at a stuck start). Each of DRAWS draws starts every such
    window at an independent uniform point within a count about its reading: `drawn_term`. Zeros with no such window.
    """
    ks, q = stuck_starts(part), encoder_step(part)
    if not len(ks) or q <= 0.0:
        return np.zeros((len(sol.names), len(sol.names)))
    rng = np.random.default_rng(STUCK_SEED)
    drawn = []
    for _ in range(DRAWS):
        shift = np.zeros(len(part.t))
        shift[ks] = rng.uniform(-q / 2, q / 2, len(ks))
        drawn.append(replace(part, start_shift=shift))
    return drawn_term(sol, v, (lambda w, d=d: residuals(base, w, d, scales) for d in drawn))

"""`pafp fit`'s least squares, solved in each parameter's own scale.

scipy's trust-region least squares (``least_squares(method="trf")``) takes ``x_scale`` for its trust region, but
tests its step tolerance on the raw parameters: it stops when ``norm(dx) < xtol (xtol + norm(x))``. The fit's
parameters span six orders of magnitude (the current lag ~1e-3 s, its 95 % half-width ~1e-5 s; the gravity moment
~2 N m; an angle offset of degrees), so that test was met by a step of 0.8 half-widths of the current lag while the
others still moved: the solver stopped short in a narrow valley, and where it stopped depended on its path, which
rounding in the BLAS kernel moved (`OPENBLAS_CORETYPE=Haswell` against `Sandybridge`: up to 0.16 half-widths apart
on `--plant-seed 7`'s 10 s experiment; a Gauss-Newton step from where it stopped still lowered the cost by 4
chi-square units). Here
the solver sees each parameter divided by its scale (`scales`), so its step test, its trust region and its
Jacobian are all in the same relative units.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["SOLVER_TOL", "scales", "solve"]

# the relative change of the cost (in units of the noise scales) and of the scaled step below which the solver stops:
# 1e-8 of each parameter's scale is far below any interval (>= 1e-3 of its scale), and of the cost far below the
# 1.92 units an interval spans (the kernels' agreement:
# tests/benchmarks/test_bench_fit_coverage.py's test_fit_under_another_kernel)
SOLVER_TOL = 1e-8


def scales(x0: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Each parameter's scale: its start's size, at least a twentieth of its bounds' span."""
    return np.maximum(np.abs(x0), 0.05 * (hi - lo))


def solve(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, lo: np.ndarray, hi: np.ndarray,
          jac: Callable[[np.ndarray], np.ndarray], max_nfev: int, tol: float = SOLVER_TOL,
          scale: np.ndarray | None = None):  # type: ignore[no-untyped-def]
    """scipy's "trf" least squares of `fun` (residuals of the raw parameters) from x0 within [lo, hi], with the
    Jacobian `jac` (of the raw parameters), solved on the parameters divided by `scale` (default `scales`). Returns
    scipy's result with ``x`` (and ``jac``) back in the raw parameters."""
    from scipy.optimize import least_squares

    s = scales(x0, lo, hi) if scale is None else np.asarray(scale, dtype=float)
    res = least_squares(lambda z: fun(z * s), x0 / s, jac=lambda z: jac(z * s) * s, bounds=(lo / s, hi / s),
                        method="trf", ftol=tol, xtol=tol, max_nfev=max_nfev)
    res.x = np.clip(res.x * s, lo, hi)
    res.jac = res.jac / s
    return res

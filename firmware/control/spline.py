"""The periodic cubic spline of the gait curve, fitted with numpy (no scipy at run time).

The interpolating cubic that is C2 across every knot and across the period's end is unique, so these are
the coefficients scipy's ``CubicSpline(x, y, bc_type="periodic")`` computes (to rounding; a test compares
the two), in its layout: ``c[:, i]`` holds (a, b, c, d) of ``a dx^3 + b dx^2 + c dx + d`` on
``[x[i], x[i + 1])``, dx = t - x[i].

>>> import numpy as np
>>> x = np.linspace(0.0, 1.0, 9); y = np.sin(2 * np.pi * x); y[-1] = y[0]
>>> c = periodic_cubic_coefficients(x, y)
>>> c.shape, bool(np.allclose(evaluate(x, c, x[:-1]), y[:-1]))
((4, 8), True)
"""

from __future__ import annotations

import numpy as np

__all__ = ["evaluate", "periodic_cubic_coefficients"]


def periodic_cubic_coefficients(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Coefficients (4, n) of the periodic C2 cubic through (x[k], y[k]); needs y[-1] == y[0], x increasing."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = len(x) - 1  # intervals; the knots x[0] and x[n] are the same point of the period
    h = np.diff(x)
    slope = np.diff(y) / h
    # second derivatives m[0..n-1] (m[n] = m[0]): h[i-1] m[i-1] + 2 (h[i-1] + h[i]) m[i] + h[i] m[i+1]
    #   = 6 (slope[i] - slope[i-1]), indices modulo n
    a = np.zeros((n, n))
    rhs = np.empty(n)
    for i in range(n):
        hp, hn = h[i - 1], h[i]
        a[i, (i - 1) % n] += hp
        a[i, i] += 2.0 * (hp + hn)
        a[i, (i + 1) % n] += hn
        rhs[i] = 6.0 * (slope[i] - slope[i - 1])
    m = np.linalg.solve(a, rhs)
    m = np.append(m, m[0])
    return np.array([
        (m[1:] - m[:-1]) / (6.0 * h),
        m[:-1] / 2.0,
        slope - h * (2.0 * m[:-1] + m[1:]) / 6.0,
        y[:-1],
    ])


def evaluate(x: np.ndarray, c: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """The spline at t within [x[0], x[-1]] (a value at x[-1] uses the last piece)."""
    t = np.asarray(t, dtype=float)
    i = np.clip(np.searchsorted(x, t, side="right") - 1, 0, c.shape[1] - 1)
    dx = t - x[i]
    return ((c[0, i] * dx + c[1, i]) * dx + c[2, i]) * dx + c[3, i]

"""The plant's inner loop: fixed-step RK4 on (angle, velocity) with an exact first-order current lag.

Everything here works on plain floats in local variables (numpy on 2-element states is slower). The
torque terms arrive pre-divided by the output inertia, so the right-hand side is an acceleration.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Final

from mypy_extensions import mypyc_attr


class Coefficients:
    """Constants of one plant configuration; torques are divided by the output inertia (1/s^2 units).

    A plain class with float attributes (not a tuple): compiled, every field read is a C double.
    """

    def __init__(self, *, inv_j: float, kto: float, ks: float, c0: float, kd: float, mg: float, psi0: float,
                 lo: float, hi: float, kst: float, cst: float, tc: float, tsx: float, tau: float, ker: float,
                 bscale: float, ipk: float = math.inf, kp: float = 0.0, pe: float = 0.0, p2: bool = False,
                 kbo: float | None = None) -> None:
        """Store the constants (keyword arguments, in SI units divided by J where noted)."""
        self.inv_j = inv_j  # 1 / J_total [1/(kg m^2)]
        self.kto = kto  # ankle torque per ampere / J, driving (motor torque along the motion, or at rest)
        self.kbo = kto if kbo is None else kbo  # the same, backdriven (motor torque against the sliding motion)
        self.ks = ks  # spring stiffness term (-k_l / J), 0 without spring
        self.c0 = c0  # constant torque / J (spring preload -k_l*theta0)
        self.kd = kd  # viscous damping / J
        self.mg = mg  # gravity moment / J
        self.psi0 = psi0  # angle of the COM line from the downward vertical at theta = 0
        self.lo = lo  # plantarflexion stop [rad]
        self.hi = hi  # dorsiflexion stop [rad]
        self.kst = kst  # stop stiffness / J
        self.cst = cst  # stop damping / J
        self.tc = tc  # kinetic Coulomb friction / J
        self.tsx = tsx  # static friction / J
        self.tau = tau  # current-loop time constant [s]
        self.ker = ker  # back-EMF per output rad/s over R: Ke*N/R [A s/rad]
        self.bscale = bscale  # N / brake speed scale: tanh argument per output rad/s
        self.ipk = ipk  # peak current [A]: the voltage mode's target is clamped to it (current mode: before)
        self.kp = kp  # parallel spring stiffness / J; 0 without one
        self.pe = pe  # its engagement angle [rad]
        self.p2 = p2  # two-sided (else only theta > pe, the dorsiflexion side)
        # the opt-in imperfections' dynamics (hal/virtual/plant/imperfections.py), installed by the plant when one is
        # on; None (the default): the nominal functions below run unchanged
        self.imp_accel: Callable[[float, float, float, float, int, float, float], float] | None = None
        self.imp_integrate: Callable[..., tuple[float, float, float, int, float, float]] | None = None
        self.imp_energy: Callable[[float, float, float], float] | None = None  # the belt's energy beyond the rigid one
        # the friction's switchings at the instant they happen inside a step (`integrate_located`): `pafp fit`'s
        # model; False (every run): each takes effect at a step's end or start
        self.located = False


def parallel_spring(kp: float, pe: float, two: bool, th: float) -> float:
    """The parallel spring's k_p (theta - theta_e) / J where it is engaged, else 0 (subtracted from the acceleration).

    >>> parallel_spring(100.0, 0.1, False, 0.3), parallel_spring(100.0, 0.1, False, 0.0)
    (20.0, 0.0)
    >>> parallel_spring(100.0, 0.1, True, 0.0)
    -10.0
    """
    d = th - pe
    if d > 0.0 or (two and d < 0.0):
        return kp * d
    return 0.0


@mypyc_attr(free_list_len=1, acyclic=True)  # one made per input event: allocation from a free list, no GC
class Drive:
    """Motor-driver inputs, constant between input events."""

    def __init__(self, target_a: float, brake_a: float, v_over_r: float, emf: float = 0.0) -> None:
        """Store the driver inputs."""
        self.target_a = target_a  # commanded q-axis current (clamped to the peak current), or V/R (voltage mode)
        self.brake_a = brake_a  # regenerative brake current magnitude; 0 = current mode
        self.v_over_r = v_over_r  # bus voltage / R: the back-EMF current limit (inf when unpowered)
        # 1.0 in voltage mode (the voltage-amplifier reading): the back-EMF current ker*w comes off the target,
        # which is then the winding's steady current V/R - Ke N w / R; 0.0: the driver closes a current loop
        self.emf = emf


def static_accel(c: Coefficients, th: float, i: float, ext: float) -> float:
    """Acceleration at rest (omega = 0) without friction: decides sticking and breakaway."""
    a = c.kto * i + ext * c.inv_j + c.c0 + c.ks * th - c.mg * math.sin(th + c.psi0)
    if c.kp != 0.0:
        a -= parallel_spring(c.kp, c.pe, c.p2, th)
    if th > c.hi:
        a -= c.kst * (th - c.hi)
    elif th < c.lo:
        a -= c.kst * (th - c.lo)
    return a


def accel(c: Coefficients, th: float, w: float, i: float, ext: float, s: int, d: float = 0.0,
          dd: float = 0.0) -> float:
    """Acceleration of the ankle for angle, velocity, current, external torque, friction mode and the belt's stretch
    and its rate (0 with a rigid belt)."""
    if c.imp_accel is not None:
        return c.imp_accel(th, w, i, ext, s, d, dd)
    return nominal_accel(c, th, w, i, ext, s)


def nominal_accel(c: Coefficients, th: float, w: float, i: float, ext: float, s: int) -> float:
    """`accel` without the opt-in imperfections."""
    if s == 0:
        a = static_accel(c, th, i, ext)
        if -c.tsx <= a <= c.tsx:
            return 0.0
        return a - c.tc if a > 0 else a + c.tc
    kt = c.kbo if i * s < 0.0 else c.kto
    a = kt * i + ext * c.inv_j + c.c0 - c.tc * s + c.ks * th - c.mg * math.sin(th + c.psi0) - c.kd * w
    if c.kp != 0.0:
        a -= parallel_spring(c.kp, c.pe, c.p2, th)
    if th > c.hi:
        x = c.kst * (th - c.hi) + c.cst * w
        if x > 0.0:
            a -= x
    elif th < c.lo:
        x = c.kst * (th - c.lo) + c.cst * w
        if x < 0.0:
            a -= x
    return a


def lag_factors(h: float, tau: float) -> tuple[float, float]:
    """Decay factors of the current lag over half a step and a whole step h: (exp(-h/2/tau), exp(-h/tau))."""
    return math.exp(-(0.5 * h) / tau), math.exp(-h / tau)


def integrate(c: Coefficients, d: Drive, state: tuple[float, float, float, int, float, float], t_base: float,
              k_first: int, n: int, h: float, ea: float, eb: float, fn: Callable[[float], float] | None,
              exps: tuple[float, float]) -> tuple[float, float, float, int, float, float]:
    """Take n RK4 steps of size h; step j starts at t_base + (k_first + j) * h.

    state = (theta, omega, i_q, s, stretch, its rate) with s the friction mode: +1/-1 sliding that way, 0 stuck; the
    belt's stretch and rate pass through unchanged (0 with a rigid belt: hal/virtual/plant/belt.py integrates them).
    External torque is ea + eb * t, or fn(t) at the stage times when fn is given. exps is
    (exp(-h/2/tau), exp(-h/tau)) for this h, from :func:`lag_factors` (computed once for the grid step).
    With an opt-in imperfection on, its own integrator takes the steps (`Coefficients.imp_integrate`).
    """
    if c.imp_integrate is not None:
        return c.imp_integrate(d, state, t_base, k_first, n, h, ea, eb, fn, exps)
    if c.located:
        return integrate_located(c, d, state, t_base, k_first, n, h, ea, eb, fn, exps)
    th, w, i, s, bd, bdd = state
    inv_j, kto, kbo, ks, c0, kd, mg, psi0 = c.inv_j, c.kto, c.kbo, c.ks, c.c0, c.kd, c.mg, c.psi0
    lo, hi, kst, cst, tc, tsx, ker, bscale, ipk = c.lo, c.hi, c.kst, c.cst, c.tc, c.tsx, c.ker, c.bscale, c.ipk
    kp, pe, p2 = c.kp, c.pe, c.p2
    tgt, brake, vr, emf = d.target_a, d.brake_a, d.v_over_r, d.emf
    hh = 0.5 * h
    h6 = h / 6.0
    eh, e1 = exps
    timed = fn is not None or eb != 0.0
    x1 = x2 = x4 = ea * inv_j
    for kk in range(k_first, k_first + n):
        if timed:
            t = t_base + kk * h
            if fn is None:
                x1 = (ea + eb * t) * inv_j
                x2 = x1 + eb * hh * inv_j
                x4 = x1 + eb * h * inv_j
            else:
                x1 = fn(t) * inv_j
                x2 = fn(t + hh) * inv_j
                x4 = fn(t + h) * inv_j
        # motor driver: target (brake opposes rotation), back-EMF voltage limit, exact first-order lag
        tg = -brake * math.tanh(w * bscale) if brake else tgt
        if emf:
            tg -= emf * ker * w
            tg = ipk if tg > ipk else -ipk if tg < -ipk else tg
        lim = vr - ker * w
        if tg > lim:
            tg = lim
        else:
            lim -= vr + vr
            if tg < lim:
                tg = lim
        dev = i - tg
        i_m = tg + dev * eh
        i_e = tg + dev * e1
        if s == 0:  # stuck: stays until the static torque exceeds breakaway
            a = kto * i + x1 + c0 + ks * th - mg * math.sin(th + psi0)
            if kp != 0.0:
                a -= parallel_spring(kp, pe, p2, th)
            if th > hi:
                a -= kst * (th - hi)
            elif th < lo:
                a -= kst * (th - lo)
            if -tsx <= a <= tsx:
                i = i_e
                continue
            s = 1 if a > 0.0 else -1
        f = c0 - tc * s
        # the transmission's gain by power direction over the step (s fixed): backdriven where i opposes s
        u1 = (kbo if i * s < 0.0 else kto) * i + f + x1
        u2 = (kbo if i_m * s < 0.0 else kto) * i_m + f + x2
        u4 = (kbo if i_e * s < 0.0 else kto) * i_e + f + x4
        a1 = u1 + ks * th - mg * math.sin(th + psi0) - kd * w
        if kp != 0.0:
            a1 -= parallel_spring(kp, pe, p2, th)
        if th > hi:
            x = kst * (th - hi) + cst * w
            if x > 0.0:
                a1 -= x
        elif th < lo:
            x = kst * (th - lo) + cst * w
            if x < 0.0:
                a1 -= x
        th2 = th + hh * w
        w2 = w + hh * a1
        a2 = u2 + ks * th2 - mg * math.sin(th2 + psi0) - kd * w2
        if kp != 0.0:
            a2 -= parallel_spring(kp, pe, p2, th2)
        if th2 > hi:
            x = kst * (th2 - hi) + cst * w2
            if x > 0.0:
                a2 -= x
        elif th2 < lo:
            x = kst * (th2 - lo) + cst * w2
            if x < 0.0:
                a2 -= x
        th3 = th + hh * w2
        w3 = w + hh * a2
        a3 = u2 + ks * th3 - mg * math.sin(th3 + psi0) - kd * w3
        if kp != 0.0:
            a3 -= parallel_spring(kp, pe, p2, th3)
        if th3 > hi:
            x = kst * (th3 - hi) + cst * w3
            if x > 0.0:
                a3 -= x
        elif th3 < lo:
            x = kst * (th3 - lo) + cst * w3
            if x < 0.0:
                a3 -= x
        th4 = th + h * w3
        w4 = w + h * a3
        a4 = u4 + ks * th4 - mg * math.sin(th4 + psi0) - kd * w4
        if kp != 0.0:
            a4 -= parallel_spring(kp, pe, p2, th4)
        if th4 > hi:
            x = kst * (th4 - hi) + cst * w4
            if x > 0.0:
                a4 -= x
        elif th4 < lo:
            x = kst * (th4 - lo) + cst * w4
            if x < 0.0:
                a4 -= x
        th += h6 * (w + 2.0 * (w2 + w3) + w4)
        w += h6 * (a1 + 2.0 * (a2 + a3) + a4)
        i = i_e
        if w * s <= 0.0:  # velocity reached or crossed zero inside the step: stick or reverse
            a = kto * i + x4 + c0 + ks * th - mg * math.sin(th + psi0)
            if kp != 0.0:
                a -= parallel_spring(kp, pe, p2, th)
            if th > hi:
                a -= kst * (th - hi)
            elif th < lo:
                a -= kst * (th - lo)
            if -tsx <= a <= tsx:
                s = 0
                w = 0.0
            elif w != 0.0:
                s = 1 if w > 0.0 else -1
            else:
                s = 1 if a > 0.0 else -1
    return th, w, i, s, bd, bdd


MAX_SWITCHINGS: Final = 4  # a step's friction switchings located (`integrate_located`); beyond, the step's end rule


def integrate_located(c: Coefficients, d: Drive, state: tuple[float, float, float, int, float, float],
                      t_base: float, k_first: int, n: int, h: float, ea: float, eb: float,
                      fn: Callable[[float], float] | None,
                      exps: tuple[float, float]) -> tuple[float, float, float, int, float, float]:
    """`integrate` (rigid belt, no opt-in imperfection) with each friction switching placed where it happens
    inside a step: the instant the velocity reaches 0 (then stick or reverse) and the instant a stuck foot's
    torque passes the static friction (breakaway), each by linear interpolation over the step, the step finished
    from there in the new mode.

    `integrate` switches at the grid: a reversal keeps the old friction's sign to the end of its step, a breakaway
    waits for the next step's start. As a switching crosses a grid point the trajectory jumps (a reversal by up to
    2 T_c h / J in velocity, a breakaway by (T_s - T_c) h / J): a least squares on simulated outputs then sees a
    cost with steps in it (`pafp fit`, docs/calibration.md, "Rounding"). Located, the trajectory is continuous in
    the parameters. The bench's plant keeps `integrate` (every run's outputs unchanged)."""
    th, w, i, s, bd, bdd = state
    for kk in range(k_first, k_first + n):
        t = t_base + kk * h
        rem = h
        events = 0
        while rem > 0.0:
            if s == 0:  # stuck: until the torque passes the static friction
                tg = lag_target(c, d, 0.0)
                a0 = static_accel(c, th, i, _ext(t, ea, eb, fn))
                if a0 > c.tsx or a0 < -c.tsx:
                    s = 1 if a0 > 0.0 else -1
                    continue
                i_end = tg + (i - tg) * math.exp(-rem / c.tau)
                a1 = static_accel(c, th, i_end, _ext(t + rem, ea, eb, fn))
                if -c.tsx <= a1 <= c.tsx or events >= MAX_SWITCHINGS:
                    i = i_end
                    break
                dt = rem * (math.copysign(c.tsx, a1) - a0) / (a1 - a0)
                i = tg + (i - tg) * math.exp(-dt / c.tau)
                s = 1 if a1 > 0.0 else -1
            else:
                th1, w1, i1 = _rk4_sliding(c, d, th, w, i, s, t, rem, ea, eb, fn,
                                           exps if rem == h else lag_factors(rem, c.tau))
                if w1 * s > 0.0:
                    th, w, i = th1, w1, i1
                    break
                if events >= MAX_SWITCHINGS:  # as `integrate` decides at a step's end
                    th, w, i = th1, w1, i1
                    a = static_accel(c, th, i, _ext(t + rem, ea, eb, fn))
                    if -c.tsx <= a <= c.tsx:
                        s, w = 0, 0.0
                    else:
                        s = (1 if w > 0.0 else -1) if w != 0.0 else (1 if a > 0.0 else -1)
                    break
                # the velocity reaches 0 inside: where its line between the ends does, then stick or reverse there
                dt = rem * w / (w - w1) if w != w1 else 0.0
                th, _, i = _rk4_sliding(c, d, th, w, i, s, t, dt, ea, eb, fn, lag_factors(dt, c.tau))
                w = 0.0
                a = static_accel(c, th, i, _ext(t + dt, ea, eb, fn))
                s = 0 if -c.tsx <= a <= c.tsx else (1 if a > 0.0 else -1)
            t += dt
            rem -= dt
            events += 1
    return th, w, i, s, bd, bdd


def _ext(t: float, ea: float, eb: float, fn: Callable[[float], float] | None) -> float:
    """The external torque at t [N m]: fn(t), or ea + eb t."""
    return fn(t) if fn is not None else ea + eb * t


def _rk4_sliding(c: Coefficients, d: Drive, th: float, w: float, i: float, s: int, t: float, h: float, ea: float,
                 eb: float, fn: Callable[[float], float] | None,
                 exps: tuple[float, float]) -> tuple[float, float, float]:
    """(angle, velocity, current) after one RK4 step of h from t sliding in mode s (`integrate`'s step, the current
    lag exact towards the target held from the step's start; exps: `lag_factors` of h)."""
    tg = lag_target(c, d, w)
    i_m = tg + (i - tg) * exps[0]
    i_e = tg + (i - tg) * exps[1]
    hh = 0.5 * h
    a1 = nominal_accel(c, th, w, i, _ext(t, ea, eb, fn), s)
    th2, w2 = th + hh * w, w + hh * a1
    a2 = nominal_accel(c, th2, w2, i_m, _ext(t + hh, ea, eb, fn), s)
    th3, w3 = th + hh * w2, w + hh * a2
    a3 = nominal_accel(c, th3, w3, i_m, _ext(t + hh, ea, eb, fn), s)
    th4, w4 = th + h * w3, w + h * a3
    a4 = nominal_accel(c, th4, w4, i_e, _ext(t + h, ea, eb, fn), s)
    return (th + h / 6.0 * (w + 2.0 * (w2 + w3) + w4), w + h / 6.0 * (a1 + 2.0 * (a2 + a3) + a4), i_e)


def lag_target(c: Coefficients, d: Drive, w: float) -> float:
    """The current target held over a step that starts at velocity w: brake or command, back-EMF clamped.

    The same expression as inside :func:`integrate` (kept inline there for speed).
    """
    tg = -d.brake_a * math.tanh(w * c.bscale) if d.brake_a else d.target_a
    if d.emf:
        tg -= d.emf * c.ker * w
        tg = c.ipk if tg > c.ipk else -c.ipk if tg < -c.ipk else tg
    lim = d.v_over_r - c.ker * w
    if tg > lim:
        return lim
    lim -= d.v_over_r + d.v_over_r
    return lim if tg < lim else tg


def hermite(x0: tuple[float, float, float, int, float, float], x1: tuple[float, float, float, int, float, float],
            a0: float, a1: float, dt: float, h: float, target_a: float,
            tau: float) -> tuple[float, float, float, int, float, float]:
    """State h into a step of size dt from x0 to x1 (same friction mode), without integrating.

    Angle: cubic Hermite from (theta, omega) at both ends; velocity: cubic Hermite from (omega, alpha);
    current: the exact first-order lag towards target_a, the target held over the step; the belt's stretch: cubic
    Hermite from (stretch, rate), its rate linear.
    """
    th0, w0, i0, s, d0, dd0 = x0
    th1, w1, d1, dd1 = x1[0], x1[1], x1[4], x1[5]
    u = h / dt
    v = 1.0 - u
    h01 = u * u * (3.0 - 2.0 * u)
    h00 = 1.0 - h01
    h10 = u * v * v * dt
    h11 = -u * u * v * dt
    return (h00 * th0 + h10 * w0 + h01 * th1 + h11 * w1,
            h00 * w0 + h10 * a0 + h01 * w1 + h11 * a1,
            target_a + (i0 - target_a) * math.exp(-h / tau), s,
            h00 * d0 + h10 * dd0 + h01 * d1 + h11 * dd1, dd0 + u * (dd1 - dd0))

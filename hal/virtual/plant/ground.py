"""The ground reaction under the foot while walking: vertical force, fore-aft force and centre of pressure.

From the normative ground reaction force (firmware/data/grf_normative_all_speeds.csv, Schwartz et al.
2008, in body weights) times the walker's weight, on the walking load's stride clock: contact from heel
strike (0 % of the stride) to toe off (the load's ``toe_off_pct``, the source's mean foot-off), none in
swing. The averaged curve smears foot-off over subjects (0.14 body weights left at 59 %); the scenario's
foot leaves at once at the mean event, as the ankle moment of the walking load does.

The data has no centre of pressure. With the ankle moment of the same source (internal, positive =
plantarflexor) the sagittal moment balance of the foot about the ankle gives the CoP's distance ahead of
the ankle: ``x = (M + F_x h) / F_z`` with h the ankle's height above the floor (the foot's own weight and
inertia neglected), clamped to the sole (``heel_m`` .. ``toe_m``). Emulation truth: the sensors
(hal/virtual/devices/load_cell.py, fsr.py) turn it into voltages. docs/plant.md, "Ground reaction".
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

from hal.virtual.plant.walking import WalkingLoad

__all__ = ["G_M_S2", "GroundReaction", "NoGround"]

G_M_S2 = 9.81


class NoGround:
    """No ground under the foot (the suspended bench): zero force everywhere."""

    def at(self, t_s: float) -> tuple[float, float, float]:
        """(vertical force N, fore-aft force N, CoP m ahead of the ankle): all zero."""
        return 0.0, 0.0, 0.0


class GroundReaction:
    """The ground reaction of the walking scenario at a time (module docstring)."""

    def __init__(self, load: WalkingLoad, percent: Sequence[float], vertical_bw: Sequence[float],
                 fore_aft_bw: Sequence[float], ankle_height_m: float = 0.08, heel_m: float = -0.06,
                 toe_m: float = 0.18) -> None:
        """Bind the walking load (stride clock, mass, moment, toe off) and the force curves (body weights)."""
        p = [float(x) for x in percent]
        if len(p) < 2 or len(p) != len(vertical_bw) or len(p) != len(fore_aft_bw) \
                or any(b <= a for a, b in zip(p, p[1:], strict=False)) or p[0] != 0.0:
            raise ValueError("ground reaction curve: percent_gait must rise strictly from 0, one force pair per point")
        if not (0.0 <= ankle_height_m <= 0.3 and -0.3 <= heel_m < 0.0 < toe_m <= 0.4):
            raise ValueError(f"foot geometry out of range: ankle_height_m {ankle_height_m} in 0..0.3, "
                             f"heel_m {heel_m} in -0.3..0, toe_m {toe_m} in 0..0.4")
        self.load = load
        self.percent = p
        self.vertical_bw = [float(x) for x in vertical_bw]
        self.fore_aft_bw = [float(x) for x in fore_aft_bw]
        self.ankle_height_m = ankle_height_m
        self.heel_m = heel_m
        self.toe_m = toe_m
        self.weight_n = load.body_mass_kg * G_M_S2

    def percent_at(self, t_s: float) -> float | None:
        """Where in the stride t_s falls (0..100), None before the gait starts."""
        start = self.load.start_s()
        if start is None or t_s < start:
            return None
        return ((t_s - start) / self.load.stride_s % 1.0) * 100.0

    def at(self, t_s: float) -> tuple[float, float, float]:
        """(vertical force N, fore-aft force N (+ forward), CoP m ahead of the ankle) at t_s."""
        pct = self.percent_at(t_s)
        if pct is None or pct >= self.load.toe_off_pct:
            return 0.0, 0.0, 0.0
        p = self.percent
        k = min(max(bisect.bisect_right(p, pct), 1), len(p) - 1)  # one look-up for both curves
        a = min(1.0, (pct - p[k - 1]) / (p[k] - p[k - 1]))
        vz, vx = self.vertical_bw, self.fore_aft_bw
        fz = max(0.0, vz[k - 1] + a * (vz[k] - vz[k - 1])) * self.weight_n
        fx = (vx[k - 1] + a * (vx[k] - vx[k - 1])) * self.weight_n
        if fz <= 0.0:
            return 0.0, 0.0, 0.0
        moment = self.load.moment_nm(pct)
        cop = (moment + fx * self.ankle_height_m) / fz
        return fz, fx, min(self.toe_m, max(self.heel_m, cop))

    def true_events(self, t_end_s: float) -> tuple[list[float], list[float]]:
        """The scenario's heel strikes and toe offs up to t_end_s (emulation truth, for detection latency)."""
        start = self.load.start_s()
        if start is None:
            return [], []
        stride = self.load.stride_s
        n = max(0, math.floor((t_end_s - start) / stride) + 1)
        strikes = [start + k * stride for k in range(n) if start + k * stride <= t_end_s]
        offs = [start + (k + self.load.toe_off_pct / 100.0) * stride for k in range(n)]
        return strikes, [t for t in offs if t <= t_end_s]

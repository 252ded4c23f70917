"""The walking load: the ground's moment on the foot in stance, scaled to a body mass, on the gait clock.

In stance the ground pushes the foot towards dorsiflexion with the moment the ankle must carry; the
net ankle moment of normative gait (inverse dynamics, N m per kg of body mass, positive = plantarflexor)
times the body mass is that moment. It acts from heel strike (0 % of the stride) to toe off
(``toe_off_pct``) and is zero in swing. The stride clock starts when the firmware's gait starts
(``bind``): the person walks with the gait the prosthesis plays. Model, assumptions and sources:
docs/plant.md, "Walking".
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence

from hal.virtual.plant.fixtures import Fixture, FixtureKind

__all__ = ["WalkingLoad", "walk"]

#: Allowed body masses, kg.
BODY_MASS_RANGE_KG = (20.0, 200.0)


class WalkingLoad:
    """External torque at the ankle [N m, positive = dorsiflexing] as a function of simulated time."""

    def __init__(self, percent: Sequence[float], moment_nm_per_kg: Sequence[float], body_mass_kg: float,
                 stride_s: float, toe_off_pct: float = 59.0) -> None:
        """Check and keep the curve (percent 0..100 increasing), the mass, the stride and toe off."""
        lo, hi = BODY_MASS_RANGE_KG
        if not (isinstance(body_mass_kg, (int, float)) and lo <= body_mass_kg <= hi):
            raise ValueError(f"body mass {body_mass_kg!r} kg out of range: {lo:g}..{hi:g} kg")
        if not (isinstance(stride_s, (int, float)) and 0.3 <= stride_s <= 5.0):
            raise ValueError(f"stride_s {stride_s!r} out of range: 0.3..5 s")
        if not 0.0 < toe_off_pct < 100.0:
            raise ValueError(f"toe_off_pct {toe_off_pct!r} out of range: (0, 100) %")
        p, m = [float(x) for x in percent], [float(x) for x in moment_nm_per_kg]
        if len(p) < 2 or len(p) != len(m) or any(b <= a for a, b in zip(p, p[1:], strict=False)) \
                or p[0] != 0.0 or p[-1] > 100.0 or not all(math.isfinite(x) for x in p + m):
            raise ValueError("moment curve: percent_gait must rise strictly from 0 to at most 100, one finite "
                             "moment per point")
        self.percent, self.moment_nm_per_kg = p, m
        self.body_mass_kg = float(body_mass_kg)
        self.stride_s = float(stride_s)
        self.toe_off_pct = float(toe_off_pct)
        self._start: Callable[[], float | None] = lambda: None

    def bind(self, gait_start_s: Callable[[], float | None]) -> None:
        """Take the stride clock from gait_start_s() (None until the gait has a start time)."""
        self._start = gait_start_s

    def start_s(self) -> float | None:
        """When the first stride began (None until the gait has a start time)."""
        return self._start()

    def moment_nm(self, percent: float) -> float:
        """The ankle moment the stride demands at percent of the stride (0 in swing)."""
        if percent >= self.toe_off_pct:
            return 0.0
        p, m = self.percent, self.moment_nm_per_kg
        k = bisect.bisect_right(p, percent)
        if k >= len(p):
            return m[-1] * self.body_mass_kg
        a = (percent - p[k - 1]) / (p[k] - p[k - 1])
        return (m[k - 1] + a * (m[k] - m[k - 1])) * self.body_mass_kg

    def stance(self, t_s: float) -> bool:
        """True while the foot is on the ground at t_s (after the gait started)."""
        start = self._start()
        return start is not None and t_s >= start and ((t_s - start) / self.stride_s % 1.0) * 100 < self.toe_off_pct

    def __call__(self, t_s: float) -> float:
        """External torque at t_s: + the demanded moment in stance (the ground dorsiflexes the foot)."""
        start = self._start()
        if start is None or t_s < start:
            return 0.0
        return self.moment_nm(((t_s - start) / self.stride_s % 1.0) * 100.0)


def walk(load: WalkingLoad) -> Fixture:
    """The foot on the walking load: powered, the ground's moment as the external torque at the ankle."""
    return Fixture(FixtureKind.WALK, torque_nm=load)

"""The gearbox's backlash as `pafp fit` simulates it: the plant's own `Gap`, with the end of each crossing blended
across the command period it ends near, so that the fit's cost is continuous in the parameters.

The bench's plant (hal/virtual/plant/model.py, ``Plant._cross_gap``) frees the rotor at a reversal of the command
and passes the command on to the output at the first command after the rotor has crossed: the torque's onset sits
on the command grid. The fit's cost is then a staircase in the backlash and the rotor side: flat (no slope to
follow) with steps where a crossing's end passes a command, the output's torque and one reply's mean current moving
by a whole period's worth. Along the backlash on 2 s of the hand-made plant's 10 s recording (0.005 deg steps, the
others at the truth) it was flat from 1.42 to 1.50 deg with steps of 2-5 units between; with the blend it is
continuous, least within 0.02 deg of the true 1.50. Such steps left the least squares on one side or the other as
the BLAS kernel's rounding took it (the hand-made plant's current lag 0.37 half-widths apart between two kernels).

Here the plant runs without backlash and the fit passes it the share of each command that reaches the output
(`GapShare.share`): the plant's own rule (0 while the rotor is free, the whole command once it has crossed), except
within ``band`` of the command nearest the crossing's end, where the share goes linearly from 1 (ended ``band``
before the command) through 1/2 (ended at it) to 0 (ends ``band`` after it); a crossing that ends on the side opposite
to the command (the output running ahead of the rotor) passes nothing either side of the command, the plant's next
command freeing the rotor again. The blend is symmetric about the
plant's rule, so it adds no lead or lag on average; outside it the fit's simulation is the plant's.
"""

from __future__ import annotations

import math

from hal.virtual.plant import PlantParams
from hal.virtual.plant.gap import Gap

__all__ = ["GAP_BLEND", "GapShare", "reach_time"]

# the blend's half-width as a share of the command period: a crossing that ends within it of a command is blended (half
# of them: a quarter period either side of each command), the others are the plant's own; the cost's step of a whole
# period's torque becomes a ramp half a period wide
GAP_BLEND = 0.25


def reach_time(phi: float, w: float, a: float, half: float) -> float:
    """The first time s >= 0 at which phi + w s + a s^2 / 2 reaches +-half moving outwards (inf: never); 0 for a
    rotor at an end pushed into it.

    >>> round(reach_time(-1.0, 0.0, 2.0, 1.0) ** 2, 9)  # across 2 at 2 per second squared: sqrt(2) s
    2.0
    >>> reach_time(0.0, 1.0, 0.0, 1.0), abs(reach_time(1.0, 0.0, 2.0, 1.0)), reach_time(-1.0, 1.0, -1.0, 1.0)
    (1.0, 0.0, 2.0)
    """
    best = math.inf
    for end in (half, -half):
        c = phi - end
        if a == 0.0:
            roots: tuple[float, ...] = (-c / w,) if w != 0.0 else ()
        else:
            disc = w * w - 2.0 * a * c
            if disc < 0.0:
                continue
            q = -0.5 * (w + math.copysign(math.sqrt(disc), w if w != 0.0 else 1.0))
            roots = (q / (0.5 * a), c / q if q != 0.0 else math.inf)
        for s in roots:
            speed = w + a * s
            if 0.0 <= s < best and (speed if speed != 0.0 else a) * end > 0.0:
                best = s
    return best


class GapShare:
    """The rotor in the backlash of a plant run without it: for each command, the share that reaches the output."""

    def __init__(self, params: PlantParams, backlash_rad: float, start_time_s: float, band_s: float) -> None:
        """The gap of `backlash_rad` at the gearbox's output, as `Plant` builds it, from start_time_s; the blend's
        half-width band_s (> 0)."""
        self.gap = Gap(0.5 * backlash_rad * params.gearbox_ratio, start_time_s,
                       params.kt_nm_per_a / params.rotor_inertia_kg_m2, params.total_ratio)
        self.band = band_s

    def share(self, t_s: float, command_a: float, output_accel_rad_s2: float) -> float:
        """Take the command (clamped, as the plant clamps it) at t_s, the output accelerating at
        output_accel_rad_s2 then: the share of it the output sees until the next command (0..1)."""
        gap = self.gap
        was_free = gap.free
        ended = gap.t + reach_time(gap.phi, gap.w, gap.a, gap.half) if was_free else math.inf
        if gap.command(t_s, (command_a > 0.0) - (command_a < 0.0)):
            gap.free_under(command_a, output_accel_rad_s2)
            # until this crossing ends, the command held; none when it ends on the side opposite to the command
            # (pushed back against the side it left, or at once into the one it is at): the plant's next command
            # frees it again, so nothing passes, however close to this command it ends
            left = reach_time(gap.phi, gap.w, gap.a, gap.half)
            if left >= self.band or (gap.phi + (gap.w + 0.5 * gap.a * left) * left) * command_a <= 0.0:
                return 0.0
            return 0.5 - 0.5 * left / self.band
        if not was_free:
            return 1.0
        # the crossing ended since the last command: how long before this one (0 where rounding puts it after)
        since = max(0.0, t_s - ended) if math.isfinite(ended) else 0.0
        return 0.5 + 0.5 * since / self.band if since < self.band else 1.0

    def angle(self, t_s: float) -> float:
        """The rotor's place in the gap at t_s (rad at the rotor, relative to N x the output's)."""
        return self.gap.motion(t_s)[0]

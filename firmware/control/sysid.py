"""The identification experiment: a controller whose commands make the plant's parameters identifiable.

Segments, in order (durations and amplitudes from the profile's ``[controller]`` table, defaults for the
AK60-6 bench; docs/calibration.md gives the reasoning):

1. ``hold_s`` at the centre of the range: the foot still, so the IMU's pitch minus the encoder's angle is
   the IMU's bias (and the encoder's offset against gravity);
2. a slow triangle sweep, ``sweep_deg`` either side of the centre at ``sweep_deg_s``: quasi-static, so the
   current needed is the gravity moment (its cos shape over the angle) plus Coulomb friction (its sign
   flips with the direction: the difference of the two passes); the reversals at the ends excite the
   static friction and the gearbox's backlash;
3. a logarithmic chirp in current, ``chirp_a`` amplitude from ``chirp_f0_hz`` to ``chirp_f1_hz`` over
   ``chirp_s``, added to the position hold: its low frequencies see the stiffness of the hold, the high
   ones the inertia; the phase between current command and measured current is the driver's lag;
4. a PRBS in current, ``prbs_a`` with a bit every ``prbs_bit_s`` (seeded by ``seed``): broadband, for
   the damping and a second look at inertia and friction;
5. ``hold_s`` again (the IMU's bias drift over the experiment).

A PD position hold (``kp_a_per_rad``, ``kd_a_s_per_rad``) carries the foot's weight under every segment;
the angle stays within ``margin_deg`` of the firmware's safety limits (a guard adds a restoring current
towards the centre beyond that) and the current within ``current_fraction`` of the firmware's current
limit. The supervisor stays active: a limit crossed still latches the safe state.
"""

from __future__ import annotations

import math
from typing import Any

from firmware.config import FirmwareConfig

__all__ = ["DEFAULTS", "SysidExperiment", "sysid_from_config"]

DEFAULTS: dict[str, float] = {
    "hold_s": 2.0, "sweep_deg": 18.0, "sweep_deg_s": 9.0, "chirp_a": 1.2, "chirp_f0_hz": 0.3, "chirp_f1_hz": 12.0,
    "chirp_s": 10.0, "prbs_a": 1.0, "prbs_bit_s": 0.03, "prbs_s": 4.0, "kp_a_per_rad": 25.0,
    "kd_a_s_per_rad": 0.6, "margin_deg": 5.0, "current_fraction": 0.6, "centre_deg": 2.0, "seed": 0,
}
_RANGES: dict[str, tuple[float, float]] = {
    "hold_s": (0.2, 60.0), "sweep_deg": (1.0, 40.0), "sweep_deg_s": (0.5, 60.0), "chirp_a": (0.0, 10.0),
    "chirp_f0_hz": (0.05, 50.0), "chirp_f1_hz": (0.1, 100.0), "chirp_s": (0.0, 120.0), "prbs_a": (0.0, 10.0),
    "prbs_bit_s": (0.002, 1.0), "prbs_s": (0.0, 120.0), "kp_a_per_rad": (0.0, 500.0), "kd_a_s_per_rad": (0.0, 20.0),
    "margin_deg": (0.0, 30.0), "current_fraction": (0.05, 1.0), "centre_deg": (-30.0, 30.0), "seed": (0, 2**32 - 1),
}


class SysidExperiment:
    """The experiment as a controller (``pafp run --experiment sysid``, or ``[controller] name = "sysid"``)."""

    cost_cycles = 2500  # a few multiplies and one sine per period on the target

    def __init__(self, params: dict[str, Any], angle_min_rad: float, angle_max_rad: float,
                 current_limit_a: float) -> None:
        """Check every parameter (ValueError naming it and its range) and lay out the segments."""
        unknown = sorted(set(params) - set(DEFAULTS))
        if unknown:
            raise ValueError(f"controller sysid: unknown parameter {unknown[0]!r}: its parameters are "
                             f"{', '.join(DEFAULTS)}")
        p = {**DEFAULTS, **params}
        for name, (lo, hi) in _RANGES.items():
            v = p[name]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
                raise ValueError(f"controller sysid: {name} = {v!r} out of range [{lo}, {hi}]")
        if p["chirp_f1_hz"] <= p["chirp_f0_hz"]:
            raise ValueError(f"controller sysid: chirp_f1_hz = {p['chirp_f1_hz']} out of range: above chirp_f0_hz "
                             f"= {p['chirp_f0_hz']}")
        self.p = p
        margin = math.radians(p["margin_deg"])
        self.lo, self.hi = angle_min_rad + margin, angle_max_rad - margin
        self.centre = math.radians(p["centre_deg"])
        sweep = math.radians(p["sweep_deg"])
        if self.centre - sweep < self.lo or self.centre + sweep > self.hi:
            raise ValueError(f"controller sysid: centre_deg ± sweep_deg = {p['centre_deg']} ± {p['sweep_deg']} leaves "
                             f"the range of motion less the margin [{math.degrees(self.lo):.1f}, "
                             f"{math.degrees(self.hi):.1f}] deg")
        self.sweep = sweep
        self.limit = p["current_fraction"] * current_limit_a
        rate = math.radians(p["sweep_deg_s"])
        self.sweep_s = 4.0 * sweep / rate
        self.rate = rate
        self.bounds = []  # segment end times, relative to the start
        t = 0.0
        for name, length in (("hold", p["hold_s"]), ("sweep", self.sweep_s), ("chirp", p["chirp_s"]),
                             ("prbs", p["prbs_s"]), ("hold_end", p["hold_s"])):
            t += length
            self.bounds.append((name, t))
        self.duration_s = t
        self._prbs_state = (int(p["seed"]) * 2654435761 + 1) & 0x7FFFFFFF or 1
        self._prbs_bit = 0
        self._prbs_value = 1.0
        self._t0: float | None = None
        self._zero = 0.0  # the fused angle minus the encoder's at the start (set at the first update)
        self.published = {"sysid_segment": 0.0, "sysid_target_deg": 0.0, "sysid_excitation_a": 0.0}

    def reset(self) -> None:
        """The experiment starts over at the next update (the supervisor entered RUN or SAFE)."""
        self._t0 = None
        self._prbs_bit = 0

    def segment(self, t: float) -> tuple[int, str, float]:
        """(index, name, time into it) of the segment at t seconds from the start; past the end: the last hold."""
        start = 0.0
        for i, (name, end) in enumerate(self.bounds):
            if t < end:
                return i, name, t - start
            start = end
        return len(self.bounds) - 1, self.bounds[-1][0], t - start

    def _prbs(self, k: int) -> float:
        """The PRBS value of bit k (a 31-bit LCG's top bit, advanced bit by bit: the same seed, the same sequence)."""
        while self._prbs_bit <= k:
            self._prbs_state = (1103515245 * self._prbs_state + 12345) & 0x7FFFFFFF
            self._prbs_value = 1.0 if self._prbs_state & 0x40000000 else -1.0
            self._prbs_bit += 1
        return self._prbs_value

    def target_and_excitation(self, t: float) -> tuple[float, float]:
        """The position held (rad) and the current added on top (A) at t seconds from the start."""
        p = self.p
        i, name, u = self.segment(t)
        if name == "sweep":  # centre -> +sweep -> -sweep -> centre, at the constant rate
            d = self.rate * u
            s = self.sweep
            off = d if d < s else 2 * s - d if d < 3 * s else d - 4 * s
            return self.centre + off, 0.0
        if name == "chirp":
            f0, f1, T = p["chirp_f0_hz"], p["chirp_f1_hz"], p["chirp_s"]
            k = math.log(f1 / f0) / T
            phase = 2 * math.pi * f0 * (math.exp(k * u) - 1.0) / k
            return self.centre, p["chirp_a"] * math.sin(phase)
        if name == "prbs":
            return self.centre, p["prbs_a"] * self._prbs(int(u / p["prbs_bit_s"]))
        return self.centre, 0.0

    def update(self, obs: Any) -> float:
        """The current command for this period: PD hold on the target plus the excitation, guarded."""
        if self._t0 is None:
            self._t0 = obs.t_s
            # the incremental encoder reads 0 wherever the foot was at power-up, which should be its zero mark
            # (within a degree or two, by eye). A foot further off than the margin (it hung on its stop before
            # the run, as the emulated serial bench's does) would sweep into the stop: its zero is then taken
            # from the fused angle, absolute through the IMU, once -- the targets and the guard become absolute
            # as the [safety] limits are, and the hold stays on the encoder's counts
            zero = obs.angle_rad - obs.encoder_angle_rad
            self._zero = zero if abs(zero) > math.radians(self.p["margin_deg"]) else 0.0
        t = obs.t_s - self._t0
        target, excitation = self.target_and_excitation(t)
        angle = obs.encoder_angle_rad + self._zero
        p = self.p
        current = p["kp_a_per_rad"] * (target - angle) - p["kd_a_s_per_rad"] * obs.velocity_rad_s + excitation
        if angle > self.hi:  # the guard: beyond the margin, push back towards the centre, no excitation
            current = min(current - excitation, -p["kp_a_per_rad"] * (angle - self.hi))
        elif angle < self.lo:
            current = max(current - excitation, p["kp_a_per_rad"] * (self.lo - angle))
        current = max(-self.limit, min(self.limit, current))
        pub = self.published
        pub["sysid_segment"] = float(self.segment(t)[0])
        pub["sysid_target_deg"] = math.degrees(target)
        pub["sysid_excitation_a"] = excitation
        return current


def sysid_from_config(config: FirmwareConfig, params: dict[str, Any]) -> SysidExperiment:
    """The experiment within the firmware profile's safety limits and current limit."""
    s = config.safety
    return SysidExperiment(params, s.angle_min_rad, s.angle_max_rad, config.current_limit_a)

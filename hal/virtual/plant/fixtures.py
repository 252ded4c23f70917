"""Bench fixtures of the plant (suspended, spring bench, backdrive, impulse) and time profiles of loads."""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import Enum

#: A load given as a function of simulated time in seconds.
TimeFunction = Callable[[float], float]


class FixtureKind(Enum):
    """Which bench the prosthesis is mounted on."""

    SUSPENDED = "suspended"  # shank clamped vertical, foot free under gravity
    SPRING_BENCH = "spring_bench"  # foot loaded by the report's spring (and a hanging mass)
    BACKDRIVE = "backdrive"  # motor unpowered, a force pushes at the toe
    IMPULSE = "impulse"  # suspended foot hit by a short torque pulse (pneumatic push)
    WALK = "walk"  # the ground's moment in stance (hal/virtual/plant/walking.py)


@dataclass(frozen=True)
class TorqueProfile:
    """Piecewise-linear function of time given by (t_s, value) points; repeat a time for a step."""

    points: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        """Check that the points are finite and their times non-decreasing."""
        if not self.points:
            raise ValueError("TorqueProfile needs at least one (t_s, value) point, got none")
        previous = -math.inf
        for t_s, value in self.points:
            if not (math.isfinite(t_s) and math.isfinite(value)):
                raise ValueError(f"TorqueProfile point ({t_s!r}, {value!r}) must be finite")
            if t_s < previous:
                raise ValueError(f"TorqueProfile times must be non-decreasing: {t_s!r} after {previous!r}")
            previous = t_s
        object.__setattr__(self, "_times", tuple(p[0] for p in self.points))

    @classmethod
    def from_points(cls, points: Sequence[Sequence[float]]) -> TorqueProfile:
        """Build a profile from any sequence of (t_s, value) pairs."""
        return cls(tuple((float(t), float(v)) for t, v in points))

    @classmethod
    def pulse(cls, amplitude: float, start_s: float, duration_s: float) -> TorqueProfile:
        """A rectangular pulse of ``amplitude`` on [start_s, start_s + duration_s), zero elsewhere."""
        if not duration_s > 0:
            raise ValueError(f"pulse duration_s = {duration_s!r} must be > 0")
        end_s = start_s + duration_s
        return cls(((start_s, 0.0), (start_s, amplitude), (end_s, amplitude), (end_s, 0.0)))

    def scaled(self, factor: float) -> TorqueProfile:
        """The same profile with every value multiplied by ``factor``."""
        return TorqueProfile(tuple((t, v * factor) for t, v in self.points))

    def segment(self, t_s: float) -> tuple[float, float, float]:
        """(a, b, t_next) such that value(t) = a + b*t on [t_s, t_next); t_next is inf past the end."""
        times: tuple[float, ...] = self._times  # type: ignore[attr-defined]
        idx = bisect.bisect_right(times, t_s)
        if idx == 0:
            return self.points[0][1], 0.0, times[0]
        if idx == len(times):
            return self.points[-1][1], 0.0, math.inf
        t_a, v_a = self.points[idx - 1]
        t_b, v_b = self.points[idx]
        slope = (v_b - v_a) / (t_b - t_a)
        return v_a - slope * t_a, slope, t_b

    def value_at(self, t_s: float) -> float:
        """Value at ``t_s`` (right-continuous at steps, held constant outside the points)."""
        a, b, _ = self.segment(t_s)
        return a + b * t_s


#: What may be given as a load: nothing, a constant, a piecewise-linear table or a function of time.
Load = TorqueProfile | TimeFunction | float | None


def check_load(name: str, load: object) -> None:
    """ValueError naming ``name`` unless load is a :data:`Load`: None, a finite number, a profile or f(t_s)."""
    number = isinstance(load, (int, float)) and not isinstance(load, bool) and math.isfinite(load)
    if not (load is None or isinstance(load, TorqueProfile) or callable(load) or number):
        raise ValueError(f"{name} = {load!r} is not a load: must be None, a finite number, a TorqueProfile "
                         "or a callable f(t_s)")


@dataclass(frozen=True)
class Fixture:
    """A bench set-up: kind, powered state, spring/load choice and external loads."""

    kind: FixtureKind
    powered: bool = True
    load_mass_kg: float = 0.0
    spring_offset_rad: float | None = None  # None: the profile's spring_offset_rad
    torque_nm: Load = None  # external torque at the ankle, positive = dorsiflexing
    toe_force_n: Load = None  # force at the toe, positive = lifting the toe (dorsiflexing)
    toe_lever_m: float | None = None  # None: the profile's toe_lever_m

    def __post_init__(self) -> None:
        """Reject negative or non-finite masses and levers."""
        if not (math.isfinite(self.load_mass_kg) and 0.0 <= self.load_mass_kg <= 100.0):
            raise ValueError(
                f"fixture load_mass_kg = {self.load_mass_kg!r} outside the allowed range [0, 100]")
        if self.toe_lever_m is not None and not (0.0 < self.toe_lever_m <= 1.0):
            raise ValueError(f"fixture toe_lever_m = {self.toe_lever_m!r} outside the allowed range (0, 1]")
        if self.torque_nm is not None and self.toe_force_n is not None:
            raise ValueError("fixture takes either torque_nm or toe_force_n, not both")
        check_load("fixture torque_nm", self.torque_nm)
        check_load("fixture toe_force_n", self.toe_force_n)
        if self.spring_offset_rad is not None and not abs(self.spring_offset_rad) <= math.pi:
            raise ValueError(
                f"fixture spring_offset_rad = {self.spring_offset_rad!r} outside the allowed range [-pi, pi]"
            )

    @property
    def has_spring(self) -> bool:
        """True when the bench spring acts on the foot."""
        return self.kind is FixtureKind.SPRING_BENCH


def suspended() -> Fixture:
    """The foot hangs free under gravity, motor powered."""
    return Fixture(FixtureKind.SUSPENDED)


def spring_bench(load_mass_kg: float = 0.68, spring_offset_rad: float | None = None) -> Fixture:
    """The report's loading bench: spring -k_l (theta + theta0) plus a mass hung at the load lever."""
    return Fixture(FixtureKind.SPRING_BENCH, load_mass_kg=load_mass_kg, spring_offset_rad=spring_offset_rad)


def backdrive(toe_force_n: TorqueProfile | TimeFunction | Sequence[Sequence[float]],
              toe_lever_m: float | None = None) -> Fixture:
    """Motor unpowered (driver open); a force F(t) (callable or (t_s, N) table) pushes at the toe."""
    force: Load = toe_force_n if callable(toe_force_n) or isinstance(toe_force_n, TorqueProfile) \
        else TorqueProfile.from_points(toe_force_n)
    return Fixture(FixtureKind.BACKDRIVE, powered=False, toe_force_n=force, toe_lever_m=toe_lever_m)


def impulse(torque_nm: float, duration_s: float, start_s: float = 0.0) -> Fixture:
    """Suspended foot hit by a pneumatic push: a rectangular torque pulse at the ankle."""
    return Fixture(FixtureKind.IMPULSE, torque_nm=TorqueProfile.pulse(torque_nm, start_s, duration_s))

"""What every fault injector shares: its window in time, the record of what it changed, and the rig it arms on.

An injector is armed once on a :class:`FaultRig` (the virtual bench being built, the controller and the task
table before the scheduler takes them) and from then acts where its fault happens: a device model, a line, a
bus, the supply, the plant, the CPU's cost model. It acts from ``onset_s`` for ``duration_s`` (``inf``: to the
end) and records every change it makes with :meth:`Injector.note` -- when, and what -- so a campaign can tell a
fault that fired from one that never did (an error, never a pass). Injectors that change bytes on a wire
(:class:`ByteFault`) are also what the ``fault://`` port wrapper and the python-can bus wrapper use on a real
bench (hal/serial/protocol_fault.py, hal/fault_bus.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

__all__ = ["ByteFault", "FaultRecord", "FaultRig", "Injector", "TIMES_KEPT", "check_param"]

TIMES_KEPT = 10_000
"""How many of an injector's acting times its record keeps (the first ones; ``count`` counts them all)."""


def check_param(name: str, key: str, value: object, lo: Any, hi: Any = None) -> Any:
    """A number in [lo, hi] (or, with lo a tuple of names, one of them) for parameter `key` of injector `name`;
    ValueError naming both and the allowed values."""
    if isinstance(lo, tuple):
        if value not in lo:
            raise ValueError(f"fault {name}: {key} = {value!r} unknown: one of {', '.join(lo)}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise ValueError(f"fault {name}: {key} = {value!r} out of range: a number in [{lo:g}, {hi:g}]")
    return float(value)


@dataclass
class FaultRecord:
    """What an injector changed: the first and last time it acted, how many times, and the first change."""

    first_s: float | None = None
    last_s: float | None = None
    count: int = 0
    what: str = ""
    times_s: list[float] = field(default_factory=list)  # when it acted, the first TIMES_KEPT times (for the trace)

    @property
    def fired(self) -> bool:
        """True once the injector changed anything."""
        return self.count > 0

    def as_dict(self) -> dict[str, Any]:
        """For summary.json and the campaign's rows."""
        return {"fired": self.fired, "first_s": self.first_s, "last_s": self.last_s, "count": self.count,
                "what": self.what}


@dataclass
class FaultRig:
    """What injectors arm on in a virtual run: the bench, the controller the firmware will get, the task costs.

    ``controller`` may be replaced (a wrapped controller); ``cost_scales`` holds, per task name, functions of
    the job's start cycle giving the factor on its cost (applied by :meth:`tasks`).
    """

    bench: Any
    f_cpu_hz: int
    controller: object = None
    taps: dict[str, Any] = field(default_factory=dict)  # one tap per wire (hal/virtual/faults/taps.py)
    cost_scales: dict[str, list[Callable[[int], float]]] = field(default_factory=dict)

    def now_s(self) -> float:
        """The bench's present time in seconds (the scheduler's clock)."""
        return self.bench.mcu.now() / self.f_cpu_hz

    def tasks(self, tasks: list[Any]) -> list[Any]:
        """The task table with each scaled task's cost model wrapped (unchanged when nothing is scaled)."""
        out = []
        for t in tasks:
            scales = self.cost_scales.get(t.name)
            out.append(t if not scales else replace(t, cost=_ScaledCost(t.cost, scales, self.bench.mcu.now)))
        return out


class _ScaledCost:
    """A task's cost model times the product of the active scale factors at the job's time."""

    def __init__(self, cost: Any, scales: list[Callable[[int], float]], now: Callable[[], int]) -> None:
        self.cost, self.scales, self.now = cost, scales, now

    def __call__(self, result: object) -> int:
        base = self.cost(result) if callable(self.cost) else self.cost
        t = self.now()
        factor = 1.0
        for s in self.scales:
            factor *= s(t)
        return base if factor == 1.0 else int(round(base * factor))


class Injector:
    """A fault from ``onset_s`` for ``duration_s``; subclasses set NAME, HAZARD, WHERE, PARAMS and ``arm``."""

    NAME: ClassVar[str] = ""
    HAZARD: ClassVar[str] = ""  # what it endangers, for the hazard table
    WHERE: ClassVar[str] = ""  # where it acts (device, wire, bus, supply, plant, CPU, controller)
    LINKS: ClassVar[tuple[str, ...]] = ()  # the motor links it applies to (empty: every link)
    DANGEROUS: ClassVar[bool] = False  # refused on a real port (fault://) without allow_dangerous=1
    PARAMS: ClassVar[dict[str, tuple[Any, ...]]] = {}  # key -> (default, lowest, highest) or (default, choices)

    def __init__(self, onset_s: float, duration_s: float = math.inf, seed: int = 0, **params: Any) -> None:
        """Act from onset_s (>= 0) for duration_s (> 0, inf: to the end); params per PARAMS (ValueError names one)."""
        if isinstance(onset_s, bool) or not isinstance(onset_s, (int, float)) or not (math.isfinite(onset_s)
                                                                                       and onset_s >= 0):
            raise ValueError(f"fault {self.NAME}: onset_s = {onset_s!r} out of range: a finite number >= 0")
        if isinstance(duration_s, bool) or not isinstance(duration_s, (int, float)) or not duration_s > 0:
            raise ValueError(f"fault {self.NAME}: duration_s = {duration_s!r} out of range: a number > 0 (inf: "
                             "to the end)")
        unknown = sorted(set(params) - set(self.PARAMS))
        if unknown:
            raise ValueError(f"fault {self.NAME}: parameter {unknown[0]!r} unknown: one of {sorted(self.PARAMS)}")
        self.onset_s = float(onset_s)
        self.duration_s = float(duration_s)
        self.end_s = self.onset_s + self.duration_s
        self.seed = seed
        self.params: dict[str, Any] = {k: check_param(self.NAME, k, params.get(k, spec[0]), *spec[1:])
                                       for k, spec in self.PARAMS.items()}
        self.record = FaultRecord()

    def move_onset(self, onset_s: float) -> None:
        """Act from onset_s instead (the same duration): a ``fault://`` onset given as a gait phase is known only
        once the firmware's gait clock has started."""
        self.onset_s = float(onset_s)
        self.end_s = self.onset_s + self.duration_s

    def active(self, t_s: float) -> bool:
        """Whether t_s lies in the fault's window."""
        return self.onset_s <= t_s < self.end_s

    def note(self, t_s: float, what: str) -> None:
        """Record a change made at t_s (the first one's description is kept)."""
        r = self.record
        if r.first_s is None:
            r.first_s, r.what = t_s, what
        r.last_s = t_s
        r.count += 1
        if len(r.times_s) < TIMES_KEPT:
            r.times_s.append(t_s)

    def arm(self, rig: FaultRig) -> None:
        """Install the fault on the virtual bench (every subclass)."""
        raise NotImplementedError(f"fault {self.NAME} cannot act on the virtual bench")

    def describe(self) -> str:
        """One line: name, window and parameters."""
        p = ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}" for k, v in self.params.items())
        end = "end" if math.isinf(self.duration_s) else f"{self.end_s:.4f} s"
        return f"{self.NAME} from {self.onset_s:.4f} s to {end}" + (f" ({p})" if p else "")


class ByteFault(Injector):
    """A fault on the bytes of one direction of a wire: ``change(data, t_s)`` returns what arrives instead.

    ``WIRE`` names the wire ("motor_rx": motor -> MCU, "imu_rx": IMU -> MCU). The same instance serves the
    virtual bench (a tap on the device's link) and a real port (the ``fault://`` wrapper).
    """

    WIRE: ClassVar[str] = "motor_rx"

    def change(self, data: bytes, t_s: float) -> bytes:
        """The bytes that arrive instead of data, sent at t_s (inside the window; subclasses)."""
        raise NotImplementedError

    def filter(self, data: bytes, t_s: float) -> bytes:
        """data unchanged outside the window, else what `change` makes of it (recorded when it differs)."""
        if not data or not self.active(t_s):
            return data
        out = self.change(data, t_s)
        if out != data:
            self.note(t_s, f"{len(data)} bytes -> {len(out)} bytes" + ("" if len(out) != len(data) or not out
                                                                          else " (altered)"))
        return out

    def arm(self, rig: FaultRig) -> None:
        """Tap the wire on the virtual bench."""
        from hal.virtual.faults.taps import tap_wire

        tap_wire(rig, self.WIRE, self)

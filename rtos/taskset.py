"""Task sets in TOML: times in a declared unit, converted to integer ticks of ``f_cpu_hz``."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any

from rtos.interrupts import PeriodicInterrupt
from rtos.task import OverrunPolicy, Task, by_priority

UNIT_SECONDS: dict[str, Fraction | None] = {
    "s": Fraction(1), "ms": Fraction(1, 10**3), "us": Fraction(1, 10**6), "ns": Fraction(1, 10**9),
    "cycles": None,
}
_TASK_KEYS = {"name", "priority", "period", "deadline", "cost", "jitter", "offset", "overrun"}
_IRQ_KEYS = {"name", "period", "cost", "offset"}


@dataclass(frozen=True)
class TaskSet:
    """Tasks and periodic interrupts in ticks (cycles of ``f_cpu_hz``), with the unit they were given in."""

    unit: str
    f_cpu_hz: int
    ticks_per_unit: Fraction
    tasks: list[Task]
    interrupts: list[PeriodicInterrupt]

    def to_unit(self, ticks: int) -> int | float:
        """Convert ticks back to the task set's unit (an int when exact).

        >>> ts = parse_taskset({"unit": "ms", "f_cpu_hz": 1000000,
        ...                     "task": [{"name": "a", "priority": 1, "period": 10, "cost": 1}]})
        >>> ts.to_unit(2500)
        2.5
        """
        value = Fraction(ticks) / self.ticks_per_unit
        return int(value) if value.denominator == 1 else float(value)


def _ticks(value: Any, what: str, per_unit: Fraction, unit: str, minimum: int) -> int:
    """Convert a number in the task set's unit to whole ticks, checking sign and exactness.

    ``minimum`` is 1 for quantities that must be > 0 and 0 for those that must be >= 0.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{what} must be a number (in {unit}), got {value!r}")
    if not math.isfinite(value) or value < 0 or (minimum > 0 and value == 0):
        rule = "> 0" if minimum > 0 else ">= 0"
        raise ValueError(f"{what} must be a finite number {rule} {unit}, got {value!r}")
    ticks = (Fraction(repr(value)) if isinstance(value, float) else Fraction(value)) * per_unit  # decimal
    if ticks.denominator != 1:
        raise ValueError(f"{what} = {value!r} {unit} is not a whole number of ticks "
                         f"({float(per_unit)} ticks per {unit})")
    return int(ticks)


def _table_list(data: dict[str, Any], key: str) -> list[dict[str, Any]]:
    """Return ``data[key]`` as a list of tables (an array of tables in TOML)."""
    items = data.get(key, [])
    if not isinstance(items, list) or not all(isinstance(x, dict) for x in items):
        raise ValueError(f"[[{key}]] must be an array of tables, got {items!r}")
    return items


def parse_taskset(data: dict[str, Any]) -> TaskSet:
    """Build a TaskSet from parsed TOML (see docs/rtos.md for the format)."""
    unit = data.get("unit", "cycles")
    if unit not in UNIT_SECONDS:
        raise ValueError(f"unit must be one of {sorted(UNIT_SECONDS)}, got {unit!r}")
    f_cpu = data.get("f_cpu_hz")
    if isinstance(f_cpu, bool) or not isinstance(f_cpu, int) or f_cpu <= 0:
        raise ValueError(f"f_cpu_hz must be a positive integer (Hz), got {f_cpu!r}")
    seconds = UNIT_SECONDS[unit]
    per_unit = Fraction(1) if seconds is None else seconds * f_cpu
    unknown = set(data) - {"unit", "f_cpu_hz", "task", "interrupt", "name", "description"}
    if unknown:
        raise ValueError(f"unknown top-level key(s) {sorted(unknown)}; "
                         "allowed: unit, f_cpu_hz, task, interrupt, name, description")
    tasks = []
    for n, raw in enumerate(_table_list(data, "task")):
        name = raw.get("name", f"task{n}")
        where = f"task {name!r}"
        bad = set(raw) - _TASK_KEYS
        if bad:
            raise ValueError(f"{where}: unknown key(s) {sorted(bad)}; allowed: {sorted(_TASK_KEYS)}")
        for key in ("priority", "period", "cost"):
            if key not in raw:
                raise ValueError(f"{where}: missing {key}")
        prio = raw["priority"]
        if isinstance(prio, bool) or not isinstance(prio, int):
            raise ValueError(f"{where}: priority must be an integer (smaller = higher), got {prio!r}")
        period = _ticks(raw["period"], f"{where}: period", per_unit, unit, 1)
        deadline = _ticks(raw.get("deadline", raw["period"]), f"{where}: deadline", per_unit, unit, 1)
        policy = raw.get("overrun", "skip")
        if policy not in {p.value for p in OverrunPolicy}:
            raise ValueError(f"{where}: overrun must be one of {[p.value for p in OverrunPolicy]}, "
                             f"got {policy!r}")
        tasks.append(Task(
            name=str(name), priority=prio, period=period, deadline=deadline,
            offset=_ticks(raw.get("offset", 0), f"{where}: offset", per_unit, unit, 0),
            cost=_ticks(raw["cost"], f"{where}: cost", per_unit, unit, 0),
            jitter=_ticks(raw.get("jitter", 0), f"{where}: jitter", per_unit, unit, 0),
            overrun=OverrunPolicy(policy),
        ))
    if not tasks:
        raise ValueError("no [[task]] table: a task set needs at least one task")
    by_priority(tasks)  # duplicate priorities or names -> ValueError
    irqs = []
    for n, raw in enumerate(_table_list(data, "interrupt")):
        name = str(raw.get("name", f"irq{n}"))
        where = f"interrupt {name!r}"
        bad = set(raw) - _IRQ_KEYS
        if bad:
            raise ValueError(f"{where}: unknown key(s) {sorted(bad)}; allowed: {sorted(_IRQ_KEYS)}")
        for key in ("period", "cost"):
            if key not in raw:
                raise ValueError(f"{where}: missing {key}")
        irqs.append(PeriodicInterrupt(
            name, _ticks(raw["period"], f"{where}: period", per_unit, unit, 1),
            _ticks(raw["cost"], f"{where}: cost", per_unit, unit, 0),
            _ticks(raw.get("offset", 0), f"{where}: offset", per_unit, unit, 0),
        ))
    return TaskSet(unit, f_cpu, per_unit, tasks, irqs)


def load_taskset(path: str | Path) -> TaskSet:
    """Read and parse a task-set TOML file (OSError if unreadable, ValueError if invalid)."""
    text = Path(path).read_text(encoding="utf-8")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"not valid TOML: {exc}") from exc
    return parse_taskset(data)

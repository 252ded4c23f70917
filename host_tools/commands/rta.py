"""`pafp rta`: worst-case response-time analysis of a task set, optionally checked by emulation."""

from __future__ import annotations

import argparse
import json
import sys

from rtos.analysis import response_time_bounds
from rtos.critical import observe_worst
from rtos.taskset import load_taskset

HELP = "response-time analysis of a task set (cooperative fixed priority), with --simulate to emulate it"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the task-set file and the output options."""
    parser.add_argument("taskset", metavar="TASKSET.toml", help="task set (format: docs/rtos.md)")
    parser.add_argument("--simulate", action="store_true",
                        help="also emulate the task set over its hyperperiod under the synchronous and "
                             "every critical-instant release pattern and report the worst response seen")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--blocking", choices=("davis", "discrete"), default="davis",
                        help="blocking term: 'davis' = max lower-priority cost (as published, default); "
                             "'discrete' = that minus one tick (exact for the tick-granular emulator)")
    parser.add_argument("--max-jobs", type=int, default=200_000, metavar="N",
                        help="cap on jobs emulated per release pattern (default 200000)")


def _count(value: int) -> str:
    """An integer as digits, or as a power of ten when it has more than 15 digits."""
    digits = str(value)
    return digits if len(digits) <= 15 else f"{digits[0]}.{digits[1:4]}e{len(digits) - 1}"


def _fmt(value: object) -> str:
    """Format one table cell."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "NO"
    return str(value)


def run(args: argparse.Namespace) -> int:
    """Analyse (and optionally emulate) the task set; print a table or JSON; exit 1 if unschedulable, 2 on bad input."""
    try:
        ts = load_taskset(args.taskset)
        if args.max_jobs <= 0:
            raise ValueError(f"--max-jobs must be >= 1, got {args.max_jobs}")
        bounds = response_time_bounds(ts.tasks, ts.interrupts, blocking=args.blocking)
        observation = None
        if args.simulate:
            observation = observe_worst(ts.tasks, ts.interrupts, max_jobs=args.max_jobs)
    except OSError as exc:
        print(f"pafp rta: cannot read {args.taskset}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"pafp rta: {args.taskset}: {exc}", file=sys.stderr)
        return 2
    rows = []
    for b in bounds:
        row: dict[str, object] = {
            "name": b.name, "period": ts.to_unit(b.period), "deadline": ts.to_unit(b.deadline),
            "cost": ts.to_unit(b.cost), "bound": None if b.bound is None else ts.to_unit(b.bound),
            "schedulable": b.schedulable,
        }
        if observation is not None:
            seen = observation.worst[b.name]
            row["observed"] = None if seen is None else ts.to_unit(seen)
        rows.append(row)
    verdict = 0 if all(b.schedulable for b in bounds) else 1  # scriptable: 1 when a deadline can be missed
    if args.json:
        print(json.dumps({"tasks": rows}))
        return verdict
    headers = ["task", "priority", "period", "deadline", "cost", "bound", "schedulable"]
    if observation is not None:
        headers.append("observed")
    cells = [[_fmt(r["name"]), str(b.priority)] + [_fmt(r[k]) for k in headers[2:]]
             for r, b in zip(rows, bounds, strict=True)]
    widths = [max(len(h), *(len(c[k]) for c in cells)) for k, h in enumerate(headers)]
    print(f"times in {ts.unit} ({ts.f_cpu_hz} ticks/s); blocking term: {args.blocking}; "
          "smaller priority number = higher priority")
    print("  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True)))
    for c in cells:
        print("  ".join(v.rjust(w) for v, w in zip(c, widths, strict=True)))
    if observation is not None:
        note = (f"emulated {observation.patterns} release patterns over "
                f"{ts.to_unit(observation.horizon_cycles)} {ts.unit} each")
        if observation.capped:
            note += (f" (CAPPED at --max-jobs={args.max_jobs}; the hyperperiod is "
                     f"{_count(observation.hyperperiod_cycles // ts.ticks_per_unit)} {ts.unit})")
        print(note)
    return verdict

"""How long this process has run: the denominator of the whole-process realtime factor.

On Linux the process's start comes from ``/proc/self/stat`` (10 ms resolution), so the interpreter's start-up
and every import count; elsewhere the clock starts when this module is first imported (the `pafp` command
imports it first).
"""

from __future__ import annotations

import os
import time

__all__ = ["process_elapsed_s"]

_IMPORTED = time.monotonic()


def _from_proc() -> float | None:
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            stat = f.read()
        with open("/proc/uptime", encoding="ascii") as f:
            uptime_s = float(f.read().split()[0])
        start_ticks = int(stat.rsplit(")", 1)[1].split()[19])  # field 22, starttime, after the command name
        return uptime_s - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def process_elapsed_s() -> float:
    """Seconds since the process started (or since this module was imported, where /proc is missing)."""
    elapsed = _from_proc()
    return elapsed if elapsed is not None and elapsed >= 0 else time.monotonic() - _IMPORTED

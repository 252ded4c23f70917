"""Why and when a serial run ended, and what the stop path put on the motor's wire (summary.json["stop"])."""

from __future__ import annotations

import traceback
from dataclasses import dataclass

from firmware.drivers.motor import SafeStop
from host_tools.serial_mode.host_watchdog import WatchdogRecord
from host_tools.serial_mode.link_watch import LinkWatch
from host_tools.stop_signals import StopSignals

__all__ = ["StopRecord", "stop_record"]


@dataclass
class StopRecord:
    """Why and when the run ended, and what the stop path put on the motor's wire."""

    reason: str  # duration | signal | link_lost | exception | watchdog
    at_s: float  # run time at which the stop began (signal: its arrival)
    signal: str | None = None
    task: str | None = None
    error: str | None = None
    traceback: str | None = None
    safe: SafeStop | None = None
    latency_ms: float | None = None  # from the stop's start (the signal) to the safe frames out of the port
    goal_ms: float | None = None  # one control period plus the frames' wire time

    def as_dict(self) -> dict:
        """For summary.json: the safe frames decoded, whether they left the port, the latency."""
        safe = self.safe
        frames = list(safe.names) if safe is not None else []
        return {"reason": self.reason, "at_s": round(self.at_s, 6), "signal": self.signal, "task": self.task,
                "error": self.error, "safe_frames": frames,
                "safe_bytes": len(safe.frames) if safe is not None else 0,
                "safe_bytes_written": safe.written if safe is not None else 0,
                "safe_on_wire": safe.on_wire if safe is not None else False,
                "safe_error": (safe.error or None) if safe is not None else None,
                "latency_ms": self.latency_ms, "goal_ms": self.goal_ms}


def stop_record(signals: StopSignals, error: BaseException | None, task: str | None, link: LinkWatch,
                 run_s: float, wall0_ns: int, duration_s: float, watch: WatchdogRecord) -> StopRecord:
    """Why the loop ended: a signal, a task's exception, the host watchdog, a lost link, or the duration."""
    if signals.name is not None:
        at = (signals.at_ns - wall0_ns) / 1e9 if signals.at_ns is not None else run_s
        return StopRecord("signal", max(0.0, at), signal=signals.name)
    if error is not None:
        where = traceback.extract_tb(error.__traceback__)[-1] if error.__traceback__ else None
        text = f"{type(error).__name__}: {error}" + (f" ({where.filename}:{where.lineno})" if where else "")
        return StopRecord("exception", run_s, task=task, error=text,
                          traceback="".join(traceback.format_exception(error)))
    if watch.fired_at_s is not None and watch.silent_ms is not None:
        return StopRecord("watchdog", max(0.0, watch.fired_at_s - watch.silent_ms / 1e3), task=watch.task,
                          error=f"the loop did not kick the host watchdog for {watch.silent_ms} ms "
                                f"(limit {watch.timeout_ms} ms)")
    if link.stop_at is not None:
        return StopRecord("link_lost", run_s)
    return StopRecord("duration", min(run_s, duration_s))

"""Optional job trace in a bounded ring buffer, exported as CSV or Chrome trace-event JSON (Perfetto).

Besides the jobs it keeps, for each job that interrupts preempted, the firings of each interrupt source as the
scheduler counted them (their times when the source can tell them, :meth:`CountingSource.fired_at`), and instant
events (deadline misses, overrun faults, watchdog kicks and resets). The hot loop appends plain tuples; formatting
happens on export. ``prune_before`` drops what ended before a time (a window of the last seconds of a run).
"""

from __future__ import annotations

import csv
import io
import itertools
import json
from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import NamedTuple, TextIO

JOB_COLUMNS = ("task", "job", "release", "ready", "start", "finish", "cost")


class JobRecord(NamedTuple):
    """One job as it ran: nominal release, ready (release + jitter), start, finish and its own cycles.

    ``finish - start - cost`` is the interference of the interrupts that preempted it.
    """

    task: str
    job: int
    release: int
    ready: int
    start: int
    finish: int
    cost: int


class IrqRecord(NamedTuple):
    """The firings of one interrupt source inside one job (the job that started at ``job_start``).

    ``times`` are the firing cycles when the source tells them (:meth:`CountingSource.fired_at`), else empty.
    """

    job_start: int
    source: int
    firings: int
    times: tuple[int, ...]


class TraceEvent(NamedTuple):
    """An instant: ``kind`` is "watchdog_reset", "watchdog_kick", "fault" or "deadline_miss"; ``source`` names who."""

    kind: str
    time: int
    source: str
    job: int


class Trace:
    """Keeps the last ``maxlen`` jobs and the last ``maxlen`` instant events.

    >>> tr = Trace(maxlen=2)
    >>> for k in range(3): tr.add_job("a", k, 10 * k, 10 * k, 10 * k, 10 * k + 4)
    >>> [r.job for r in tr.jobs()]
    [1, 2]
    """

    def __init__(self, maxlen: int = 100_000) -> None:
        """Create an empty trace holding at most ``maxlen`` jobs, ``maxlen`` interrupt records and ``maxlen`` events."""
        if isinstance(maxlen, bool) or not isinstance(maxlen, int) or maxlen <= 0:
            raise ValueError(f"trace maxlen must be an int >= 1, got {maxlen!r}")
        self._jobs: deque[tuple[str, int, int, int, int, int, int]] = deque(maxlen=maxlen)
        self._irqs: deque[tuple[int, int, int, tuple[int, ...]]] = deque(maxlen=maxlen)
        self._events: deque[tuple[str, int, str, int]] = deque(maxlen=maxlen)
        self.task_names: list[str] = []
        self.interrupts: list[tuple[str, int]] = []  # (name, cycles per firing) by source index

    def add_job(self, task: str, job: int, release: int, ready: int, start: int, finish: int,
                cost: int | None = None) -> None:
        """Record one job (``cost``: its own cycles; by default ``finish - start``, no interference)."""
        self._jobs.append((task, job, release, ready, start, finish, finish - start if cost is None else cost))

    def job_appender(self) -> Callable[[tuple[str, int, int, int, int, int, int]], None]:
        """``add_job`` for a hot loop: a callable taking the tuple (task, job, release, ready, start, finish, cost)."""
        return self._jobs.append

    def irq_appender(self) -> Callable[[tuple[int, int, int, tuple[int, ...]]], None]:
        """For the hot loop: a callable taking (job start, source index, firings, firing times) (see IrqRecord)."""
        return self._irqs.append

    def irqs(self) -> list[IrqRecord]:
        """The recorded interrupt firings inside jobs, oldest first."""
        return [IrqRecord(*r) for r in self._irqs]

    def prune_before(self, t: int) -> None:
        """Forget the jobs that finished, the firings in jobs that started, and the instants that happened before t."""
        jobs, irqs, events = self._jobs, self._irqs, self._events
        while jobs and jobs[0][5] < t:
            jobs.popleft()
        while irqs and irqs[0][0] < t:
            irqs.popleft()
        while events and events[0][1] < t:
            events.popleft()

    def add_event(self, kind: str, time: int, source: str, job: int = -1) -> None:
        """Record one instant event."""
        self._events.append((kind, time, source, job))

    def jobs(self) -> list[JobRecord]:
        """The recorded jobs, oldest first."""
        return [JobRecord(*r) for r in self._jobs]

    def events(self) -> list[TraceEvent]:
        """The recorded instant events, oldest first."""
        return [TraceEvent(*e) for e in self._events]

    def clear(self) -> None:
        """Forget every record."""
        self._jobs.clear()
        self._irqs.clear()
        self._events.clear()

    def write_csv(self, out: TextIO) -> None:
        """Write the jobs as CSV with a header row (times in cycles)."""
        w = csv.writer(out, lineterminator="\n")
        w.writerow(JOB_COLUMNS)
        w.writerows(self._jobs)

    def to_csv(self) -> str:
        """Return the jobs as CSV text."""
        buf = io.StringIO()
        self.write_csv(buf)
        return buf.getvalue()

    def to_chrome(self, f_cpu_hz: int) -> dict[str, list[dict[str, object]]]:
        """Return a Chrome trace-event document: one "X" event per job (ts/dur in µs), one tid per task."""
        return {"traceEvents": list(self.chrome_events(f_cpu_hz))}

    def chrome_events(self, f_cpu_hz: int) -> Iterator[dict[str, object]]:
        """The events of :meth:`to_chrome` one at a time (metadata, jobs, then instants)."""
        if f_cpu_hz <= 0:
            raise ValueError(f"f_cpu_hz must be > 0 Hz, got {f_cpu_hz!r}")
        us = 1e6 / f_cpu_hz
        names = self._names()
        tid = {n: k + 1 for k, n in enumerate(names)}
        yield {"name": "process_name", "ph": "M", "pid": 1, "tid": 0, "args": {"name": "rtos"}}
        for n in names:
            yield {"name": "thread_name", "ph": "M", "pid": 1, "tid": tid[n], "args": {"name": n}}
            yield {"name": "thread_sort_index", "ph": "M", "pid": 1, "tid": tid[n], "args": {"sort_index": tid[n]}}
        for task, job, release, ready, start, finish, _cost in self._jobs:
            yield {
                "name": task, "cat": "job", "ph": "X", "pid": 1, "tid": tid[task],
                "ts": start * us, "dur": (finish - start) * us,
                "args": {"job": job, "release_cycles": release, "ready_cycles": ready,
                         "response_cycles": finish - release},
            }
        for kind, time, source, job in self._events:
            yield {
                "name": f"{kind}:{source}", "cat": kind, "ph": "i", "s": "g" if source not in tid else "t",
                "pid": 1, "tid": tid.get(source, 0), "ts": time * us, "args": {"job": job},
            }

    def write_chrome(self, path: str | Path, f_cpu_hz: int) -> None:
        """Write the Chrome trace-event JSON to ``path`` (open it in Perfetto or chrome://tracing).

        The same bytes as ``json.dumps(self.to_chrome(f_cpu_hz))``, written a batch of events at a time (no
        document in memory; the job events from a template, which is several times faster than encoding
        dicts) to a temporary name that is renamed when done.
        """
        path = Path(path)
        tmp = path.with_name(f".{path.name}.tmp")
        encode = json.JSONEncoder().encode
        events = self.chrome_events(f_cpu_hz)
        head = [encode(e) for e in itertools.islice(events, 1 + 2 * len(self._names()))]  # the metadata
        us = 1e6 / f_cpu_hz
        tid = {n: k + 1 for k, n in enumerate(self._names())}
        name = {n: encode(n) for n in tid}
        job = ('{"name": %s, "cat": "job", "ph": "X", "pid": 1, "tid": %d, "ts": %r, "dur": %r, "args": '
               '{"job": %d, "release_cycles": %d, "ready_cycles": %d, "response_cycles": %d}}')
        try:
            with tmp.open("w", encoding="utf-8") as f:
                f.write('{"traceEvents": [' + ", ".join(head))
                jobs = iter(self._jobs)
                while batch := list(itertools.islice(jobs, 10_000)):
                    f.write("".join([", " + job % (name[t], tid[t], start * us, (finish - start) * us, j, release,
                                                   ready, finish - release)
                                     for t, j, release, ready, start, finish, _c in batch]))
                for kind, time, source, j in self._events:
                    f.write(", " + encode({
                        "name": f"{kind}:{source}", "cat": kind, "ph": "i", "s": "g" if source not in tid else "t",
                        "pid": 1, "tid": tid.get(source, 0), "ts": time * us, "args": {"job": j},
                    }))
                f.write("]}")
            tmp.replace(path)
        except BaseException:  # a failed write leaves no partial file behind
            tmp.unlink(missing_ok=True)
            raise

    def _names(self) -> list[str]:
        """Task names in tid order: the declared ones, then any other seen in the jobs."""
        names = list(self.task_names)
        for r in self._jobs:
            if r[0] not in names:
                names.append(r[0])
        return names

    def __len__(self) -> int:
        """Number of recorded jobs."""
        return len(self._jobs)

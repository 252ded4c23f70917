"""Optional job trace in a bounded ring buffer, exported as CSV or Chrome trace-event JSON (Perfetto).

Besides the jobs it keeps, for each job that interrupts preempted, the firings of each interrupt source as the
scheduler counted them (their times when the source can tell them, :meth:`CountingSource.fired_at`), and instant
events (deadline misses, overrun faults, watchdog kicks and resets). The hot loop appends ints to short lists, which
the trace moves into arrays (one per field, each as narrow as its values) every :data:`CHUNK_JOBS` jobs; formatting
happens on export. ``prune_before`` drops what ended before a time (a window of the last seconds of a run).
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import struct
from array import array
from bisect import bisect_left
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import NamedTuple, TextIO

from rtos.interrupts import firings_from

JOB_COLUMNS = ("task", "job", "release", "ready", "start", "finish", "cost")
JOB_FIELDS = 2  # per job: task id, start
EXC_FIELDS = 6  # per job its task's timing does not predict: position, job, and the differences (Trace.flat_records)
IRQ_FIELDS = 4  # job start, source index, firings, number of firing times
CHUNK_JOBS = 1024
"""Jobs the hot loop appends to its lists before :meth:`Trace.compact` moves them into the arrays: the lists and the
ints they box stay small and their memory is reused, what is kept takes a few bytes per job (6 in a 2-stride run),
and what the window left behind is freed as the run goes (docs/telemetry.md, "Cost")."""
_WIDER = {"b": "h", "h": "i", "i": "q"}


def _packed(code: str, values: Sequence[int]) -> bytes:
    """``values`` as the bytes of an array of typecode ``code`` (struct packs ints ten times faster than
    ``array.extend`` converts them); struct.error when one does not fit."""
    return struct.pack(f"@{len(values)}{code}", *values)


def _extended(column: array, values: list[int]) -> array:
    """``column`` with ``values`` appended, first widened (8, 16, 32, 64 bits) until they fit."""
    while True:
        try:
            column.frombytes(_packed(column.typecode, values))
            return column
        except struct.error:
            wide = _WIDER[column.typecode]
            column = array(wide, _packed(wide, column))


class _Columns:
    """Records of ``width`` ints, kept as one array per field (starting at 8 bits, widened when a value needs it)."""

    def __init__(self, width: int) -> None:
        self.fields = [array("b") for _ in range(width)]

    def __len__(self) -> int:
        return len(self.fields[0])

    def extend(self, flat: list[int]) -> None:
        """Append the records of ``flat`` (``width`` ints each), and empty it."""
        width = len(self.fields)
        self.fields = [_extended(f, flat[k::width]) for k, f in enumerate(self.fields)]
        del flat[:]

    def drop(self, n: int) -> None:
        """Forget the first ``n`` records."""
        for f in self.fields:
            del f[:n]

    def row(self, k: int) -> tuple[int, ...]:
        """The ``k``-th record."""
        return tuple(f[k] for f in self.fields)


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

    ``times`` are the firing cycles when the source tells them (:meth:`CountingSource.fired_at`, or for a periodic
    source :func:`firings_from` its pattern), else empty.
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
    """Keeps the last ``maxlen`` jobs, the last ``maxlen`` interrupt records and the last ``maxlen`` instant events.

    The jobs and the interrupt records are kept as columns of ints, an array per field (the task as an index into a
    table of tasks): no object per record or per field; they become :class:`JobRecord` and :class:`IrqRecord` when
    read. The hot loop appends to lists (:meth:`flat_records`), which :meth:`compact` empties into the arrays. A job
    is kept as its task and start; what its task's timing predicts from them is not kept: job ``(start - offset) //
    period``, release ``offset + job * period``, ready at its release, and the interference (finish - start - cost)
    and cost - nominal cost of the task's previous job (0 for its first). A job that differs (one that started a
    period or more after its release, had jitter, or whose interference or modelled cost changed) is kept with its
    values in a side record keyed by its position: one job in eleven in a 2-stride run.

    >>> tr = Trace(maxlen=2)
    >>> for k in range(3): tr.add_job("a", k, 10 * k, 10 * k, 10 * k, 10 * k + 4)
    >>> [r.job for r in tr.jobs()]
    [1, 2]
    """

    def __init__(self, maxlen: int = 100_000, skip: Iterable[str] = ()) -> None:
        """Create an empty trace holding at most ``maxlen`` jobs, ``maxlen`` interrupt records and ``maxlen`` events;
        the jobs of the tasks named in ``skip`` are not recorded by the scheduler."""
        if isinstance(maxlen, bool) or not isinstance(maxlen, int) or maxlen <= 0:
            raise ValueError(f"trace maxlen must be an int >= 1, got {maxlen!r}")
        self.maxlen = maxlen
        self.skip = frozenset(skip)
        # per job: task id and start; the jobs before _job0 are dropped, and _dropped jobs were freed before the first
        self._jobs = _Columns(JOB_FIELDS)
        self._job0 = 0
        self._dropped = 0
        # per job its task's timing does not predict: its position (counted from the first job ever recorded), job
        # and differences (see flat_records), in the order of the positions
        self._exc = _Columns(EXC_FIELDS)
        # (interference, cost - nominal cost) of each task's last job: appended (the hot loop's, by task id) and
        # before _job0 (by task id; absent: (0, 0))
        self._carried: tuple[list[int], list[int]] = ([], [])
        self._carried0: dict[int, tuple[int, int]] = {}
        # (job start, source index, firings, number of firing times) per record, and the firing times (none of a
        # periodic source's)
        self._irqs = _Columns(IRQ_FIELDS)
        self._irq_times = _Columns(1)
        self._appended: tuple[list[int], list[int], list[int], list[int]] = ([], [], [], [])  # (flat_records)
        self._irq0 = 0
        self._times0 = 0
        self._events: deque[tuple[str, int, str, int]] = deque(maxlen=maxlen)
        self._task_table: list[tuple[str, int, int, int]] = []  # (name, offset, period, nominal cost) by task id
        self._task_id: dict[tuple[str, int, int, int], int] = {}
        self.task_names: list[str] = []
        self.interrupts: list[tuple[str, int]] = []  # (name, cycles per firing) by source index
        # by source index: (period, first firing) of a periodic source, whose firing times the hot loop leaves out
        # (no firing times in its records: firings_from gives them), else None
        self.periodic: list[tuple[int, int] | None] = []

    def task_ids(self, tasks: Iterable[tuple[str, int, int, int]]) -> list[int]:
        """The ids by which the job records name ``tasks``, each (name, offset, period, nominal cost in cycles); -1
        for a task the trace skips."""
        return [-1 if t[0] in self.skip else self._task_of(t) for t in tasks]

    def _task_of(self, task: tuple[str, int, int, int]) -> int:
        k = self._task_id.get(task)
        if k is None:
            k = self._task_id[task] = len(self._task_table)
            self._task_table.append(task)
            for carried in self._carried:
                carried.append(0)
        return k

    def add_job(self, task: str, job: int, release: int, ready: int, start: int, finish: int,
                cost: int | None = None) -> None:
        """Record one job (``cost``: its own cycles; by default ``finish - start``, no interference)."""
        cost = finish - start if cost is None else cost
        jobs, exceptions = self._appended[0], self._appended[3]
        exceptions.extend((len(jobs) // JOB_FIELDS, job, release, ready - release, finish - start - cost, cost))
        k = self._task_of((task, 0, 0, 0))
        jobs.extend((k, start))
        self._carried[0][k], self._carried[1][k] = finish - start - cost, cost
        if len(jobs) >= JOB_FIELDS * min(self.maxlen, CHUNK_JOBS):
            self.compact()

    def flat_records(self) -> tuple[list[int], list[int], list[int], list[int]]:
        """The lists a hot loop appends the records to: jobs, :data:`JOB_FIELDS` ints each (task id (:meth:`task_ids`),
        start); interrupt records, :data:`IRQ_FIELDS` ints each (job start, source index, firings, number of firing
        times: 0 for a source in :attr:`periodic`); the firing times (see IrqRecord); the jobs' exceptions,
        :data:`EXC_FIELDS` ints each (the job's position in the jobs list (its index there // JOB_FIELDS), job,
        release - offset - job * period, ready - release, finish - start - cost, cost - nominal cost), appended for
        each job that is not as predicted (see the class), and then its last two stored into :meth:`carried` lists.
        The loop calls :meth:`compact` each time it has appended :meth:`room` jobs since."""
        return self._appended

    def carried(self) -> tuple[list[int], list[int]]:
        """The interference and cost - nominal cost of each task's last job appended, by task id (see the class)."""
        return self._carried

    def room(self) -> int:
        """Jobs that may be appended before :meth:`compact` must run (it keeps the lists short and the memory within
        2 ``maxlen`` jobs)."""
        return max(1, min(self.maxlen, CHUNK_JOBS) - len(self._appended[0]) // JOB_FIELDS)

    def compact(self) -> int:
        """Move the appended records into the arrays, drop all but the last ``maxlen`` records (and the pruned
        ones), free them when they take as much memory as the kept ones; return :meth:`room`."""
        self._trim()
        if self._job0 * 2 >= len(self._jobs):
            self._jobs.drop(self._job0)
            self._dropped += self._job0
            self._job0 = 0
            self._exc.drop(bisect_left(self._exc.fields[0], self._dropped))
        if self._irq0 * 2 >= len(self._irqs):
            self._irqs.drop(self._irq0)
            self._irq_times.drop(self._times0)
            self._irq0 = self._times0 = 0
        return self.room()

    def _trim(self) -> None:
        """Move the appended records into the arrays; drop all but the last ``maxlen`` jobs and interrupt records (as
        a ``deque(maxlen=...)`` would)."""
        self._move()
        self._forget(len(self._jobs) - self.maxlen)
        self._drop_irqs(len(self._irqs) - self.maxlen)

    def _forget(self, k: int) -> None:
        """Move _job0 on to ``k`` (when later), carrying the values of the exceptions passed."""
        if k <= self._job0:
            return
        positions, _job, _release, _ready, preempted, cost = self._exc.fields
        tasks, dropped, carried = self._jobs.fields[0], self._dropped, self._carried0
        e = bisect_left(positions, dropped + self._job0)
        end = bisect_left(positions, dropped + k, e)
        for position, values in zip(positions[e:end], zip(preempted[e:end], cost[e:end], strict=True), strict=True):
            carried[tasks[position - dropped]] = values
        self._job0 = k

    def _move(self) -> None:
        """Move the records the hot loop appended into the arrays."""
        exceptions = self._appended[3]
        if exceptions:  # positions counted from the first job ever recorded
            base = self._dropped + len(self._jobs)
            exceptions[::EXC_FIELDS] = [base + k for k in exceptions[::EXC_FIELDS]]
        for kept, appended in zip(self._kept(), self._appended, strict=True):
            if appended:
                kept.extend(appended)

    def _kept(self) -> tuple[_Columns, _Columns, _Columns, _Columns]:
        """The arrays :meth:`flat_records`' lists are moved into."""
        return self._jobs, self._irqs, self._irq_times, self._exc

    def _job_rows(self) -> Iterator[tuple[str, int, int, int, int, int, int]]:
        """The kept jobs as tuples (task name, job, release, ready, start, finish, cost), oldest first."""
        self._trim()
        tasks, k = self._task_table, self._job0
        exceptions = self._exc.fields
        e = bisect_left(exceptions[0], self._dropped + k)
        at = exceptions[0][e] - self._dropped if e < len(exceptions[0]) else -1
        carried = dict(self._carried0)
        for task, start in zip(*(f[k:] for f in self._jobs.fields), strict=True):
            name, offset, period, nominal = tasks[task]
            if k == at:
                _, job, release, ready, preempted, cost = (f[e] for f in exceptions)
                carried[task] = preempted, cost
                e += 1
                at = exceptions[0][e] - self._dropped if e < len(exceptions[0]) else -1
            else:
                job, release, ready = (start - offset) // period, 0, 0
                preempted, cost = carried.get(task, (0, 0))
            k += 1
            release += offset + job * period
            cost += nominal
            yield name, job, release, release + ready, start, start + cost + preempted, cost

    def _finish(self, k: int) -> int:
        """The finish of the ``k``-th job kept (``k``: _job0, which the values in _carried0 precede)."""
        task, start = self._jobs.row(k)
        positions = self._exc.fields[0]
        e = bisect_left(positions, self._dropped + k)
        if e < len(positions) and positions[e] == self._dropped + k:
            _, _job, _release, _ready, preempted, cost = self._exc.row(e)
        else:
            preempted, cost = self._carried0.get(task, (0, 0))
        return start + self._task_table[task][3] + preempted + cost

    def irqs(self) -> list[IrqRecord]:
        """The recorded interrupt firings inside jobs, oldest first."""
        self._trim()
        times, t, k = self._irq_times.fields[0], self._times0, self._irq0
        out, periodic = [], self.periodic
        for start, source, firings, n in zip(*(f[k:] for f in self._irqs.fields), strict=True):
            pattern = periodic[source]
            out.append(IrqRecord(start, source, firings, tuple(times[t:t + n]) if pattern is None
                                 else firings_from(pattern, start, firings)))
            t += n
        return out

    def prune_before(self, t: int) -> None:
        """Forget the jobs that finished, the firings in jobs that started, and the instants that happened before t.

        The jobs are taken as the scheduler records them: in the order they ran, one at a time (each finishes before
        the next starts), which makes this a search, not a walk: the timeline prunes every 100 ms. The records the
        hot loop appended since the last :meth:`compact` are moved into the arrays only when every kept record is
        older than t and their first is too (moving a few records each time would cost more than the records)."""
        self._prune_kept(t)
        jobs, irqs = self._appended[0], self._appended[1]
        if ((self._job0 == len(self._jobs) and jobs and jobs[1] < t)
                or (self._irq0 == len(self._irqs) and irqs and irqs[0] < t)):
            self._move()
            self._prune_kept(t)
        events = self._events
        while events and events[0][1] < t:
            events.popleft()

    def _prune_kept(self, t: int) -> None:
        """:meth:`prune_before` in the arrays."""
        starts = self._jobs.fields[1]
        self._forget(bisect_left(starts, t, self._job0) - 1)  # those before the last one that started before t
        if self._job0 < len(starts) and starts[self._job0] < t and self._finish(self._job0) < t:
            self._forget(self._job0 + 1)
        self._drop_irqs(bisect_left(self._irqs.fields[0], t, self._irq0))

    def _drop_irqs(self, k: int) -> None:
        """Move _irq0 on to ``k`` (when later), and _times0 past their firing times."""
        if k > self._irq0:
            self._times0 += sum(self._irqs.fields[3][self._irq0:k])
            self._irq0 = k

    def add_event(self, kind: str, time: int, source: str, job: int = -1) -> None:
        """Record one instant event."""
        self._events.append((kind, time, source, job))

    def jobs(self) -> list[JobRecord]:
        """The recorded jobs, oldest first."""
        return [JobRecord(*r) for r in self._job_rows()]

    def events(self) -> list[TraceEvent]:
        """The recorded instant events, oldest first."""
        return [TraceEvent(*e) for e in self._events]

    def clear(self) -> None:
        """Forget every record."""
        for kept, appended in zip(self._kept(), self._appended, strict=True):
            del appended[:]
            kept.drop(len(kept))
        self._job0 = self._irq0 = self._times0 = self._dropped = 0
        self._carried0 = {k: v for k, v in enumerate(zip(*self._carried, strict=True)) if v != (0, 0)}
        self._events.clear()

    def write_csv(self, out: TextIO) -> None:
        """Write the jobs as CSV with a header row (times in cycles)."""
        w = csv.writer(out, lineterminator="\n")
        w.writerow(JOB_COLUMNS)
        w.writerows(self._job_rows())

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
        for task, job, release, ready, start, finish, _cost in self._job_rows():
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
                jobs = self._job_rows()
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
        self._trim()
        for task in dict.fromkeys(self._jobs.fields[0][self._job0:]):
            name = self._task_table[task][0]
            if name not in names:
                names.append(name)
        return names

    def __len__(self) -> int:
        """Number of recorded jobs."""
        self._trim()
        return len(self._jobs) - self._job0

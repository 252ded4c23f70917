"""Optional job trace in a bounded ring buffer (exported as CSV or Chrome trace-event JSON: rtos/trace_export.py).

Besides the jobs it keeps, for each job that interrupts preempted, the firings of each interrupt source as the
scheduler counted them (their times when the source can tell them, :meth:`CountingSource.fired_at`; a periodic
source's are derived from the job when read), and instant events (deadline misses, overrun faults, watchdog kicks
and resets). The hot loop appends a small int per job (its task, where it started, which of its values it keeps
beside it) to a list, and what its task's timing does not predict to side lists; the trace moves them into arrays
(one per field, each as narrow as its values) every :data:`CHUNK_JOBS` jobs, with a checkpoint from which that
chunk's jobs are read; formatting happens on export. ``prune_before`` drops what ended before a time (a window of
the last seconds of a run).
"""

from __future__ import annotations

import struct
from array import array
from bisect import bisect_left, bisect_right
from collections import deque
from collections.abc import Iterable, Iterator, Sequence
from typing import Final, NamedTuple

from rtos.interrupts import firings_from

JOB_COLUMNS = ("task", "job", "release", "ready", "start", "finish", "cost")
CODES: Final = 9
"""A job's code is its task id * CODES + 3 * where it started + which of its values are kept beside it."""
AT_LAST_FINISH: Final = 0  # started at the finish of the job recorded before it (the CPU went from one to the next)
AT_NEXT_RELEASE: Final = 3  # at its task's first release after that finish (the CPU was idle until then)
AT_GIVEN: Final = 6  # anywhere else: its start is the next given start
AS_BEFORE: Final = 0  # its job, release, ready, interference and cost are as its task's timing predicts (Trace)
NEW_INTERFERENCE: Final = 1  # ... but its interference, the next in the interference list
DIFFERS: Final = 2  # its values are the next side record
SIDE_FIELDS = 5  # the ints of a side record (Trace.flat_records)
IRQ_FIELDS = 4  # job start, source index, firings, number of firing times
CHUNK_JOBS = 4096
"""Jobs the hot loop appends to its lists before :meth:`Trace.compact` moves them into the arrays: the lists stay
small and their memory is reused, what is kept takes about a byte per job, and what the window left behind is freed
a chunk at a time as the run goes (docs/telemetry.md, "Cost")."""
_WIDER = {"B": "h", "h": "i", "i": "q"}


def _packed(code: str, values: Sequence[int]) -> bytes:
    """``values`` as the bytes of an array of typecode ``code`` (``bytes`` makes unsigned bytes, and struct packs
    wider ints, ten times faster than ``array.extend`` converts them); ValueError or struct.error when one does not
    fit."""
    return bytes(values) if code == "B" else struct.pack(f"@{len(values)}{code}", *values)


def _extended(column: array, values: list[int]) -> array:
    """``column`` with ``values`` appended, first widened (8 bits unsigned, then 16, 32, 64 bits) until they fit."""
    while True:
        try:
            column.frombytes(_packed(column.typecode, values))
            return column
        except (ValueError, struct.error):
            wide = _WIDER[column.typecode]
            column = array(wide, _packed(wide, column))


class _Columns:
    """Records of ``width`` ints, kept as one array per field (starting at 8 bits unsigned, widened when a value
    needs it)."""

    def __init__(self, width: int) -> None:
        self.fields = [array("B") for _ in range(width)]

    def __len__(self) -> int:
        return len(self.fields[0])

    def extend(self, flat: list[int]) -> None:
        """Append the records of ``flat`` (``width`` ints each), and empty it."""
        width = len(self.fields)
        self.fields = [_extended(f, flat if width == 1 else flat[k::width]) for k, f in enumerate(self.fields)]
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


class _Checkpoint(NamedTuple):
    """Where a chunk of jobs begins, and what reading its jobs needs of those before it."""

    position: int  # of its first job, counted from the first job ever recorded
    given: int  # index of its first given start (AT_GIVEN), counted likewise
    interference: int  # index of its first interference kept beside its job (NEW_INTERFERENCE), likewise
    differs: int  # index of its first side record (DIFFERS), likewise
    last_finish: int  # the finish of the job before it (-1: none)
    preempted: tuple[int, ...]  # by task id: the interference of the task's last job before it
    cost: tuple[int, ...]  # by task id: that job's cost - its task's nominal cost


class TraceEvent(NamedTuple):
    """An instant: ``kind`` is "watchdog_reset", "watchdog_kick", "fault" or "deadline_miss"; ``source`` names who."""

    kind: str
    time: int
    source: str
    job: int


class Trace:
    """Keeps the last ``maxlen`` jobs, the interrupts' firings in them and the last ``maxlen`` instant events.

    A job is kept as a small int, its code: its task (an index into a table of tasks), where it started and which of
    its values are kept beside it (:data:`CODES`). Its start is the finish of the job before it, or its task's first
    release after that finish, or (rarely: jitter, a late start) given. What its task's timing predicts from the
    start is not kept: job ``(start - offset) // period``, release ``offset + job * period``, ready at its release,
    and the interference (finish - start - cost) and cost - nominal cost of the task's previous job (0 for its
    first). A job whose interference differs keeps it beside it (809 of a 2-stride run's 19,125 jobs); one that differs
    otherwise (a late start, jitter, a modelled cost) keeps a side record. The interrupt records of sources that are
    not periodic are kept as columns of ints; those of a periodic one (:attr:`periodic`) follow from the jobs'
    starts and finishes and are derived when read. Every chunk of jobs the hot loop appends (:meth:`flat_records`)
    is moved into arrays (one per field, each as narrow as its values) with a checkpoint from which its jobs are
    read: the finish of the job before and the values carried over; so the trace forgets and frees whole chunks.
    Records become :class:`JobRecord` and :class:`IrqRecord` when read.

    >>> tr = Trace(maxlen=2)
    >>> for k in range(3): tr.add_job("a", k, 10 * k, 10 * k, 10 * k, 10 * k + 4)
    >>> [r.job for r in tr.jobs()]
    [1, 2]
    """

    def __init__(self, maxlen: int = 100_000, skip: Iterable[str] = ()) -> None:
        """Create an empty trace holding at most ``maxlen`` jobs (and the firings in them) and ``maxlen`` events; the
        jobs of the tasks named in ``skip`` are not recorded by the scheduler."""
        if isinstance(maxlen, bool) or not isinstance(maxlen, int) or maxlen <= 0:
            raise ValueError(f"trace maxlen must be an int >= 1, got {maxlen!r}")
        self.maxlen = maxlen
        self.skip = frozenset(skip)
        # the jobs' codes from the position of _checks[0] on, and beside them from its indices on: the given starts,
        # the interferences and the side records
        self._codes = _Columns(1)
        self._given = _Columns(1)
        self._interference = _Columns(1)
        self._differs = _Columns(SIDE_FIELDS)
        self._checks = [_Checkpoint(0, 0, 0, 0, -1, (), ())]  # one per chunk, in order; the last is at the end
        self._job0 = 0  # the position of the first job kept (the ring)
        self._cut: tuple[int, int] | None = None  # (t, end): prune_before's, not applied yet (_settle_cut)
        self.last_finish: int | None = -1
        """The finish of the last job appended (-1: none); None while a scheduler's loop keeps it (take_last_finish)."""
        # (interference, cost - nominal cost) of each task's last job appended, by task id
        self._carried: tuple[list[int], list[int]] = ([], [])
        # (job start, source index, firings, number of firing times) per record of a source that is not periodic,
        # and the firing times
        self._irqs = _Columns(IRQ_FIELDS)
        self._irq_times = _Columns(1)
        self._irq0 = 0
        self._times0 = 0
        self._appended: tuple[list[int], ...] = ([], [], [], [], [], [])  # (flat_records)
        self._events: deque[tuple[str, int, str, int]] = deque(maxlen=maxlen)
        self._kicks: deque[int] = deque(maxlen=maxlen)  # the watchdog kicks' times (kick_log)
        self._task_table: list[tuple[str, int, int, int]] = []  # (name, offset, period, nominal cost) by task id
        self._task_id: dict[tuple[str, int, int, int], int] = {}
        self.task_names: list[str] = []
        self.interrupts: list[tuple[str, int]] = []  # (name, cycles per firing) by source index
        # by source index: (period, first firing) of a periodic source, whose records the hot loop leaves out (they
        # are derived from the jobs when read), else None
        self.periodic: list[tuple[int, int] | None] = []

    def task_ids(self, tasks: Iterable[tuple[str, int, int, int]]) -> list[int]:
        """The ids by which the job records name ``tasks``, each (name, offset, period > 0, nominal cost in cycles);
        -1 for a task the trace skips."""
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
        codes, given, _interference, differs = self._appended[:4]
        k = self._task_of((task, 0, 0, 0))
        codes.append(k * CODES + AT_GIVEN + DIFFERS)
        given.append(start)
        differs.extend((job, release, ready - release, finish - start - cost, cost))
        self._carried[0][k], self._carried[1][k] = finish - start - cost, cost
        self.last_finish = finish
        if len(codes) >= min(self.maxlen, CHUNK_JOBS):
            self.compact()

    def flat_records(self) -> tuple[list[int], ...]:
        """The lists a hot loop appends the records to:

        - jobs, a code each: task id (:meth:`task_ids`) * :data:`CODES`, plus where it started: :data:`AT_LAST_FINISH`
          at the finish of the job appended before it, :data:`AT_NEXT_RELEASE` at its task's first release after
          that finish (release - period <= that finish < release), else :data:`AT_GIVEN`; plus which values it keeps
          beside it: :data:`AS_BEFORE` none, :data:`NEW_INTERFERENCE` its interference, :data:`DIFFERS` a side record;
        - the start of each AT_GIVEN job, in order;
        - the interference (finish - start - cost) of each NEW_INTERFERENCE job;
        - the side records, :data:`SIDE_FIELDS` ints each (job, release - offset - job * period, ready - release,
          interference, cost - nominal cost), of each DIFFERS job: one whose job, release, ready or cost is not as
          its task's timing predicts (see the class);
        - records of the interrupts that preempted a job, :data:`IRQ_FIELDS` ints each (job start, source index,
          firings, number of firing times), of the sources not in :attr:`periodic`;
        - their firing times (see IrqRecord).

        A NEW_INTERFERENCE or DIFFERS job stores its interference and cost - nominal cost into the :meth:`carried`
        lists. The loop takes :attr:`last_finish` with :meth:`take_last_finish`, calls :meth:`compact` each time it
        has appended :meth:`room` jobs since, with :attr:`last_finish` set to the last one's finish, and sets it back
        when it ends."""
        return self._appended

    def carried(self) -> tuple[list[int], list[int]]:
        """The interference and cost - nominal cost of each task's last job appended, by task id (see the class)."""
        return self._carried

    def take_last_finish(self) -> int:
        """:attr:`last_finish` for a loop that appends jobs from now on; it is None until the loop sets it back (the
        trace reads it from the records if it needs it before)."""
        if self.last_finish is None:
            self._move()
            self.last_finish = self._checks[-1].last_finish
        last, self.last_finish = self.last_finish, None
        return last

    def room(self) -> int:
        """Jobs that may be appended before :meth:`compact` must run (it keeps the lists short and the memory within
        ``maxlen`` jobs and a chunk)."""
        return max(1, min(self.maxlen, CHUNK_JOBS) - len(self._appended[0]))

    def compact(self) -> int:
        """Move the appended records into the arrays, drop all but the last ``maxlen`` jobs (and the pruned ones) by
        whole chunks with the interrupt records in them, free the interrupt records when they take as much memory
        as the kept ones; return :meth:`room`."""
        self._trim()
        if self._irq0 * 2 >= len(self._irqs):
            self._irqs.drop(self._irq0)
            self._irq_times.drop(self._times0)
            self._irq0 = self._times0 = 0
        return self.room()

    def _end(self) -> int:
        """The position after the last job in the arrays."""
        return self._checks[0].position + len(self._codes)

    def _trim(self) -> None:
        """Move the appended records into the arrays; drop all but the last ``maxlen`` jobs (as a
        ``deque(maxlen=...)`` would; their memory a chunk at a time)."""
        self._move()
        self._job0 = max(self._job0, self._end() - self.maxlen)
        self._drop_chunks(bisect_right(self._checks, self._job0, key=_position) - 1)

    def _drop_chunks(self, c: int) -> None:
        """Free the jobs before the ``c``-th checkpoint and the interrupt records of jobs that started before the
        last of them finished."""
        if c <= 0:
            return
        check, first = self._checks[c], self._checks[0]
        self._codes.drop(check.position - first.position)
        self._given.drop(check.given - first.given)
        self._interference.drop(check.interference - first.interference)
        self._differs.drop(check.differs - first.differs)
        del self._checks[:c]
        self._job0 = max(self._job0, check.position)
        k = bisect_left(self._irqs.fields[0], check.last_finish, self._irq0)
        if k > self._irq0:
            self._times0 += sum(self._irqs.fields[3][self._irq0:k])
            self._irq0 = k

    def _move(self) -> None:
        """Move the records the hot loop appended into the arrays, with a checkpoint after the jobs."""
        moved = len(self._appended[0])
        for kept, appended in zip(self._kept(), self._appended, strict=True):
            if appended:
                kept.extend(appended)
        if moved:
            last = self.last_finish
            if last is None:  # a scheduler's loop has it: the finish of the last job read back
                last = self._checks[-1].last_finish
                for row in self._rows(len(self._checks) - 1):
                    last = row[6]
            first = self._checks[0]
            self._checks.append(_Checkpoint(
                self._end(), first.given + len(self._given), first.interference + len(self._interference),
                first.differs + len(self._differs), last, tuple(self._carried[0]), tuple(self._carried[1])))

    def _kept(self) -> tuple[_Columns, ...]:
        """The arrays :meth:`flat_records`' lists are moved into."""
        return self._codes, self._given, self._interference, self._differs, self._irqs, self._irq_times

    def _rows(self, c: int) -> Iterator[tuple[int, str, int, int, int, int, int, int]]:
        """The jobs in the arrays from the ``c``-th checkpoint on, as tuples (position, task name, job, release, ready,
        start, finish, cost)."""
        first, check = self._checks[0], self._checks[c]
        tasks = self._task_table
        preempted = [*check.preempted, *[0] * (len(tasks) - len(check.preempted))]
        costs = [*check.cost, *[0] * (len(tasks) - len(check.cost))]
        given, g = self._given.fields[0], check.given - first.given
        interference, i = self._interference.fields[0], check.interference - first.interference
        differs, d = self._differs.fields, check.differs - first.differs
        last, position = check.last_finish, check.position
        for code in self._codes.fields[0][check.position - first.position:]:
            task, where = divmod(code, CODES)
            values = where % 3
            where -= values
            name, offset, period, nominal = tasks[task]
            if where == AT_LAST_FINISH:
                start = last
            elif where == AT_NEXT_RELEASE:
                start = offset + ((last - offset) // period + 1) * period
            else:
                start = given[g]
                g += 1
            if values == DIFFERS:
                job, release, ready, preempted[task], costs[task] = (f[d] for f in differs)
                d += 1
            else:
                if values == NEW_INTERFERENCE:
                    preempted[task] = interference[i]
                    i += 1
                job, release, ready = (start - offset) // period, 0, 0
            release += offset + job * period
            cost = nominal + costs[task]
            last = start + cost + preempted[task]
            yield position, name, job, release, release + ready, start, last, cost
            position += 1

    def job_rows(self) -> Iterator[tuple[str, int, int, int, int, int, int]]:
        """The kept jobs as tuples (task name, job, release, ready, start, finish, cost), oldest first, one at a
        time (:meth:`jobs` as a list of JobRecord)."""
        self._trim()
        self._settle_cut()
        job0 = self._job0
        for position, *row in self._rows(bisect_right(self._checks, job0, key=_position) - 1):
            if position >= job0:
                yield tuple(row)  # type: ignore[misc]

    def irqs(self) -> list[IrqRecord]:
        """The interrupt firings inside the kept jobs, oldest first (by job, then by source): a periodic source's
        derived from each job's start and finish, the other sources' as recorded."""
        jobs = [(start, finish) for *_, start, finish, _cost in self.job_rows()]
        starts = {start for start, _finish in jobs}
        times, t, k = self._irq_times.fields[0], self._times0, self._irq0
        out: list[tuple[int, int, int, tuple[int, ...]]] = []
        for start, source, firings, n in zip(*(f[k:] for f in self._irqs.fields), strict=True):
            if start in starts:
                out.append((start, source, firings, tuple(times[t:t + n])))
            t += n
        periodic = [(k, p) for k, p in enumerate(self.periodic) if p is not None]
        for start, finish in jobs if periodic else ():
            for source, (period, first) in periodic:
                firings = _before(finish, period, first) - _before(start, period, first)
                if firings:
                    out.append((start, source, firings, firings_from((period, first), start, firings)))
        out.sort(key=lambda r: r[:2])
        return [IrqRecord(*r) for r in out]

    def prune_before(self, t: int) -> None:
        """Forget the jobs that finished (and the firings in them) and the instants that happened before t.

        The jobs are taken as the scheduler records them: in the order they ran, one at a time (each finishes before
        the next starts), which makes this a search, not a walk: the timeline prunes every 100 ms. Whole chunks of
        jobs are freed at once (a search over the checkpoints); the jobs of the chunk t falls in are found when the
        trace is next read, as are those the hot loop appended since the last :meth:`compact`."""
        self._drop_chunks(bisect_left(self._checks, t, key=_last_finish) - 1)
        end = self._end() + len(self._appended[0])
        if self._cut is not None and (t < self._cut[0] or end < self._cut[1]):
            self._settle_cut()  # this prune does not cover the one before: apply that first
        self._cut = (t, end)
        for events in (self._events, self._kicks):
            while events and _time(events[0]) < t:
                events.popleft()

    def _settle_cut(self) -> None:
        """Apply the prune not applied yet: move _job0 past the jobs before its end that finished before its t."""
        if self._cut is None:
            return
        t, end = self._cut
        self._cut = None
        self._move()
        for position, *_, finish, _cost in self._rows(0):
            if position >= end or finish >= t:
                break
            self._job0 = max(self._job0, position + 1)

    def add_event(self, kind: str, time: int, source: str, job: int = -1) -> None:
        """Record one instant event."""
        self._events.append((kind, time, source, job))

    def jobs(self) -> list[JobRecord]:
        """The recorded jobs, oldest first."""
        return [JobRecord(*r) for r in self.job_rows()]

    def events(self) -> list[TraceEvent]:
        """The recorded instant events and the kicks (kick_log), by time (in the order they were recorded at the same
        time)."""
        kicks = [("watchdog_kick", t, "watchdog", -1) for t in self._kicks]
        return [TraceEvent(*e) for e in (sorted([*self._events, *kicks], key=_time) if kicks else self._events)]

    def kick_log(self) -> deque[int]:
        """Where a watchdog appends the time of each kick (an instant "watchdog_kick" of source "watchdog"): an int
        appended natively costs the loop less than a call."""
        return self._kicks

    def clear(self) -> None:
        """Forget every record."""
        self._trim()
        self._cut = None
        self._job0 = self._end()
        self._drop_chunks(len(self._checks) - 1)
        self._irqs.drop(len(self._irqs))
        self._irq_times.drop(len(self._irq_times))
        self._irq0 = self._times0 = 0
        self._events.clear()
        self._kicks.clear()

    def task_order(self) -> list[str]:
        """The task names: the declared ones (priority order), then any other seen in the kept jobs."""
        names = list(self.task_names)
        self._trim()
        self._settle_cut()
        codes = self._codes.fields[0][self._job0 - self._checks[0].position:]
        for task in dict.fromkeys(code // CODES for code in codes):
            name = self._task_table[task][0]
            if name not in names:
                names.append(name)
        return names

    def __len__(self) -> int:
        """Number of recorded jobs."""
        self._trim()
        self._settle_cut()
        return self._end() - self._job0


def _position(check: _Checkpoint) -> int:
    return check.position


def _last_finish(check: _Checkpoint) -> int:
    return check.last_finish


def _time(event: tuple[str, int, str, int] | int) -> int:
    """An instant's time (a kick's is the int itself)."""
    return event if isinstance(event, int) else event[1]


def _before(t: int, period: int, first: int) -> int:
    """How many times a source firing at ``first + k * period``, k >= 0, fired before ``t``."""
    return max(0, -((first - t) // period))

"""A job trace (:class:`rtos.trace.Trace`) as CSV or Chrome trace-event JSON (Perfetto, chrome://tracing): the
kernel's own export, for a scheduler used on its own (`pafp run` writes its trace.pftrace with
host_tools/reports/timeline.py)."""

from __future__ import annotations

import csv
import io
import itertools
import json
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

from rtos.trace import JOB_COLUMNS, Trace


def write_csv(trace: Trace, out: TextIO) -> None:
    """Write the jobs as CSV with a header row (times in cycles)."""
    w = csv.writer(out, lineterminator="\n")
    w.writerow(JOB_COLUMNS)
    w.writerows(trace.job_rows())


def to_csv(trace: Trace) -> str:
    """The jobs as CSV text."""
    buf = io.StringIO()
    write_csv(trace, buf)
    return buf.getvalue()


def to_chrome(trace: Trace, f_cpu_hz: int) -> dict[str, list[dict[str, object]]]:
    """A Chrome trace-event document: one "X" event per job (ts/dur in µs), one tid per task."""
    return {"traceEvents": list(chrome_events(trace, f_cpu_hz))}


def chrome_events(trace: Trace, f_cpu_hz: int) -> Iterator[dict[str, object]]:
    """The events of :func:`to_chrome` one at a time (metadata, jobs, then instants)."""
    if f_cpu_hz <= 0:
        raise ValueError(f"f_cpu_hz must be > 0 Hz, got {f_cpu_hz!r}")
    us = 1e6 / f_cpu_hz
    tid = _tids(trace)
    yield from _metadata(tid)
    for task, job, release, ready, start, finish, _cost in trace.job_rows():
        yield {
            "name": task, "cat": "job", "ph": "X", "pid": 1, "tid": tid[task],
            "ts": start * us, "dur": (finish - start) * us,
            "args": {"job": job, "release_cycles": release, "ready_cycles": ready,
                     "response_cycles": finish - release},
        }
    for event in trace.events():
        yield _instant(event, tid, us)


def write_chrome(trace: Trace, path: str | Path, f_cpu_hz: int) -> None:
    """Write the Chrome trace-event JSON to ``path`` (open it in Perfetto or chrome://tracing).

    The same bytes as ``json.dumps(to_chrome(trace, f_cpu_hz))``, written a batch of events at a time (no document
    in memory; the job events from a template, which is several times faster than encoding dicts) to a temporary
    name that is renamed when done.
    """
    if f_cpu_hz <= 0:
        raise ValueError(f"f_cpu_hz must be > 0 Hz, got {f_cpu_hz!r}")
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    encode = json.JSONEncoder().encode
    us = 1e6 / f_cpu_hz
    tid = _tids(trace)
    name = {n: encode(n) for n in tid}
    job = ('{"name": %s, "cat": "job", "ph": "X", "pid": 1, "tid": %d, "ts": %r, "dur": %r, "args": '
           '{"job": %d, "release_cycles": %d, "ready_cycles": %d, "response_cycles": %d}}')
    try:
        with tmp.open("w", encoding="utf-8") as f:
            f.write('{"traceEvents": [' + ", ".join(encode(e) for e in _metadata(tid)))
            jobs = trace.job_rows()
            while batch := list(itertools.islice(jobs, 10_000)):
                f.write("".join([", " + job % (name[t], tid[t], start * us, (finish - start) * us, j, release,
                                               ready, finish - release)
                                 for t, j, release, ready, start, finish, _c in batch]))
            for event in trace.events():
                f.write(", " + encode(_instant(event, tid, us)))
            f.write("]}")
        tmp.replace(path)
    except BaseException:  # a failed write leaves no partial file behind
        tmp.unlink(missing_ok=True)
        raise


def _tids(trace: Trace) -> dict[str, int]:
    """A thread id per task, in the order of :meth:`Trace.task_order` from 1 (0: the kernel's instants)."""
    return {n: k + 1 for k, n in enumerate(trace.task_order())}


def _metadata(tid: dict[str, int]) -> Iterator[dict[str, object]]:
    """The process's name, and each task's thread name and sort index."""
    yield {"name": "process_name", "ph": "M", "pid": 1, "tid": 0, "args": {"name": "rtos"}}
    for n, k in tid.items():
        yield {"name": "thread_name", "ph": "M", "pid": 1, "tid": k, "args": {"name": n}}
        yield {"name": "thread_sort_index", "ph": "M", "pid": 1, "tid": k, "args": {"sort_index": k}}


def _instant(event: tuple[str, int, str, int], tid: dict[str, int], us: float) -> dict[str, object]:
    """An instant event: on its task's thread, else global."""
    kind, time, source, job = event
    return {"name": f"{kind}:{source}", "cat": kind, "ph": "i", "s": "g" if source not in tid else "t",
            "pid": 1, "tid": tid.get(source, 0), "ts": time * us, "args": {"job": job}}

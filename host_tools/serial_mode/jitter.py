"""Bounded, deterministic histograms of wall-clock timings (release jitter, execution time) per task.

The RTOS's `TaskStats` keeps min/max only; percentiles need the distribution. A `TimingHistogram`
has fixed 1 µs bins up to `limit_ns` plus one overflow bin, so memory is bounded whatever the run
length, and the maximum is kept exactly. Percentiles are read off the bins (1 µs resolution).

Each job whose response (start - release + execution) exceeds its deadline is put down to one cause:
an *overrun* when its own execution took longer than the deadline (the code is too slow for its
budget), else a *late release* (the host started it late: a stall, or a job before it that ran long).
"""

from __future__ import annotations

from collections.abc import Callable

from rtos import Job, Task

__all__ = ["TimingHistogram", "TaskTimings", "instrument"]

BIN_NS = 1000


class TimingHistogram:
    """Counts of durations in 1 µs bins up to `limit_ns` (the rest in an overflow bin), exact max.

    >>> h = TimingHistogram()
    >>> for ns in (1_500, 2_500, 2_700, 90_000):
    ...     h.add(ns)
    >>> h.count, h.percentile_us(50), h.max_us
    (4, 2.0, 90.0)
    """

    __slots__ = ("bins", "overflow", "count", "max_ns", "limit_ns")

    def __init__(self, limit_ns: int = 50_000_000) -> None:
        """Empty histogram; durations at or above `limit_ns` go to the overflow bin."""
        if limit_ns < BIN_NS:
            raise ValueError(f"limit_ns {limit_ns!r} out of range: >= {BIN_NS}")
        self.limit_ns = limit_ns
        self.bins = [0] * (limit_ns // BIN_NS)
        self.overflow = 0
        self.count = 0
        self.max_ns = 0

    def add(self, ns: int) -> None:
        """Count one duration (negative values count as 0)."""
        ns = max(0, ns)
        k = ns // BIN_NS
        if k < len(self.bins):
            self.bins[k] += 1
        else:
            self.overflow += 1
        self.count += 1
        if ns > self.max_ns:
            self.max_ns = ns

    def percentile_us(self, q: float) -> float | None:
        """The lower edge of the bin holding the q-th percentile (µs), None when empty."""
        if not 0 <= q <= 100:
            raise ValueError(f"percentile {q!r} out of range: 0..100")
        if not self.count:
            return None
        rank = max(1, -(-int(q * self.count) // 100))  # ceil(q/100 * count), at least the first
        seen = 0
        for k, n in enumerate(self.bins):
            seen += n
            if seen >= rank:
                return k * BIN_NS / 1000
        return self.limit_ns / 1000

    @property
    def max_us(self) -> float:
        """Longest duration seen (µs, exact)."""
        return self.max_ns / 1000

    def mean_us(self) -> float | None:
        """Mean from the bin centres (µs; the overflow bin counts at the limit), None when empty."""
        if not self.count:
            return None
        total = sum((k * BIN_NS + BIN_NS // 2) * n for k, n in enumerate(self.bins) if n)
        return (total + self.overflow * self.limit_ns) / self.count / 1000

    def as_dict(self) -> dict[str, float | int | None]:
        """p50 / p99 / max in µs and the count."""
        return {"count": self.count, "p50_us": self.percentile_us(50), "p99_us": self.percentile_us(99),
                "max_us": round(self.max_us, 3)}


class TaskTimings:
    """Per task: release jitter (start - nominal release) and host execution time of the body."""

    def __init__(self, names: list[str], f_cpu_hz: int, clock_ns: Callable[[], int]) -> None:
        """Histograms for each task name; job times are cycles of f_cpu_hz, bodies timed with clock_ns."""
        self.f_cpu_hz = f_cpu_hz
        self.clock_ns = clock_ns
        self.jitter = {n: TimingHistogram() for n in names}
        self.execution = {n: TimingHistogram() for n in names}
        self.late_releases = dict.fromkeys(names, 0)
        self.overruns = dict.fromkeys(names, 0)
        self.running: str | None = None  # the task whose body is running (still set if it raised)

    def as_dict(self) -> dict[str, dict[str, object]]:
        """{task: {"release_jitter": {...}, "execution": {...}, "late_releases": n, "overruns": n}}."""
        return {n: {"release_jitter": self.jitter[n].as_dict(), "execution": self.execution[n].as_dict(),
                    "late_releases": self.late_releases[n], "overruns": self.overruns[n]}
                for n in self.jitter}


def instrument(task: Task, timings: TaskTimings) -> Task:
    """A copy of `task` whose body also records its release jitter and execution time into `timings`."""
    from dataclasses import replace

    body = task.body
    if body is None:
        return task
    name = task.name
    jit, exe = timings.jitter[name], timings.execution[name]
    f_cpu, clock_ns = timings.f_cpu_hz, timings.clock_ns
    deadline_ns = task.deadline * 1_000_000_000 // f_cpu

    def timed(job: Job) -> object:
        """Run the original body, timing it, noting how late it started and why a miss happened."""
        late_ns = (job.start - job.release) * 1_000_000_000 // f_cpu
        jit.add(late_ns)
        timings.running = name
        t0 = clock_ns()
        result = body(job)
        ns = clock_ns() - t0
        timings.running = None
        exe.add(ns)
        if late_ns + ns > deadline_ns:
            if ns > deadline_ns:
                timings.overruns[name] += 1
            else:
                timings.late_releases[name] += 1
        return result

    return replace(task, body=timed)

"""Job trace: bounded ring buffer, CSV, Chrome trace-event JSON with instant events."""

from __future__ import annotations

import csv
import io
import json

import pytest

from rtos import Fault, OverrunPolicy, Scheduler, Task, Trace, VirtualClock, Watchdog
from rtos.interrupts import firings_from
from rtos.trace_export import to_chrome, to_csv, write_chrome


def _traced_run():
    tr = Trace(maxlen=1000)
    tasks = [Task("ctrl", 1, 1000, deadline=300, cost=200, offset=100),
             Task("log", 2, 2000, cost=450, overrun=OverrunPolicy.FAULT)]
    faults: list[Fault] = []
    s = Scheduler(tasks, VirtualClock(1_000_000), trace=tr, on_fault=faults.append)
    s.add_watchdog(Watchdog(1500))
    s.run_until(4000)
    return s, tr


def test_ring_buffer_keeps_the_last_jobs_only():
    tr = Trace(maxlen=5)
    s = Scheduler([Task("x", 1, 10, cost=1)], trace=tr)
    s.run_until(1000)
    assert len(tr) == 5 and [j.job for j in tr.jobs()] == [95, 96, 97, 98, 99]


def test_csv_has_header_and_one_row_per_job():
    s, tr = _traced_run()
    rows = list(csv.reader(io.StringIO(to_csv(tr))))
    assert rows[0] == ["task", "job", "release", "ready", "start", "finish", "cost"]
    assert len(rows) - 1 == sum(st.jobs for st in s.stats.values())
    assert rows[1] == ["log", "0", "0", "0", "0", "450", "450"]


def test_chrome_trace_has_complete_events_per_task_and_instants():
    s, tr = _traced_run()
    doc = json.loads(json.dumps(to_chrome(tr, 1_000_000)))
    events = doc["traceEvents"]
    jobs = [e for e in events if e["ph"] == "X"]
    assert len(jobs) == len(tr.jobs())
    tids = {e["name"]: e["tid"] for e in jobs}
    assert tids == {"ctrl": 1, "log": 2}  # one thread per task, in priority order
    first_ctrl = next(e for e in jobs if e["name"] == "ctrl")
    assert (first_ctrl["ts"], first_ctrl["dur"]) == (450.0, 200.0)  # µs at 1 MHz
    names = {e["args"]["name"] for e in events if e["ph"] == "M" and e["name"] == "thread_name"}
    assert names == {"ctrl", "log"}
    kinds = {e["cat"] for e in events if e["ph"] == "i"}
    assert kinds == {"deadline_miss", "watchdog_reset"}
    miss = next(e for e in events if e["ph"] == "i" and e["cat"] == "deadline_miss")
    assert miss["ts"] == 400.0 and miss["tid"] == tids["ctrl"]


def test_fault_events_are_traced(tmp_path):
    tr = Trace()
    s = Scheduler([Task("x", 1, 10, cost=15, overrun=OverrunPolicy.FAULT)], trace=tr,
                  on_fault=lambda f: None)
    s.run_until(30)
    events = [(e.kind, e.time, e.source, e.job) for e in tr.events()]
    assert events[:2] == [("deadline_miss", 10, "x", 0), ("fault", 10, "x", 0)]
    path = tmp_path / "t.json"
    write_chrome(tr, path, 168_000_000)
    doc = json.loads(path.read_text())
    x = [e for e in doc["traceEvents"] if e["ph"] == "X"]
    assert x[0]["dur"] == pytest.approx(15 / 168)


def test_write_chrome_writes_the_bytes_of_to_chrome(tmp_path):
    import json

    from rtos.trace import Trace

    tr = Trace(maxlen=50)
    tr.task_names = ["ctl", "log"]
    for k in range(80):  # more than maxlen: the window of the last 50
        tr.add_job("ctl" if k % 3 else "other", k, 1000 * k, 1000 * k + 7, 1000 * k + 9, 1000 * k + 420)
    tr.add_event("fault", 12345, "ctl", 4)
    tr.add_event("watchdog_reset", 99999, "board")
    path = tmp_path / "trace.json"
    write_chrome(tr, path, 168_000_000)
    assert path.read_text(encoding="utf-8") == json.dumps(to_chrome(tr, 168_000_000))
    assert [p.name for p in tmp_path.iterdir()] == ["trace.json"]


def _irq_run(maxlen: int) -> Trace:
    """Two tasks preempted by two periodic interrupts (one whose firings land inside jobs at several times) and one
    that fires at given times."""
    from rtos import PeriodicInterrupt, TimestampedInterrupt

    tr = Trace(maxlen=maxlen)
    tasks = [Task("fast", 1, 100, cost=30), Task("slow", 2, 250, cost=70, offset=5)]
    irqs = [PeriodicInterrupt("tick", period=40, cost=3), PeriodicInterrupt("rx", period=170, cost=9, offset=11),
            TimestampedInterrupt("uart", cost=5, times=range(7, 20_000, 230))]
    Scheduler(tasks, VirtualClock(1_000_000), interrupts=irqs, trace=tr).run_until(20_000)
    return tr


def _in(irqs, jobs):
    """The interrupt records of ``jobs``."""
    starts = {j.start for j in jobs}
    return [i for i in irqs if i.job_start in starts]


def test_a_bounded_trace_keeps_what_an_unbounded_one_ends_with_and_frees_the_rest():
    whole, kept = _irq_run(10_000), _irq_run(7)
    assert len(kept._codes) <= 2 * 7  # freed as the run went (a chunk of 7 jobs at a time), not only when read
    assert len(kept._irqs) - kept._irq0 <= 7  # the uart's records, of those jobs at most
    assert len(whole.irqs()) > 100 and any(len(i.times) > 1 for i in whole.irqs())
    assert {i.source for i in whole.irqs()} == {0, 1, 2}
    assert kept.jobs() == whole.jobs()[-7:] and kept.irqs() == _in(whole.irqs(), kept.jobs()) and len(kept) == 7
    kept.compact()
    assert len(kept._codes) < 2 * 7
    assert kept.jobs() == whole.jobs()[-7:] and kept.irqs() == _in(whole.irqs(), kept.jobs())


def test_a_periodic_sources_firing_times_derived_on_reading_are_those_it_tells():
    """The hot loop keeps no firing times of a periodic source (CountingSource.periodic): reading derives them."""
    from hal.virtual.timer import SysTick
    from rtos import PeriodicInterrupt

    tr = _irq_run(10_000)
    assert tr.periodic == [(40, 0), (170, 11), None]
    uart = [i for i in tr.irqs() if i.source == 2]
    assert len(tr._irqs) == len(uart) > 10  # the records kept: the uart's
    finish = {j.start: j.finish for j in tr.jobs()}
    sources = [PeriodicInterrupt("tick", period=40, cost=3), PeriodicInterrupt("rx", period=170, cost=9, offset=11)]
    assert all(i.times == sources[i.source].fired_at(i.job_start, finish[i.job_start]) and len(i.times) == i.firings
               for i in tr.irqs() if i.source < 2)
    interference = {j.start: j.finish - j.start - j.cost for j in tr.jobs()}  # as the scheduler solved it
    for start, preempted in interference.items():
        assert preempted == sum(i.firings * (3, 9, 5)[i.source] for i in tr.irqs() if i.job_start == start)
    tick = SysTick(1_000_000).interrupt(5)  # fires at k * 1000 cycles, k >= 1
    assert tick.periodic() == (1000, 1000)
    for t0, t1 in ((0, 3000), (1, 3001), (999, 3999), (1000, 3001), (5001, 8001)):
        fired = tick.fired_at(t0, t1)
        assert firings_from((1000, 1000), t0, len(fired)) == fired and fired


def test_prune_before_forgets_the_jobs_finished_and_the_firings_in_them_before():
    tr, whole = _irq_run(10_000), _irq_run(10_000)
    tr.prune_before(12_345)
    assert tr.jobs() == [j for j in whole.jobs() if j.finish >= 12_345]
    assert tr.irqs() == _in(whole.irqs(), tr.jobs()) and {i.source for i in tr.irqs()} == {0, 1, 2}
    tr.compact()
    assert tr.irqs() == _in(whole.irqs(), tr.jobs()) and len(tr) == len(tr.jobs())


def test_records_keep_values_of_any_width_exactly():
    """The arrays start at 8 bits per field and widen (16, 32, 64) for a value that needs it, without losing one."""
    tr = Trace(maxlen=10)
    values = [0, 127, -128, 128, 40_000, -(2**31), 2**31, 2**61]
    for k, v in enumerate(values):
        start = abs(v) + k
        tr.add_job("t", abs(v), start - k, start - k, start, start + abs(v) + 3, abs(v))
    assert [(j.job, j.release, j.start, j.finish, j.cost) for j in tr.jobs()] == [
        (abs(v), abs(v), abs(v) + k, abs(v) + k + abs(v) + 3, abs(v)) for k, v in enumerate(values)]


def _varied_run(maxlen: int, prune: int = 0):
    """Jobs whose timing their task does not predict (jitter, a cost model, late and skipped releases, interrupts),
    with what each body saw, and a skipped task; pruned at ``prune`` cycles (0: not) halfway through."""
    from rtos import PeriodicInterrupt

    seen = []

    def body(job):
        seen.append((job.task.name, job.index, job.release, job.ready, job.start))
        return job.index

    tr = Trace(maxlen=maxlen, skip=("probe",))
    tasks = [Task("fast", 1, 100, cost=30, body=body, jitter=20),
             Task("modelled", 2, 300, cost=lambda n: 60 + 170 * (n % 4 == 0), body=body,
                  overrun=OverrunPolicy.LATE),
             Task("slow", 3, 700, cost=400, body=body, offset=5),
             Task("probe", 9, 50, cost=0, body=body)]
    s = Scheduler(tasks, VirtualClock(1_000_000), interrupts=[PeriodicInterrupt("tick", period=40, cost=3)], trace=tr)
    s.run_until(15_000)
    if prune:
        tr.prune_before(prune)
    s.run_until(30_000)
    return s, tr, [v for v in seen if v[0] != "probe"]


def test_jobs_their_task_does_not_predict_read_back_as_they_ran():
    s, tr, seen = _varied_run(100_000)
    jobs = tr.jobs()
    assert [(j.task, j.job, j.release, j.ready, j.start) for j in jobs] == seen
    assert all(j.cost == (60 + 170 * (j.job % 4 == 0) if j.task == "modelled" else {"fast": 30, "slow": 400}[j.task])
               for j in jobs)
    tick = s.interrupt_stats()[0]
    assert sum(j.finish - j.start - j.cost for j in jobs) == tick.in_jobs * tick.cost_cycles > 0
    assert sum(j.finish - j.start for j in jobs if j.task == "slow") == s.stats["slow"].busy_cycles + 3 * sum(
        i.firings for i in tr.irqs() if i.job_start in {j.start for j in jobs if j.task == "slow"})
    late = [j for j in jobs if j.start - j.release >= 300 and j.task == "modelled"]
    assert late and s.stats["slow"].skipped and any(j.ready > j.release for j in jobs)
    tr.compact()
    # beside the jobs: the side records of the jobs whose job, release, ready or cost differ from their task's
    # timing (all of the jittered task's), the interference of others, the starts of the jittered ones
    assert 0 < len(tr._interference) and 0 < len(tr._differs) < len(tr) and 0 < len(tr._given) < len(tr)


def test_a_ring_and_a_prune_keep_the_jobs_a_whole_trace_ends_with():
    _, whole, _ = _varied_run(100_000)
    _, kept, _ = _varied_run(13)
    assert kept.jobs() == whole.jobs()[-13:]
    _, pruned, _ = _varied_run(100_000, prune=12_345)
    rest = [j for j in whole.jobs() if j.finish >= 12_345 or j.start >= 15_000]
    assert pruned.jobs() == rest and pruned.jobs()[0].finish >= 12_345
    pruned.compact()
    assert pruned.jobs() == rest


def test_jobs_are_kept_as_a_code_each_and_read_back_mid_run_as_after_it():
    """A periodic task set's jobs start at the previous job's finish or at their own release: no start is kept for
    them; a body that reads the trace while the loop appends (the loop holds the last finish) changes nothing."""
    from rtos import PeriodicInterrupt

    def run(read_every: int) -> tuple[Trace, list[int]]:
        tr = Trace(maxlen=60)  # read from a checkpoint of the loop's or of a read mid-run
        lengths: list[int] = []

        def body(job) -> None:
            if read_every and job.index % read_every == 0:
                lengths.append(len(tr.jobs()))

        tasks = [Task("fast", 1, 100, cost=30, body=body), Task("slow", 2, 250, cost=70, offset=5)]
        irqs = [PeriodicInterrupt("tick", period=40, cost=3)]
        Scheduler(tasks, VirtualClock(1_000_000), interrupts=irqs, trace=tr).run_until(20_000)
        return tr, lengths

    quiet, _ = run(0)
    read, lengths = run(7)
    assert read.jobs() == quiet.jobs() and len(lengths) > 20 and lengths[-1] == 60
    assert len(quiet._given) == 0 and len(quiet.jobs()) == 60 and quiet.jobs()[-1].finish > 19_000

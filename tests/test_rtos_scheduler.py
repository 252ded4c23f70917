"""The cooperative scheduler: ordering, cost models, job fields, overrun policies, stops, statistics."""

from __future__ import annotations

import pytest

from rtos import Fault, OverrunError, OverrunPolicy, Scheduler, Task, Trace


def _traced(tasks, t_end, **kw):
    tr = Trace()
    s = Scheduler(tasks, trace=tr, **kw)
    s.run_until(t_end)
    return s, [(j.task, j.job, j.start, j.finish) for j in tr.jobs()]


def test_priorities_must_be_unique_and_names_too():
    with pytest.raises(ValueError, match="priority 3 is used by both 'a' and 'b'"):
        Scheduler([Task("a", 3, 10, cost=1), Task("b", 3, 20, cost=1)])
    with pytest.raises(ValueError, match="name 'a'"):
        Scheduler([Task("a", 1, 10, cost=1), Task("a", 2, 20, cost=1)])


@pytest.mark.parametrize("field,value", [("period", 0), ("period", -5), ("cost", -1), ("offset", -1),
                                         ("deadline", 0), ("jitter", 11), ("priority", 1.5)])
def test_task_validation_names_the_value(field, value):
    kw = {"name": "x", "priority": 1, "period": 10, "cost": 1, field: value}
    with pytest.raises(ValueError, match=field):
        Task(**kw)


def test_smaller_number_runs_first_and_nothing_preempts():
    tasks = [Task("low", 5, 100, cost=30), Task("high", 1, 10, cost=2, offset=1)]
    _, jobs = _traced(tasks, 45)
    # low starts at 0 (high not yet released) and runs to 30 unpreempted; high's job 0 (released at 1)
    # runs late at 30, and under SKIP the releases 11, 21, 31 that came while it was pending are dropped
    assert jobs[:3] == [("low", 0, 0, 30), ("high", 0, 30, 32), ("high", 4, 41, 43)]


def test_simultaneous_release_highest_priority_first_and_idle_jumps():
    tasks = [Task(n, p, 50, cost=5) for n, p in (("c", 3), ("a", 1), ("b", 2))]
    _, jobs = _traced(tasks, 60)
    # c's second job would start at 60 = t_end: not run in this call
    assert jobs == [("a", 0, 0, 5), ("b", 0, 5, 10), ("c", 0, 10, 15), ("a", 1, 50, 55), ("b", 1, 55, 60)]


def test_cost_callable_gets_the_body_result_and_job_fields():
    seen = []
    sched = None

    def body(job):
        seen.append((job.index, job.release, job.ready, job.start, job.deadline, sched.now))
        return 4 * (job.index + 1)  # bytes handled

    t = Task("rx", 1, 100, deadline=80, offset=7, cost=lambda nbytes: 10 + 3 * nbytes, body=body)
    sched = Scheduler([t])
    tr = Trace()
    sched.trace = tr
    sched.run_until(300)
    assert seen == [(0, 7, 7, 7, 87, 7), (1, 107, 107, 107, 187, 107), (2, 207, 207, 207, 287, 207)]
    assert [j.finish - j.start for j in tr.jobs()] == [22, 34, 46]
    assert sched.stats["rx"].busy_cycles == 22 + 34 + 46


def test_cost_callable_must_return_cycles():
    s = Scheduler([Task("x", 1, 10, cost=lambda r: -1)])
    with pytest.raises(ValueError, match="-1"):
        s.run_until(10)


def test_skip_drops_and_counts_overrun_releases():
    s, jobs = _traced([Task("x", 1, 10, cost=25, overrun=OverrunPolicy.SKIP)], 100)
    # each job ends at 25 after its release: releases +10, +20 are dropped, next at +30
    assert [j[2] for j in jobs] == [0, 30, 60, 90]
    assert s.stats["x"].skipped == 2 * 4  # the last job's overruns are counted when it finishes (115)
    assert s.stats["x"].jobs == 4


def test_late_keeps_one_pending_release():
    s, jobs = _traced([Task("x", 1, 10, cost=25, overrun=OverrunPolicy.LATE)], 60)
    # job 0 [0,25): releases 10 and 20 come; 10 is kept (runs late at 25), 20 is dropped
    assert jobs[:3] == [("x", 0, 0, 25), ("x", 1, 25, 50), ("x", 3, 50, 75)]
    # job 1 [25, 50): 30 kept, 40 dropped; job 3 [50, 75): 50 kept, 60 and 70 dropped
    assert s.stats["x"].skipped == 1 + 1 + 2


def test_queue_keeps_every_release():
    s, jobs = _traced([Task("x", 1, 10, cost=15, overrun=OverrunPolicy.QUEUE)], 50)
    assert [(j[1], j[2]) for j in jobs] == [(0, 0), (1, 15), (2, 30), (3, 45)]
    assert s.stats["x"].skipped == 0 and s.stats["x"].worst_response == 45 + 15 - 30


def test_fault_goes_to_the_handler():
    faults: list[Fault] = []
    s = Scheduler([Task("x", 1, 10, cost=25, overrun=OverrunPolicy.FAULT)], on_fault=faults.append)
    s.run_until(31)
    assert faults[0] == Fault(time=10, task="x", job=0, missed=2)
    assert s.stats["x"].faults == len(faults) == 2 and s.stats["x"].skipped == 4


def test_fault_without_handler_raises():
    s = Scheduler([Task("x", 1, 10, cost=11, overrun=OverrunPolicy.FAULT)])
    with pytest.raises(OverrunError, match="'x' job 0"):
        s.run_until(100)


def test_request_stop_from_a_body_stops_after_that_job():
    s = None

    def body(job):
        if job.index == 3:
            s.request_stop()

    s = Scheduler([Task("x", 1, 10, cost=2, body=body)])
    s.run_until(1000)
    assert s.now == 32 and s.stats["x"].jobs == 4
    s.run_until(60)  # resumes where it stopped
    assert s.stats["x"].jobs == 6 and s.now == 60


def test_run_until_lets_a_started_job_finish_and_half_open_end():
    s = Scheduler([Task("x", 1, 100, cost=30)])
    s.run_until(10)
    assert s.now == 30
    s.run_for(70)  # to 100: the release at 100 is not run yet
    assert s.now == 100 and s.stats["x"].jobs == 1
    with pytest.raises(ValueError, match="past"):
        s.run_until(50)


def test_progress_reports_fractions_up_to_one():
    got = []
    s = Scheduler([Task("x", 1, 10, cost=1)])
    s.run_until(10_000, progress=got.append)
    assert got[-1] == 1.0 and got == sorted(got) and 50 <= len(got) <= 102


def test_statistics_responses_jitter_misses_streaks():
    # "b" (period 10, deadline 6) is blocked 3 cycles by "a" every other job: responses alternate 6 and 3
    tasks = [Task("a", 2, 20, cost=5, offset=0), Task("b", 1, 10, deadline=6, cost=3, offset=2)]
    s = Scheduler(tasks)
    s.run_until(200)
    b = s.stats["b"]
    assert (b.best_response, b.worst_response, b.mean_response) == (3, 6, 4.5)
    assert b.start_jitter == 3 and b.finish_jitter == 3
    assert b.deadline_misses == 0
    assert b.worst_blocker is not None and (b.worst_blocker.task, b.worst_blocker.cycles) == ("a", 3)
    tight = Scheduler([Task("a", 2, 20, cost=5), Task("b", 1, 10, deadline=5, cost=3, offset=2)])
    tight.run_until(200)
    assert tight.stats["b"].deadline_misses == 10 and tight.stats["b"].longest_miss_streak == 1
    u = s.utilisation()
    assert u.elapsed_cycles == 200 and u.task_cycles == {"b": 60, "a": 50} and u.total == pytest.approx(0.55)


def test_longest_miss_streak_counts_consecutive_misses():
    count = {"n": 0}

    def cost(_):
        count["n"] += 1
        return 9 if 3 <= count["n"] <= 6 else 1

    s = Scheduler([Task("x", 1, 10, deadline=5, cost=cost)])
    s.run_until(200)
    assert s.stats["x"].deadline_misses == 4 and s.stats["x"].longest_miss_streak == 4


def test_jitter_is_bounded_and_seeded():
    def run(seed):
        tr = Trace()
        Scheduler([Task("x", 1, 100, cost=1, jitter=30)], trace=tr, seed=seed).run_until(10_000)
        return [j.ready - j.release for j in tr.jobs()]

    a = run(1)
    assert a == run(1) and a != run(2)
    assert min(a) >= 0 and max(a) <= 30 and len(set(a)) > 10


def test_an_exception_from_a_body_leaves_the_job_pending_and_the_scheduler_usable():
    calls = []

    def flaky(job):
        calls.append(job.start)
        if len(calls) == 2:
            raise KeyError("boom")

    s = Scheduler([Task("x", 1, 10, cost=2, body=flaky), Task("y", 2, 10, cost=3)])
    with pytest.raises(KeyError):
        s.run_until(100)
    assert s.now == 10 and s.stats["x"].jobs == 1
    s.run_until(100)
    assert calls[:3] == [0, 10, 10] and s.stats["x"].jobs == 10 and s.stats["y"].jobs == 10


def test_after_an_overrun_error_the_run_can_continue():
    s = Scheduler([Task("x", 1, 10, cost=11, overrun=OverrunPolicy.FAULT), Task("y", 2, 7, cost=1)])
    with pytest.raises(OverrunError):
        s.run_until(100)
    assert s.now == 11
    s.on_fault = lambda fault: None
    s.run_until(100)
    assert s.stats["y"].jobs >= 10 and s.stats["x"].faults >= 4

"""The independent watchdog: resets at the exact cycle, re-arms, is kept quiet by timely kicks."""

from __future__ import annotations

import pytest

from rtos import Scheduler, Task, Trace, Watchdog


def _kicker(wd, stop_after=None):
    def body(job):
        if stop_after is None or job.index < stop_after:
            wd.kick()

    return body


def test_no_kick_resets_every_timeout_while_idle():
    resets = []
    s = Scheduler([Task("x", 1, 10_000, cost=1)])
    wd = s.add_watchdog(Watchdog(1000, on_reset=resets.append))
    s.run_until(3500)
    assert resets == [1000, 2000, 3000] and wd.resets == 3 and wd.due == 4000


def test_timely_kicks_keep_it_quiet_and_a_missed_kick_resets_at_the_right_cycle():
    resets = []
    wd = Watchdog(2500, on_reset=resets.append)
    # kicks at 0, 1000, ..., 4000 (index < 5); the last kick at 4000 -> reset at 6500, then re-armed
    s = Scheduler([Task("feed", 1, 1000, offset=0, cost=3, body=_kicker(wd, stop_after=5))])
    s.add_watchdog(wd)
    s.run_until(9500)
    assert resets == [6500, 9000]
    assert wd.kicks == 5


def test_on_reset_sees_the_scheduler_at_or_after_the_reset_instant():
    nows = []
    s = None
    s = Scheduler([Task("x", 1, 700, cost=300)])
    s.add_watchdog(Watchdog(1000, on_reset=lambda t: nows.append((t, s.now))))
    s.run_until(2000)
    # the job [700, 1000) ends exactly at the deadline: the reset fires at 1000; the one due at 2000 is
    # left for the next run (runs are half-open), and fires as soon as it starts
    assert nows == [(1000, 1000)]
    s.run_until(2001)
    assert nows == [(1000, 1000), (2000, 2000)]


def test_reset_inside_a_long_job_is_stamped_at_the_deadline():
    resets = []
    s = Scheduler([Task("long", 1, 10_000, cost=2500, offset=100)])
    s.add_watchdog(Watchdog(1000, on_reset=resets.append))
    s.run_until(2700)
    # idle until 100 is fine (due 1000); the job [100, 2600) overruns two deadlines: 1000 and 2000
    assert resets == [1000, 2000]


def test_kick_exactly_at_the_deadline_is_too_late():
    resets = []
    wd = Watchdog(1000, on_reset=resets.append)
    s = Scheduler([Task("feed", 1, 1000, cost=1, body=_kicker(wd))])
    s.add_watchdog(wd)
    s.run_until(3001)
    # kicks at 0 -> due 1000; the kick at 1000 comes after the reset at 1000, which re-armed to 2000 ...
    assert resets == [1000, 2000, 3000]


def test_resets_are_traced():
    tr = Trace()
    s = Scheduler([Task("x", 1, 5000, cost=1)], trace=tr)
    s.add_watchdog(Watchdog(2000))
    s.run_until(4500)
    assert [(e.kind, e.time) for e in tr.events()] == [("watchdog_reset", 2000), ("watchdog_reset", 4000)]


def test_watchdog_validation_and_unbound_kick():
    with pytest.raises(ValueError, match="timeout"):
        Watchdog(0)
    wd = Watchdog(10)
    with pytest.raises(RuntimeError, match="not attached"):
        wd.kick()
    wd.arm(5)
    wd.kick(12)
    assert wd.due == 22

"""The kernel's boundaries at equality: a bound equal to its deadline is met, a job that ends exactly at its next
release did not overrun, a job released exactly when the running one ends was not blocked."""

from __future__ import annotations

from pathlib import Path

import pytest

from host_tools.cli import main
from rtos import OverrunPolicy, Scheduler, Task
from rtos.analysis import response_time_bounds


@pytest.mark.parametrize(("deadline", "schedulable"), [(14, True), (13, False)])
def test_a_bound_equal_to_the_deadline_is_schedulable(deadline, schedulable):
    # b waits for at most one job of a (cost 10, released just after b) and runs 4: bound 14 exactly
    tasks = [Task("a", 1, 100, cost=10), Task("b", 2, 100, deadline=deadline, cost=4)]
    bounds = {b.name: b for b in response_time_bounds(tasks)}
    assert bounds["b"].bound == 14
    assert bounds["b"].schedulable is schedulable


@pytest.mark.parametrize(("deadline", "code"), [(4, 0), (3, 1)])
def test_rta_exit_code_at_equality(tmp_path: Path, capsys, deadline, code):
    path = tmp_path / "one.toml"
    path.write_text(f'unit = "cycles"\nf_cpu_hz = 1000\n[[task]]\nname = "x"\npriority = 1\nperiod = 10\n'
                    f"deadline = {deadline}\ncost = 4\n", encoding="utf-8")
    assert main(["rta", str(path), "--json"]) == code
    assert '"bound": 4' in capsys.readouterr().out


@pytest.mark.parametrize("policy", list(OverrunPolicy))
def test_a_job_that_ends_exactly_at_its_next_release_did_not_overrun(policy):
    s = Scheduler([Task("x", 1, 10, cost=10, overrun=policy)])  # FAULT would raise OverrunError without a handler
    s.run_until(100)
    st = s.stats["x"]
    assert (st.jobs, st.skipped, st.faults, st.deadline_misses) == (10, 0, 0, 0)


@pytest.mark.parametrize("policy", list(OverrunPolicy))
def test_one_cycle_more_is_an_overrun(policy):
    faults = []
    s = Scheduler([Task("x", 1, 10, cost=11, overrun=policy)], on_fault=faults.append)
    s.run_until(100)
    st = s.stats["x"]
    if policy is OverrunPolicy.FAULT:
        assert st.faults >= 1 and faults
    elif policy is OverrunPolicy.SKIP:
        assert st.skipped >= 1
    assert st.deadline_misses >= 1


@pytest.mark.parametrize(("offset", "blocked"), [(10, None), (9, 1), (5, 5)])
def test_a_job_released_as_the_running_one_ends_was_not_blocked(offset, blocked):
    s = Scheduler([Task("low", 5, 100, cost=10), Task("high", 1, 100, cost=1, offset=offset)])
    s.run_until(50)
    blocker = s.stats["high"].worst_blocker
    if blocked is None:
        assert blocker is None
    else:
        assert blocker is not None and (blocker.task, blocker.cycles) == ("low", blocked)

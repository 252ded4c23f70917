"""The cooperative (non-preemptive) fixed-priority scheduler: one slot per task, one ready bitmask."""

from __future__ import annotations

import logging
import random
from collections.abc import Callable, Iterable
from typing import Final

from rtos.clock import Clock, VirtualClock
from rtos.interrupts import CountingSource, InterruptSource, bind_sources, is_interrupt_source, solve_bound
from rtos.slot import Slot
from rtos.stats import Blocker, InterruptStats, TaskStats, Utilisation
from rtos.task import Fault, OverrunError, OverrunPolicy, Task, by_priority
from rtos.trace import AT_GIVEN, AT_NEXT_RELEASE, CODES, DIFFERS, NEW_INTERFERENCE, Trace
from rtos.watchdog import Watchdog

log = logging.getLogger(__name__)

_MAX_TASKS: Final = 256  # tasks per scheduler (a wider ready bitmask works, but no longer as a native int)
_FAR: Final = 1 << 61  # later than any event (435 years at 168 MHz); an unboxed int in compiled code
_LATE: Final = OverrunPolicy.LATE
_FAULT: Final = OverrunPolicy.FAULT


class SchedulerNow:
    """A callable giving a scheduler's ``now``, for objects built before the scheduler (a bench's clock).

    Create it, hand it out, then ``bind`` the scheduler; calling it before that raises RuntimeError.
    Being compiled, a call from compiled code costs a native call and a field read.
    """

    def __init__(self) -> None:
        """An unbound source (no scheduler yet)."""
        self._scheduler: Scheduler | None = None

    def bind(self, scheduler: Scheduler) -> None:
        """Read ``scheduler``'s time from now on."""
        self._scheduler = scheduler

    def __call__(self) -> int:
        """The bound scheduler's current time in cycles (during a job body: the job's start)."""
        s = self._scheduler
        if s is None:
            raise RuntimeError("SchedulerNow called before a scheduler was bound to it")
        return s._now


class Scheduler:
    """Runs tasks cooperatively: at each scheduling point the highest-priority ready job runs to completion.

    In virtual time (``VirtualClock``) a job's finish is ``start + cost`` plus the cycles of every
    interrupt firing while it runs (solved exactly); when nothing is ready, time jumps to the next
    release or watchdog deadline. With a ``WallClock`` the same loop waits for absolute wall times and
    measures each job instead (interrupt sources are then not modelled).

    >>> s = Scheduler([Task("fast", 1, period=10, cost=3), Task("slow", 2, period=25, cost=8)])
    >>> s.run_until(100)
    >>> s.stats["fast"].jobs, s.stats["slow"].worst_response
    (10, 11)
    """

    def __init__(
        self,
        tasks: Iterable[Task],
        clock: Clock | None = None,
        *,
        interrupts: Iterable[InterruptSource] = (),
        trace: Trace | None = None,
        on_fault: Callable[[Fault], None] | None = None,
        seed: int = 0,
    ) -> None:
        """Set up the tasks (priorities unique, smaller = higher); ``clock`` defaults to 1 MHz virtual."""
        self.clock: Clock = clock if clock is not None else VirtualClock(1_000_000)
        self._tasks = by_priority(tasks)
        if len(self._tasks) > _MAX_TASKS:
            raise ValueError(f"at most {_MAX_TASKS} tasks are supported, got {len(self._tasks)}")
        self._interrupts: list[InterruptSource] = list(interrupts)
        for src in self._interrupts:
            if not is_interrupt_source(src):
                raise ValueError(f"{src!r} is not an InterruptSource (name, cost_cycles, count_in)")
        self.trace = trace
        if trace is not None:
            trace.task_names = [t.name for t in self._tasks]
            trace.interrupts = [(src.name, src.cost_cycles) for src in self._interrupts]
            # on the wall clock interrupts are not modelled: no firings to derive
            trace.periodic = [src.periodic() if isinstance(src, CountingSource) and not self.clock.realtime else None
                              for src in self._interrupts]
        self.on_fault = on_fault
        self._rng = random.Random(seed)
        self._now = 0
        self._stop = False
        self._started = False
        self._watchdogs: list[Watchdog] = []
        self.stats: dict[str, TaskStats] = {t.name: TaskStats(t.name) for t in self._tasks}
        self._stat_list = [self.stats[t.name] for t in self._tasks]
        self._irq_in_job = [0] * len(self._interrupts)
        self._irq_idle = [0] * len(self._interrupts)
        self._mask = 0
        self._prev = -1  # rank of the job that ran last (-1: the CPU was idle)
        self._prev_release = 0  # its nominal release
        self._slots: list[Slot] = []
        for i, t in enumerate(self._tasks):
            ready = t.offset + (self._rng.randint(0, t.jitter) if t.jitter else 0)
            self._slots.append(Slot(i, t, self._stat_list[i], ready))

    @property
    def now(self) -> int:
        """Current time in cycles (during a job body: the job's start)."""
        return self._now

    @property
    def tasks(self) -> list[Task]:
        """The tasks, highest priority first."""
        return list(self._tasks)

    def add_watchdog(self, watchdog: Watchdog) -> Watchdog:
        """Attach ``watchdog``: it is armed now and its kicks use this scheduler's ``now``."""
        watchdog.bind(self)
        watchdog.kick_log = self.trace.kick_log() if self.trace is not None else None
        self._watchdogs.append(watchdog)
        return watchdog

    def request_stop(self) -> None:
        """Stop ``run_until`` at the next scheduling point (the running job completes first)."""
        self._stop = True

    def run_for(self, cycles: int, progress: Callable[[float], None] | None = None) -> None:
        """Run for ``cycles`` more cycles (see ``run_until``)."""
        self.run_until(self._now + cycles, progress)

    def releases(self, name: str, before: int | None = None) -> int:
        """Nominal releases of task ``name`` before ``before`` (default ``now``): jobs run, skipped and still due.

        With a wall clock the host may end a run behind schedule; releases whose time has come but
        whose job has not started yet are counted here too, so the count reflects the absolute release
        times (offset + k * period < before), not how many jobs the host managed to run. A run ends at
        the last job's finish, which may lie past the end asked of ``run_until``: pass that end as
        ``before`` to count the releases of the run's span only.
        """
        i = next((k for k, t in enumerate(self._tasks) if t.name == name), None)
        if i is None:
            raise ValueError(f"no task named {name!r}: tasks are {[t.name for t in self._tasks]}")
        end = self._now if before is None else min(before, self._now)
        st, pending_from, period = self._stat_list[i], self._slots[i].nrel, self._tasks[i].period
        due = -(-(end - pending_from) // period) if pending_from < end else 0
        return st.jobs + st.skipped + due

    def utilisation(self) -> Utilisation:
        """CPU utilisation from cycle 0 to now: busy cycles per task and per interrupt source."""
        return Utilisation(
            elapsed_cycles=self._now,
            task_cycles={s.name: s.busy_cycles for s in self._stat_list},
            interrupt_cycles={s.name: s.busy_cycles for s in self.interrupt_stats()},
        )

    def busy_cycles(self) -> int:
        """Cycles spent in jobs and interrupt service routines from cycle 0 to now (``utilisation().busy_cycles``)."""
        busy = 0
        for st in self._stat_list:
            busy += st.busy_cycles
        for j, src in enumerate(self._interrupts):
            busy += (self._irq_in_job[j] + self._irq_idle[j]) * src.cost_cycles
        return busy

    def interrupt_stats(self) -> list[InterruptStats]:
        """Firings per interrupt source so far, split into in-job and idle."""
        out = []
        for j, src in enumerate(self._interrupts):
            st = InterruptStats(src.name, src.cost_cycles)
            st.in_jobs, st.while_idle = self._irq_in_job[j], self._irq_idle[j]
            out.append(st)
        return out

    def _wd_due(self) -> int:
        """Earliest watchdog deadline, or _FAR."""
        best = None
        for w in self._watchdogs:
            due = w.due
            if due is not None and (best is None or due < best):
                best = due
        return _FAR if best is None else best

    def _fire_watchdogs(self, now: int, t_end: int) -> int:
        """Fire, in time order, every watchdog reset due at or before ``now`` and before ``t_end``.

        Returns the next deadline.
        """
        self._now = now
        while True:
            due = self._wd_due()
            if due > now or due >= t_end:
                return due
            wd = next(w for w in self._watchdogs if w.due == due)
            t = wd.expire()
            log.info("watchdog reset at cycle %d", t)
            if self.trace is not None:
                self.trace.add_event("watchdog_reset", t, "watchdog")

    def _overrun(self, slot: Slot, release: int, nxt: int, finish: int) -> Fault | None:
        """Apply the slot's policy to its releases in [nxt, finish); set its next job; maybe a Fault."""
        task, st = slot.task, slot.stats
        period = slot.period
        n = (finish - 1 - nxt) // period + 1
        fault = None
        if task.overrun is _LATE:  # keep the first as the pending job, drop the others
            st.skipped += n - 1
            slot.nnext = nxt + n * period
        else:
            st.skipped += n
            if task.overrun is _FAULT:
                fault = Fault(nxt, task.name, slot.index_of(release), n)
            nxt += n * period
            slot.nnext = nxt + period
        slot.nrel = nxt
        return fault

    def _overrun_fault(self, i: int, fault: Fault) -> None:
        """Record task ``i``'s FAULT-policy overrun and hand it to ``on_fault`` (or raise OverrunError)."""
        self._stat_list[i].faults += 1
        if self.trace is not None:
            self.trace.add_event("fault", fault.time, fault.task, fault.job)
        log.warning("overrun fault: %s", fault)
        if self.on_fault is None:
            raise OverrunError(fault)
        self.on_fault(fault)

    def _admit(self, now: int, prev: int, prev_release: int) -> tuple[int, int]:
        """Move every waiting slot whose ready time has come (<= ``now``) into the ready set.

        Returns (their bits for the ready mask, the earliest ready time still waiting or _FAR). A job
        that became ready while a lower-priority job (rank ``prev``, release ``prev_release``) ran
        records that job as its blocker.
        """
        bits = 0
        earliest = _FAR
        for slot in self._slots:
            if slot.waiting:
                r = slot.ready
                if r <= now:
                    slot.waiting = False
                    bits |= 1 << slot.rank
                    if prev > slot.rank and r < now:
                        slot.blocked_by, slot.blocked_release, slot.blocked_cycles = prev, prev_release, now - r
                elif r < earliest:
                    earliest = r
        return bits, earliest

    def _account(self, slot: Slot, release: int, start: int, finish: int, cost: int) -> None:
        """Add a finished job (nominal release, start, finish, cycles of its own) to the slot's statistics."""
        st = slot.stats
        resp = finish - release
        st.jobs += 1
        st.response_sum += resp
        st.busy_cycles += cost
        if resp > st.worst:
            st.worst = resp
            st.worst_job = slot.index_of(release)
            if slot.blocked_by < 0:
                st.worst_blocker = None
            else:
                p = self._slots[slot.blocked_by]
                st.worst_blocker = Blocker(p.name, p.index_of(slot.blocked_release), slot.blocked_cycles)
        if resp < st.best:
            st.best = resp
        d = start - release
        if d > st.delay_max:
            st.delay_max = d
        if d < st.delay_min:
            st.delay_min = d
        slot.blocked_by = -1
        if resp > slot.deadline:
            st.deadline_misses += 1
            st.miss_streak += 1
            if st.miss_streak > st.longest_miss_streak:
                st.longest_miss_streak = st.miss_streak
            if self.trace is not None:
                self.trace.add_event("deadline_miss", release + slot.deadline, slot.name, slot.index_of(release))
        elif st.miss_streak:
            st.miss_streak = 0

    def run_until(self, t_end: object, progress: Callable[[float], None] | None = None) -> None:
        """Run every job that can start before cycle ``t_end``; then ``now`` is ``max(t_end, last finish)``.

        A job started before ``t_end`` runs to completion even if it ends later. ``progress(fraction)``
        is called about every 1 % of the span and once with 1.0 at the end (unless stopped).
        ``t_end`` is typed ``object`` (docs/compiled.md, "Values checked as given"); the loop runs on the
        checked int.
        """
        if isinstance(t_end, bool) or not isinstance(t_end, int):
            raise ValueError(f"t_end must be an int number of cycles, got {t_end!r}")
        self._run(t_end, progress)

    def _run(self, t_end: int, progress: Callable[[float], None] | None) -> None:
        """:meth:`run_until` after its type check."""
        if t_end < self._now:
            raise ValueError(f"t_end {t_end} is in the past (now = {self._now} cycles)")
        if t_end >= _FAR:
            raise ValueError(f"t_end {t_end} out of range: below 2**61 cycles")
        clock = self.clock
        realtime = clock.realtime
        if not self._started:
            self._started = True
            clock.start(self._now)
        self._stop = False
        slots, trace = self._slots, self.trace
        jitter_draw = self._rng.randint  # bound once: the generator's draws, in the same order
        irqs = [] if realtime else bind_sources(self._interrupts)
        traced_irqs = [b for b in irqs if not b.periodic]  # the sources whose firings the trace records
        irq_in_job, irq_idle = self._irq_in_job, self._irq_idle
        wd_due = self._wd_due()
        wds = self._watchdogs
        tr_jobs: list[int] = []  # the trace's flat records (Trace.flat_records), appended to natively
        tr_given: list[int] = []
        tr_interference: list[int] = []
        tr_differs: list[int] = []
        tr_irqs: list[int] = []
        tr_times: list[int] = []
        tr_preempted: list[int] = []  # by task id: the last job's interference and cost - nominal (Trace.carried)
        tr_cost: list[int] = []
        trace_room = 0
        tr_last = -1  # the finish of the last job recorded (Trace.take_last_finish)
        for slot in slots:
            slot.trace_id = -1
        if trace is not None:
            tr_jobs, tr_given, tr_interference, tr_differs, tr_irqs, tr_times = trace.flat_records()
            tr_preempted, tr_cost = trace.carried()
            ids = trace.task_ids([(s.name, s.offset, s.period, s.cost) for s in slots])
            for slot, tid in zip(slots, ids, strict=True):
                if tid >= 0:
                    slot.trace_id, slot.trace_code = tid, tid * CODES
                    slot.carried_preempted, slot.carried_dcost = tr_preempted[tid], tr_cost[tid]
            trace_room = trace.room()
            tr_last = trace.take_last_finish()
        now, mask, prev, nrel_prev = self._now, self._mask, self._prev, self._prev_release
        next_ready = -1  # the earliest ready time of a waiting slot (-1: not known yet, look)
        t_begin = now
        span = max(1, t_end - t_begin)
        step = max(1, span // 100)
        next_progress = t_begin + step if progress is not None else _FAR
        next_check = min(wd_due, next_progress)  # the earlier of the two slow-path instants
        stopped = False
        try:  # on any exit, even an exception from a callback, keep the state consistent
            while True:
                if now >= next_check:
                    if now >= wd_due and wd_due < t_end:
                        wd_due = self._fire_watchdogs(now, t_end)
                    if now >= next_progress:
                        self._now = now
                        progress(min(1.0, (now - t_begin) / span))  # type: ignore[misc]
                        next_progress = now + step
                    next_check = min(wd_due, next_progress)
                    if self._stop:
                        stopped = True
                        break
                if now >= next_ready:
                    admitted, next_ready = self._admit(now, prev, nrel_prev)
                    mask |= admitted
                if now >= t_end:
                    break
                if not mask:  # idle: jump to the next release, watchdog deadline or the end
                    target = next_ready
                    if wd_due < target:
                        target = wd_due
                    if target > t_end:
                        target = t_end
                    for b in irqs:
                        k = b.src.count_in(now, target)
                        if k:
                            irq_idle[b.index] += k
                    now = clock.wait_until(target) if realtime else target
                    prev = -1
                    continue
                i = (mask & -mask).bit_length() - 1
                mask ^= 1 << i
                slot = slots[i]
                r = slot.nrel
                k = slot.index_of(r)
                start = now
                body = slot.body
                result: object = None
                if body is not None:
                    job = slot.job
                    job.index, job.release, job.ready, job.start = k, r, slot.ready, start
                    self._now = start
                    try:
                        result = body(job)
                    except BaseException:
                        mask |= 1 << i  # the job stays pending: the state is as before it started
                        raise
                    if len(wds) == 1:  # one watchdog (the usual case): its deadline, inline
                        due = wds[0].due
                        wd_due = _FAR if due is None else due
                        next_check = wd_due if wd_due < next_progress else next_progress
                    elif wds:
                        wd_due = self._wd_due()
                        next_check = min(wd_due, next_progress)
                    if self._stop:
                        stopped = True
                c = slot.cost
                if slot.cost_model is not None:
                    modelled = slot.cost_model(result)
                    if type(modelled) is not int or modelled < 0:
                        mask |= 1 << i
                        raise ValueError(
                            f"task {slot.name!r}: cost model returned {modelled!r}; need an int >= 0 cycles")
                    c = modelled
                if realtime:
                    f = max(start, clock.now_cycles())
                    c = f - start
                elif irqs and c:  # a zero-cost job spans an empty window: nothing can fire in it
                    f = solve_bound(start, c, irqs, irq_in_job)
                    if trace is not None and f != start + c:  # the firings the solve counted, of each source
                        for b in traced_irqs:  # that is not periodic (Trace.irqs derives those)
                            if b.hits:
                                tr_irqs.append(start)
                                tr_irqs.append(b.index)
                                tr_irqs.append(b.hits)
                                times = b.src.fired_at(start, f)
                                tr_irqs.append(len(times))
                                tr_times.extend(times)
                else:
                    f = start + c
                self._account(slot, r, start, f, c)
                tid = slot.trace_id
                if trace is not None and tid >= 0:  # the record as Trace.flat_records says (-1: skipped)
                    code = slot.trace_code
                    if start == tr_last:
                        pass  # AT_LAST_FINISH
                    elif start == r and r - slot.period <= tr_last < r:
                        code += AT_NEXT_RELEASE
                    else:
                        code += AT_GIVEN
                        tr_given.append(start)
                    tr_last = f
                    preempted, dcost = f - start - c, c - slot.cost
                    # its release is offset + k * period always (nrel moves by periods from the offset), kept
                    # anyway, as Trace.add_job's are
                    if slot.ready != r or dcost != slot.carried_dcost or start - r >= slot.period:
                        code += DIFFERS
                        tr_differs.append(k)
                        tr_differs.append(r - slot.offset - k * slot.period)
                        tr_differs.append(slot.ready - r)
                        tr_differs.append(preempted)
                        tr_differs.append(dcost)
                        tr_preempted[tid] = slot.carried_preempted = preempted
                        tr_cost[tid] = slot.carried_dcost = dcost
                    elif preempted != slot.carried_preempted:
                        code += NEW_INTERFERENCE
                        tr_interference.append(preempted)
                        tr_preempted[tid] = slot.carried_preempted = preempted
                    tr_jobs.append(code)
                    trace_room -= 1
                    if not trace_room:
                        trace.last_finish = tr_last
                        trace_room = trace.compact()
                        trace.last_finish = None
                # the task's next job: releases that came while this one was pending or running overran
                nxt = slot.nnext
                fault = None
                if nxt < f and slot.plain:
                    fault = self._overrun(slot, r, nxt, f)
                    nxt = slot.nrel
                else:
                    slot.nnext = nxt + slot.period
                    slot.nrel = nxt
                a = nxt + jitter_draw(0, slot.jitter) if slot.jitter else nxt
                slot.ready = a
                slot.waiting = True
                if a < next_ready:
                    next_ready = a
                prev, nrel_prev, now = i, r, f
                if fault is not None:
                    self._now = f
                    self._overrun_fault(i, fault)
                    stopped = stopped or self._stop
                if stopped:
                    break
            if not stopped and now < t_end:
                now = t_end
        finally:
            self._now, self._mask, self._prev, self._prev_release = now, mask, prev, nrel_prev
            if trace is not None:
                trace.last_finish = tr_last
        if progress is not None and not stopped:
            progress(1.0)

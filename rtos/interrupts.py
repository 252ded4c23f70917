"""Interrupt sources and the exact interference they add to a running job."""

from __future__ import annotations

import bisect
from collections.abc import Iterable, Iterator, Sequence
from typing import Protocol

from mypy_extensions import mypyc_attr

MAX_FIXED_POINT_STEPS = 1_000_000


class InterruptSource(Protocol):
    """Anything that fires interrupts: a name, the cycles of one service routine, and a firing count.

    ``count_in(t0, t1)`` returns how many times it fires in [t0, t1). Callers promise non-decreasing
    ``t0`` across calls, so a lazy source may advance its world to ``t1`` and forget the past.
    """

    name: str
    cost_cycles: int

    def count_in(self, t0: int, t1: int) -> int:
        """Number of firings in [t0, t1)."""
        ...


def is_interrupt_source(obj: object) -> bool:
    """Whether ``obj`` has the :class:`InterruptSource` shape (a str name, an int cost, a callable count_in).

    >>> is_interrupt_source(PeriodicInterrupt("systick", period=1000, cost=80)), is_interrupt_source(3)
    (True, False)
    """
    return (isinstance(getattr(obj, "name", None), str) and isinstance(getattr(obj, "cost_cycles", None), int)
            and callable(getattr(obj, "count_in", None)))


@mypyc_attr(allow_interpreted_subclasses=True)
class CountingSource:
    """Base class of interrupt sources that compiled callers count with a direct (native) call.

    A subclass sets ``name`` and ``cost_cycles`` and overrides ``count_in``. Any other object of the
    :class:`InterruptSource` shape is counted too, through a generic call of its bound ``count_in``.
    """

    name: str
    cost_cycles: int

    def count_in(self, t0: int, t1: int) -> int:
        """Number of firings in [t0, t1)."""
        raise NotImplementedError(f"{type(self).__name__} must define count_in(t0, t1)")

    def fired_at(self, t0: int, t1: int) -> tuple[int, ...]:
        """The firing cycles in [t0, t1), right after ``count_in(t0, t1)`` (for the trace); () when unknown."""
        return ()

    def periodic(self) -> tuple[int, int] | None:
        """(period, first firing cycle) of a source that fires at ``first + k * period`` for k = 0, 1, ... and at
        no other time, else None: its firings in a window follow from the window's start and their count, which
        the trace derives on export (:func:`firings_from`) instead of the hot loop asking ``fired_at``."""
        return None


def firings_from(pattern: tuple[int, int], t0: int, n: int) -> tuple[int, ...]:
    """The first ``n`` firing cycles from ``t0`` on of a source firing at ``first + k * period`` (``pattern``:
    (period, first), :meth:`CountingSource.periodic`).

    >>> firings_from((1000, 0), 1, 2), firings_from((1000, 1000), 0, 1)
    ((1000, 2000), (1000,))
    """
    period, first = pattern
    k = max(0, -((first - t0) // period))
    return tuple(first + j * period for j in range(k, k + n))


def _check_cost(name: str, cost: object) -> int:
    """Return ``cost`` if it is an int >= 0, else raise ValueError naming the source."""
    if isinstance(cost, bool) or not isinstance(cost, int) or cost < 0:
        raise ValueError(f"interrupt {name!r}: cost must be an int >= 0 cycles, got {cost!r}")
    return cost


class PeriodicInterrupt(CountingSource):
    """An interrupt that fires at ``offset + k * period`` for k = 0, 1, ... (e.g. SysTick).

    >>> PeriodicInterrupt("systick", period=1000, cost=80).count_in(0, 2500)
    3
    """

    def __init__(self, name: str, period: object, cost: object, offset: object = 0) -> None:
        """Check and store the firing pattern; ``period`` is also the minimum inter-arrival time."""
        if isinstance(period, bool) or not isinstance(period, int) or period <= 0:
            raise ValueError(f"interrupt {name!r}: period must be an int >= 1 cycles, got {period!r}")
        if isinstance(offset, bool) or not isinstance(offset, int) or offset < 0:
            raise ValueError(f"interrupt {name!r}: offset must be an int >= 0 cycles, got {offset!r}")
        self.name = name
        self.period = period
        self.cost_cycles = _check_cost(name, cost)
        self.offset = offset

    def _fired_before(self, t: int) -> int:
        """Number of firings in [0, t)."""
        if t <= self.offset:
            return 0
        return -((self.offset - t) // self.period)

    def count_in(self, t0: int, t1: int) -> int:
        """Number of firings in [t0, t1)."""
        if t1 <= t0:
            return 0
        return self._fired_before(t1) - self._fired_before(t0)

    def fired_at(self, t0: int, t1: int) -> tuple[int, ...]:
        """The firing cycles in [t0, t1).

        >>> PeriodicInterrupt("systick", period=1000, cost=80).fired_at(0, 2500)
        (0, 1000, 2000)
        """
        return firings_from((self.period, self.offset), t0, self.count_in(t0, t1))

    def periodic(self) -> tuple[int, int] | None:
        """(period, offset): it fires at offset + k * period."""
        return self.period, self.offset

    def __repr__(self) -> str:
        """Show the firing pattern."""
        return f"PeriodicInterrupt({self.name!r}, period={self.period}, cost={self.cost_cycles}, " \
            f"offset={self.offset})"


class TimestampedInterrupt(CountingSource):
    """An interrupt that fires at given, sorted cycle times, read lazily from any iterable.

    >>> irq = TimestampedInterrupt("uart_rx", cost=120, times=[10, 20, 20, 35])
    >>> irq.count_in(0, 20), irq.count_in(20, 100)
    (1, 3)
    """

    def __init__(self, name: str, cost: object, times: Iterable[int]) -> None:
        """Store the source; ``times`` must be non-decreasing."""
        self.name = name
        self.cost_cycles = _check_cost(name, cost)
        self._times: Iterator[int] = iter(times)
        self._buf: list[int] = []
        self._lo = 0
        self._exhausted = False

    def _pull_until(self, t: int) -> None:
        """Buffer firing times until one >= t is seen or the iterable ends."""
        buf = self._buf
        while not self._exhausted and (not buf or buf[-1] < t):
            try:
                nxt = next(self._times)
            except StopIteration:
                self._exhausted = True
                return
            if buf and nxt < buf[-1]:
                raise ValueError(f"interrupt {self.name!r}: times must be non-decreasing, got {nxt} "
                                 f"after {buf[-1]}")
            buf.append(nxt)

    def count_in(self, t0: int, t1: int) -> int:
        """Number of firings in [t0, t1); ``t0`` must not decrease between calls."""
        if t1 <= t0:
            return 0
        self._pull_until(t1)
        buf = self._buf
        lo = bisect.bisect_left(buf, t0, self._lo)
        if lo > 4096:  # forget the past so memory stays bounded
            del buf[:lo]
            lo = 0
        self._lo = lo
        return bisect.bisect_left(buf, t1, lo) - lo

    def fired_at(self, t0: int, t1: int) -> tuple[int, ...]:
        """The firing cycles in [t0, t1) (after ``count_in(t0, t1)``: the buffer holds them)."""
        buf = self._buf
        return tuple(buf[bisect.bisect_left(buf, t0, self._lo):bisect.bisect_left(buf, t1, self._lo)])


class _BoundCounter(CountingSource):
    """Any object of the :class:`InterruptSource` shape as a :class:`CountingSource` (its bound count_in)."""

    def __init__(self, src: InterruptSource) -> None:
        """Bind src's ``count_in`` once."""
        self.name = src.name
        self.cost_cycles = src.cost_cycles
        self._count_in = src.count_in
        self._fired_at = getattr(src, "fired_at", None)

    def count_in(self, t0: int, t1: int) -> int:
        """The wrapped source's firings in [t0, t1)."""
        return self._count_in(t0, t1)

    def fired_at(self, t0: int, t1: int) -> tuple[int, ...]:
        """The wrapped source's firing cycles in [t0, t1) if it tells them, else ()."""
        return () if self._fired_at is None else tuple(self._fired_at(t0, t1))


class BoundSource:
    """One interrupt source as :func:`solve_bound` reads it: its index, the source and its cost.

    ``src`` is a :class:`CountingSource` (any other source is wrapped once), so the compiled solver
    counts it with a direct call; ``periodic`` tells whether its firing times follow from a window's start
    (:meth:`CountingSource.periodic`); ``hits`` is scratch space of the solver (firings in the window of the
    current pass).
    """

    def __init__(self, index: int, src: CountingSource, cost: int) -> None:
        """Keep the source's index in the caller's tables, the source and its cost."""
        self.index = index
        self.src = src
        self.cost = cost
        self.hits = 0
        self.periodic = src.periodic() is not None  # its firing times follow from a window's start: not asked


BoundSources = list[BoundSource]
"""Interrupt sources bound for the hot loop, see :func:`bind_sources`."""


def bind_sources(sources: Sequence[InterruptSource]) -> BoundSources:
    """The sources as :class:`BoundSource` records for :func:`solve_bound` in a hot loop."""
    return [BoundSource(j, src if isinstance(src, CountingSource) else _BoundCounter(src), src.cost_cycles)
            for j, src in enumerate(sources)]


def solve_finish(start: int, cost: int, sources: Sequence[InterruptSource], counts: list[int]) -> int:
    """Return the least f with f = start + cost + sum_i cost_i * count_i(start, f), adding counts in place.

    ``counts[i]`` is incremented by the number of firings of ``sources[i]`` inside the job.

    >>> solve_finish(0, 100, [PeriodicInterrupt("t", period=30, cost=10)], [0])
    150
    """
    return solve_bound(start, cost, bind_sources(sources), counts)


def solve_bound(start: int, cost: int, bound: BoundSources, counts: list[int]) -> int:
    """:func:`solve_finish` on sources already bound with :func:`bind_sources`."""
    base = start + cost
    finish = base
    for _step in range(MAX_FIXED_POINT_STEPS):
        extra = 0
        fired = False
        for b in bound:
            k = b.src.count_in(start, finish)
            b.hits = k
            if k:
                extra += k * b.cost
                fired = True
        nxt = base + extra
        if nxt == finish:
            if fired:
                for b in bound:
                    if b.hits:
                        counts[b.index] += b.hits
            return finish
        finish = nxt
    raise RuntimeError(
        f"interrupt load never lets the job started at cycle {start} finish: the sources "
        f"{[b.src.name for b in bound]} saturate the CPU"
    )

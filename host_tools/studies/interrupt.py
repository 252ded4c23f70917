"""A stop signal that ends a long host-side job (a sweep, a tuning search) at once, through its own clean-up.

`pafp run` lets the running segment finish (:class:`~host_tools.stop_signals.StopSignals` sets a flag); a sweep
or a search waits on Dask futures that may take minutes, so here the first SIGINT, SIGTERM or SIGHUP raises
:class:`Interrupted` in the main thread instead. It is a ``BaseException`` (like ``KeyboardInterrupt``), so the
``except Exception`` that turns a failing point into a row does not swallow it; the ``finally`` clauses and
context managers on its way out run: the results table is flushed, the Dask client and its LocalCluster are
closed (no worker left behind, no leaked semaphore), and the command writes what it has, marked as
interrupted, and exits 128 + the signal's number.

This is the one interruption path of the long commands that wait on work they cannot pause (`pafp sweep`,
`design`, `faults`, `tune`, `fit`): each enters :func:`interrupting` around its work, catches
:class:`Interrupted` and prints :func:`stopped_line`. ``Interrupted.elapsed_s`` is the time from entering to the
signal (the report's "stopped after"). Their outputs are checked before the work by
:func:`host_tools.outdir.check_writable` (writable, at least 1 MiB free).
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from host_tools.stop_signals import EXIT_CODES, StopSignals

__all__ = ["Interrupted", "interrupting", "raise_if_stopped", "stopped_line"]

REDELIVER_AFTER_S = 0.02
"""How long after Python dropped the Interrupted (raised in a gc callback) its signal comes again: long enough for
the callback to return, so that the handler runs in the job's own code (if not, it is dropped and comes again)."""


class Interrupted(BaseException):
    """A stop signal arrived: ``signal`` is its name, ``exit_code`` 128 + its number."""

    def __init__(self, signal: str, elapsed_s: float = float("nan")) -> None:
        """The signal's name (SIGINT, SIGTERM, SIGHUP) and the seconds from :func:`interrupting` to it."""
        super().__init__(f"stopped by {signal}")
        self.signal = signal
        self.exit_code = EXIT_CODES.get(signal, 130)
        self.elapsed_s = elapsed_s


_STOPS: list[tuple[StopSignals, float]] = []
"""The entered :func:`interrupting` blocks, innermost last: (their signals, their start on perf_counter)."""


def raise_if_stopped() -> None:
    """Raise Interrupted if a stop signal came to an entered :func:`interrupting` block and its Interrupted was lost.

    A job that calls this is still running, so the Interrupted raised at the signal did not leave it: somewhere on its
    way it was swallowed without a trace (where Python reports it, :func:`interrupting` delivers the signal again).
    A loop calls this once per step (`run_tasks`, once per finished point), so a lost stop ends the job at its next
    step instead of letting it run on to its end and exit 0."""
    for signals, t0 in _STOPS:
        if signals.name is not None:  # the elapsed time to the signal (StopSignals' clock is perf_counter_ns)
            at = time.perf_counter() if signals.at_ns is None else signals.at_ns / 1e9
            raise Interrupted(signals.name, at - t0)


@contextmanager
def interrupting() -> Iterator[StopSignals]:
    """While entered, the first stop signal raises Interrupted where the main thread is (a second one raises
    KeyboardInterrupt, StopSignals' way out). Where Python drops that exception (the signal landed in a
    garbage-collector callback), the signal is delivered again, so the stop is never lost."""
    signals = StopSignals()
    t0 = time.perf_counter()
    in_flight = [False]  # an Interrupted was raised and Python has not dropped it
    in_hook = [False]  # swallowed() is running: what it raised would be dropped for good (not passed to a hook)

    def raise_now() -> None:
        if in_flight[0] or in_hook[0]:  # a late redelivery while one is already on its way out, or one that came
            return  # while the hook starts the redelivering thread (which delivers it again): nothing more to do
        in_flight[0] = True
        raise Interrupted(signals.name or "SIGINT", time.perf_counter() - t0)

    def again() -> None:
        """Deliver the signal again once the hook and the callback that dropped it have returned, and again every
        REDELIVER_AFTER_S until its handler raised: a delivery that lands between the main thread's last check and
        a blocking call (a sleep, a wait) is handled only when the call returns, and the next one interrupts it."""
        while not in_flight[0] and (signals, t0) in _STOPS:
            time.sleep(REDELIVER_AFTER_S)
            if not in_flight[0]:
                signals.redeliver()

    def swallowed(unraisable: sys.UnraisableHookArgs) -> None:  # raised inside a gc callback (distributed's
        if isinstance(unraisable.exc_value, Interrupted):   # GCDiagnosis) and dropped: delivered again
            in_hook[0] = True
            try:
                in_flight[0] = False
                threading.Thread(target=again, daemon=True).start()
            finally:
                in_hook[0] = False
        else:
            previous_hook(unraisable)

    signals.on_stop = raise_now
    previous_hook = sys.unraisablehook
    sys.unraisablehook = swallowed
    _STOPS.append((signals, t0))
    try:
        with signals:
            yield signals
    finally:
        _STOPS.remove((signals, t0))
        sys.unraisablehook = previous_hook


def stopped_line(command: str, stop: Interrupted, done: int, total: int, out: Path, what: str = "points") -> str:
    """The line a study prints after a stop signal: how far it got, where the rows are, how to finish.

    >>> stopped_line("faults", Interrupted("SIGTERM", 12.34), 3, 8, Path("runs/f"))
    'pafp faults: stopped by SIGTERM after 12.3 s: 3 of 8 points finished, kept in runs/f; `--resume` runs the rest'
    """
    return (f"pafp {command}: stopped by {stop.signal} after {stop.elapsed_s:.1f} s: {done} of {total} {what} "
            f"finished, kept in {out}; `--resume` runs the rest")

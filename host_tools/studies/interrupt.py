"""A stop signal that ends a long host-side job (a sweep, a tuning search) at once, through its own clean-up.

`pafp run` lets the running segment finish (:class:`~host_tools.stop_signals.StopSignals` sets a flag); a sweep
or a search waits on Dask futures that may take minutes, so here the first SIGINT, SIGTERM or SIGHUP raises
:class:`Interrupted` in the main thread instead. It is a ``BaseException`` (like ``KeyboardInterrupt``), so the
``except Exception`` that turns a failing point into a row does not swallow it; the ``finally`` clauses and
context managers on its way out run: the results table is flushed, the Dask client and its LocalCluster are
closed (no worker left behind, no leaked semaphore), and the command writes what it has, marked as
interrupted, and exits 128 + the signal's number.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from host_tools.stop_signals import EXIT_CODES, StopSignals

__all__ = ["Interrupted", "interrupting"]


class Interrupted(BaseException):
    """A stop signal arrived: ``signal`` is its name, ``exit_code`` 128 + its number."""

    def __init__(self, signal: str) -> None:
        """The signal's name (SIGINT, SIGTERM, SIGHUP)."""
        super().__init__(f"stopped by {signal}")
        self.signal = signal
        self.exit_code = EXIT_CODES.get(signal, 130)


@contextmanager
def interrupting() -> Iterator[StopSignals]:
    """While entered, the first stop signal raises Interrupted where the main thread is (a second one raises
    KeyboardInterrupt, StopSignals' way out)."""
    signals = StopSignals()

    def raise_now() -> None:
        raise Interrupted(signals.name or "SIGINT")

    signals.on_stop = raise_now
    with signals:
        yield signals

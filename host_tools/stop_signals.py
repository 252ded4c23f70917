"""SIGINT, SIGTERM and SIGHUP as a request for an orderly stop, not an exception in the middle of a job.

While a :class:`StopSignals` is entered, the first of these signals records its name and instant and calls
``on_stop`` (the scheduler's ``request_stop``): the running job finishes, the loop ends at its next
scheduling point and the caller runs its stop path. `pafp run` enters it before opening the ports and
leaves it after the last output file is written, so a signal at any moment ends in the same orderly way.
A second signal raises ``KeyboardInterrupt``: the way out if the stop path itself hangs (a port that
never drains). The previous handlers come back on exit.
Only the main thread can install handlers; elsewhere this does nothing (and says so in ``installed``).
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from types import FrameType, TracebackType

__all__ = ["EXIT_CODES", "STOP_SIGNALS", "StopSignals"]

STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))
EXIT_CODES = {s.name: 128 + int(s) for s in STOP_SIGNALS}
"""The shell's convention, 128 + signal number: SIGHUP 129, SIGINT 130, SIGTERM 143."""


class StopSignals:
    """Context manager turning the stop signals into ``on_stop()``; ``name`` and ``at_ns`` of the first one."""

    def __init__(self, on_stop: Callable[[], None] | None = None,
                 clock_ns: Callable[[], int] = time.perf_counter_ns) -> None:
        """``on_stop`` (settable later) must be safe to call from a signal handler: set a flag, nothing more."""
        self.on_stop = on_stop
        self.clock_ns = clock_ns
        self.name: str | None = None
        self.at_ns: int | None = None
        self.installed = False
        self._previous: dict[int, object] = {}
        self._again = False  # redeliver(): the next delivery is the first signal again, not a second one

    @property
    def exit_code(self) -> int | None:
        """128 + the signal's number, or None when no signal came."""
        return EXIT_CODES[self.name] if self.name is not None else None

    def redeliver(self) -> None:
        """Deliver the first signal again while the handlers are installed: its ``on_stop`` raised where Python
        swallows exceptions (a garbage-collector callback, a ``__del__``: sys.unraisablehook)."""
        if self.name is not None and self._previous:
            self._again = True
            main = threading.main_thread().ident  # to the main thread: a sleep or a wait there ends at once
            signal.pthread_kill(main if main is not None else threading.get_ident(), signal.Signals[self.name])

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self._again:
            self._again = False
            if self.on_stop is not None:
                self.on_stop()
            return
        if self.name is not None:
            raise KeyboardInterrupt(f"second signal {signal.Signals(signum).name} during the stop path")
        self.at_ns = self.clock_ns()
        self.name = signal.Signals(signum).name
        if self.on_stop is not None:
            self.on_stop()

    def __enter__(self) -> StopSignals:
        """Install the handlers (main thread only)."""
        if threading.current_thread() is threading.main_thread():
            for s in STOP_SIGNALS:
                self._previous[s] = signal.signal(s, self._handle)
            self.installed = True
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        """Put the previous handlers back."""
        for s, handler in self._previous.items():
            signal.signal(s, handler)  # type: ignore[arg-type]
        self._previous.clear()

"""What a soft-real-time Python loop can ask of the host, asked for the span of a serial run and undone after.

Each measure is optional and reported as granted or refused (the OS decides; nothing here fails a run):

* ``gc``: collect, then freeze what exists and disable the cyclic collector; the caller collects the
  young generation at safe points (:meth:`RealtimeSection.collect_young`). A full collection stalled
  the loop 45 ms on this host.
* ``pin``: bind the loop's thread to one core, when the machine has more than one and ``SCHED_FIFO`` was granted:
  an ordinary thread pinned to a core it shares with a busy process cannot move away (measured here: release
  jitter p99 8 ms pinned without FIFO, 0.2 ms unpinned, 0.08 ms with both). The core is the last of those with the
  fewest real-time threads of other processes pinned there (another serial run's loop, or `make test`'s other
  worker's): two FIFO loops that each sleep, spin and work on one core share it, and what FIFO threads get of a
  core is bounded by the kernel's RT throttling.
* ``fifo``: ``SCHED_FIFO`` at priority ``fifo_priority`` (needs root or CAP_SYS_NICE / an RLIMIT_RTPRIO).
  The loop sleeps most of each period, so other processes keep running; the kernel's RT throttling
  (``/proc/sys/kernel/sched_rt_runtime_us``) bounds it anyway.
* ``mlock``: ``mlockall(MCL_CURRENT | MCL_FUTURE)``: no page faults to disk in the loop (needs
  CAP_IPC_LOCK or a large enough RLIMIT_MEMLOCK).
* ``spin_s``: the wall clock sleeps until this long before each release, then spins (the sleep's own
  wake-up latency is 50-100 µs on a loaded Linux host).

Linux only for pin / fifo / mlock; elsewhere they are reported as unsupported.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import os
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from types import TracebackType

__all__ = ["RealtimeSection", "RealtimeSettings", "realtime_threads_pinned"]

log = logging.getLogger(__name__)

_MCL_CURRENT, _MCL_FUTURE = 1, 2


@dataclass(frozen=True)
class RealtimeSettings:
    """Which measures to ask for (all on by default) and the spin window of the wall clock."""

    gc: bool = True
    pin: bool = True
    fifo: bool = True
    mlock: bool = True
    spin_s: float = 0.0003
    fifo_priority: int = 10

    def __post_init__(self) -> None:
        """Reject a spin window or priority the OS cannot take."""
        if not 0 <= self.spin_s <= 0.01:
            raise ValueError(f"spin_s {self.spin_s!r} out of range: 0..0.01 s")
        if not 1 <= self.fifo_priority <= 99:
            raise ValueError(f"fifo_priority {self.fifo_priority!r} out of range: 1..99")

    @classmethod
    def none(cls, spin_s: float = 0.0) -> RealtimeSettings:
        """No measure at all: a plain Python loop (sleep to the release, no spin unless given)."""
        return cls(gc=False, pin=False, fifo=False, mlock=False, spin_s=spin_s)


class RealtimeSection:
    """Context manager: apply the settings on entry, undo them on exit; `granted` says what the OS gave."""

    def __init__(self, settings: RealtimeSettings) -> None:
        """Nothing is applied before ``__enter__``."""
        self.settings = settings
        self.granted: dict[str, object] = {}
        self._undo: list = []

    def __enter__(self) -> RealtimeSection:
        """Apply each requested measure; record what was granted and why a refusal happened."""
        s = self.settings
        self.granted = {"requested": asdict(s)}
        self.granted["gc"] = self._gc() if s.gc else "not requested"
        self.granted["fifo"] = fifo = self._fifo() if s.fifo else "not requested"
        if not s.pin:
            self.granted["pin"] = "not requested"
        elif not fifo.startswith("granted"):
            self.granted["pin"] = "not done: without SCHED_FIFO a pinned thread cannot leave a busy core"
        else:
            self.granted["pin"] = self._pin()
        self.granted["mlock"] = self._mlock() if s.mlock else "not requested"
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        """Undo in reverse order (each undo guarded: a failure is logged, never raised)."""
        while self._undo:
            undo = self._undo.pop()
            try:
                undo()
            except OSError as e:
                log.warning("could not undo a real-time setting: %s", e)

    def collect_young(self) -> None:
        """A safe point: collect the youngest generation only (tens of µs) while the collector is off."""
        if self.settings.gc:
            gc.collect(0)

    # Each measure: apply, push its undo, return "granted" or the reason it was not ---------------
    def _gc(self) -> str:
        was_enabled = gc.isenabled()
        gc.collect()
        gc.freeze()
        gc.disable()

        def undo() -> None:
            gc.unfreeze()
            if was_enabled:
                gc.enable()

        self._undo.append(undo)
        return "granted"

    def _pin(self) -> str:
        if not hasattr(os, "sched_setaffinity"):
            return "unsupported on this OS"
        before = os.sched_getaffinity(0)
        if len(before) < 2:
            return f"not done: {len(before)} core available"
        taken = realtime_threads_pinned()
        core = min(before, key=lambda c: (taken[c], -c))
        try:
            os.sched_setaffinity(0, {core})
        except OSError as e:
            return f"refused: {e.strerror}"
        self._undo.append(lambda: os.sched_setaffinity(0, before))
        return f"granted: core {core} of {sorted(before)}"

    def _fifo(self) -> str:
        if not hasattr(os, "sched_setscheduler"):
            return "unsupported on this OS"
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.settings.fifo_priority))
        except OSError as e:
            return f"refused: {e.strerror} (needs root, CAP_SYS_NICE or an RLIMIT_RTPRIO)"
        self._undo.append(lambda: os.sched_setscheduler(0, policy, param))
        return f"granted: SCHED_FIFO priority {self.settings.fifo_priority}"

    def _mlock(self) -> str:
        name = ctypes.util.find_library("c")
        if os.name != "posix" or name is None:
            return "unsupported on this OS"
        libc = ctypes.CDLL(name, use_errno=True)
        if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) != 0:
            err = ctypes.get_errno()
            return f"refused: {os.strerror(err)} (needs CAP_IPC_LOCK or a larger RLIMIT_MEMLOCK)"
        self._undo.append(libc.munlockall)
        return "granted: mlockall(MCL_CURRENT | MCL_FUTURE)"


_PF_KTHREAD = 0x00200000  # a task's flag for a kernel thread (linux/sched.h)


def realtime_threads_pinned(proc: Path = Path("/proc")) -> Counter[int]:
    """Per core, the user threads of other processes running SCHED_FIFO or SCHED_RR pinned to that core alone
    (/proc/PID/task/TID/stat's flags and policy, status's Cpus_allowed_list); kernel threads (a FIFO migration
    thread on every core) and unreadable tasks are left out."""
    me = str(os.getpid())
    taken: Counter[int] = Counter()
    for task in proc.glob("[0-9]*/task/[0-9]*"):
        if task.parts[-3] == me:
            continue
        try:
            stat = (task / "stat").read_text()
            fields = stat[stat.rindex(")") + 2:].split()  # from field 3 (state) on: the name may hold spaces
            if int(fields[6]) & _PF_KTHREAD or int(fields[38]) not in (os.SCHED_FIFO, os.SCHED_RR):
                continue
            for line in (task / "status").read_text().splitlines():
                if line.startswith("Cpus_allowed_list:"):
                    cpus = line.split(":", 1)[1].strip()
                    if cpus.isdigit():
                        taken[int(cpus)] += 1
        except (OSError, ValueError, IndexError):
            continue  # a task that ended while it was read
    return taken

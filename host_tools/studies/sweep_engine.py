"""Runs sweep points on Dask distributed: a LocalCluster on 127.0.0.1, or an existing scheduler.

`dask_client(workers=N)` starts a LocalCluster of N single-threaded worker processes listening on
127.0.0.1 only (no dashboard); `dask_client(scheduler="tcp://HOST:PORT")` connects to a running cluster
(`dask scheduler` + `dask worker`, or dask-jobqueue). `run_sweep` submits every point not yet finished,
records each row as it completes (host_tools/studies/sweep_table.py) and returns the rows sorted by point, so the
table is the same whatever the number of workers or the order in which they finish.
"""

from __future__ import annotations

import functools
import logging
import math
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from host_tools.studies.interrupt import raise_if_stopped
from host_tools.studies.sweep_point import (
    FIGURES,
    PointTask,
    error_row,
    firmware_config_of,
    plant_seed_run_options,
    run_point,
    warm_up,
)
from host_tools.studies.sweep_spec import SpecError, SweepSpec
from host_tools.studies.sweep_table import ResultsTable

__all__ = ["Progress", "SweepOutcome", "check_points", "check_scheduler", "columns_of", "dask_client", "run_sweep",
           "run_tasks", "tasks_of"]

PlantOptions = Callable[[int], dict[str, Any]]


def check_scheduler(address: str) -> None:
    """ValueError unless `address` is a scheduler file that exists (.json) or an address with a port.

    >>> check_scheduler("tcp://10.0.0.2:8786")
    >>> check_scheduler("nosuch.json")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    ValueError: --scheduler 'nosuch.json' is not allowed: no such file; give tcp://HOST:PORT or ...
    """
    allowed = "give tcp://HOST:PORT or an existing scheduler file (.json)"
    if address.endswith(".json"):
        if not Path(address).is_file():
            raise ValueError(f"--scheduler {address!r} is not allowed: no such file; {allowed}")
        return
    scheme, _, rest = address.rpartition("://")
    host, _, port = rest.rpartition(":")
    if scheme != "inproc" and not (host and port.isdigit() and 0 < int(port) < 65536):
        raise ValueError(f"--scheduler {address!r} is not allowed: no HOST:PORT (port 1..65535); {allowed}")


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, processes: bool = True) -> Iterator[Any]:
    """A dask.distributed Client: on `scheduler` (an address or a scheduler file) if given, else on a LocalCluster
    of `workers` on 127.0.0.1."""
    if scheduler:
        check_scheduler(scheduler)  # before dask is imported: a bad address costs nothing
    from dask.distributed import Client, LocalCluster

    for name in ("distributed", "tornado"):  # the cluster's chatter; errors still show
        logging.getLogger(name).setLevel(max(logging.WARNING, logging.getLogger(name).getEffectiveLevel()))
    if scheduler:
        by_file = scheduler.endswith(".json")  # `dask scheduler --scheduler-file`
        client = Client(scheduler_file=scheduler, timeout="10s") if by_file else Client(scheduler, timeout="10s")
        try:
            yield client
        finally:
            client.close()
        return
    n = workers or 1
    if not 1 <= n <= 1024:
        raise ValueError(f"--workers {n!r} out of range: an int in 1..1024")
    # dashboard_address ":0": the HTTP endpoints on a free port of the same host, never a fixed one.
    # processes=False: threads of this process on the in-process transport (no socket at all; tests use it)
    where = {"host": "127.0.0.1"} if processes else {}
    with _workers_ignore(TERMINAL_SIGNALS if processes else ()):
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=processes, dashboard_address=":0",
                               silence_logs=logging.ERROR, **where)
    client = Client(cluster)
    try:
        if processes:  # the worker processes' stderr is the command's
            from host_tools.studies.quiet_workers import QuietHeartbeat

            client.register_plugin(QuietHeartbeat())
        yield client
    finally:
        client.close()
        if processes:  # with the client gone, a point still computing (after a stop signal or an error) is not wanted
            cluster.sync(_stop_workers, cluster)
        cluster.close()


WORKER_STOP_GRACE_S = 1.0
"""How long a worker process still computing a point when its cluster closes (after a stop signal or an error) is
given to stop before it is killed; an idle one stops at once. (Distributed's nanny would give it 4 s, which a Ctrl-C
would wait for; the point's result is not wanted.)"""


async def _stop_workers(cluster: Any) -> None:
    """Close every worker process of the LocalCluster, killing those still busy after WORKER_STOP_GRACE_S (without
    the nanny's warning that it does: that is the intent)."""
    import asyncio

    nanny_log = logging.getLogger("distributed.nanny")
    level = nanny_log.level
    nanny_log.setLevel(logging.ERROR)
    try:  # a Nanny waits 0.8 * timeout for its worker to stop, then kills it; a kill slow to be joined on a loaded
        # host (its TimeoutError) must not hide the exception on its way out: cluster.close() follows either way
        await asyncio.gather(*(w.close(timeout=WORKER_STOP_GRACE_S / 0.8) for w in list(cluster.workers.values())),
                             return_exceptions=True)
    finally:
        nanny_log.setLevel(level)


TERMINAL_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGHUP") if hasattr(signal, n))
"""What a terminal sends its whole process group (Ctrl-C, a closed terminal): the worker processes ignore them
and are stopped by the command's own clean-up (host_tools/studies/interrupt.py closes the cluster)."""


@contextmanager
def _workers_ignore(signals: tuple[int, ...]) -> Iterator[None]:
    """Ignore `signals` while worker processes are started (an ignored signal stays ignored across exec, a
    handler does not), then put the handlers back; one arriving meanwhile is lost. Main thread only."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in signals}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def tasks_of(spec: SweepSpec) -> list[PointTask]:
    """The PointTask of every point of the spec, in index order."""
    run = tuple(sorted(spec.run.items()))
    name = str(spec.profile)
    return [PointTask(p.index, p.params, p.sample, p.plant_seed, p.seed, run, name, spec.profile_text,
                      spec.timeout_s) for p in spec.points()]


def columns_of(spec: SweepSpec) -> list[str]:
    """The columns of the spec's table: point, the axes, sample and seeds, status and error, the figures."""
    return ["point", *(a.key for a in spec.grid), "sample", "plant_seed", "seed", "status", "error", *FIGURES]


def check_points(spec: SweepSpec, plant_options: PlantOptions = plant_seed_run_options) -> None:
    """Build every distinct firmware configuration and one plant draw before any run (SpecError if one fails)."""
    profile_axes = [a for a in spec.grid if not a.is_run_key]
    for a in profile_axes:  # each value alone first, so the error names one key
        for v in a.values:
            try:
                firmware_config_of(spec.profile_text, {a.key: v}, str(spec.profile))
            except (ValueError, TypeError) as e:
                raise SpecError(f"spec {spec.path}: [[grid]] key {a.key!r} value {v!r}: {e}") from None
    seen = set()
    for t in tasks_of(spec):
        combo = tuple((k, v) for k, v in t.params if not k.startswith("run."))
        if combo and combo not in seen:
            seen.add(combo)
            try:
                firmware_config_of(spec.profile_text, dict(combo), str(spec.profile))
            except (ValueError, TypeError) as e:
                point = ", ".join(f"{k} = {v!r}" for k, v in combo)
                raise SpecError(f"spec {spec.path}: point {t.index} ({point}): {e}") from None
    if spec.samples:
        from host_tools.runner import RunConfig

        try:
            RunConfig(**plant_options(tasks_of(spec)[0].plant_seed or 0)).bench_setup()  # one draw, checked
        except Exception as e:  # noqa: BLE001 - the draw's own message, as one line
            raise SpecError(f"spec {spec.path}: [monte_carlo] samples = {spec.samples}: {e}") from None


class Progress:
    """A progress line on `stream`: points done / total, failed, rate and ETA (a line per 10 % if not a tty)."""

    def __init__(self, total: int, enabled: bool = True, stream: TextIO | None = None, label: str = "points") -> None:
        """Count `total` units from now."""
        self.total, self.enabled, self.label = total, enabled, label
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.t0 = time.perf_counter()
        self.done = self.failed = 0
        self._last_decile = -1

    def line(self) -> str:
        """The progress line as it stands."""
        el = time.perf_counter() - self.t0
        rate = self.done / el if el > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else math.inf
        frac = self.done / self.total if self.total else 1.0
        eta_s = "--" if not math.isfinite(eta) else f"{int(eta) // 60}m{int(eta) % 60:02d}s"
        return (f"[{'#' * int(frac * 25):<25}] {self.done}/{self.total} {self.label}, {self.failed} failed, "
                f"{rate:.2f}/s, elapsed {el:.0f} s, ETA {eta_s}")

    def step(self, failed: bool = False) -> None:
        """One more unit done."""
        self.done += 1
        self.failed += failed
        if not self.enabled:
            return
        if self.tty:
            self.stream.write("\r" + self.line())
            if self.done == self.total:
                self.stream.write("\n")
        elif (d := int(10 * self.done / max(1, self.total))) != self._last_decile:
            self._last_decile = d
            self.stream.write(self.line() + "\n")
        self.stream.flush()


@dataclass
class SweepOutcome:
    """The rows of a sweep (sorted by point) and what this invocation ran."""

    rows: list[dict[str, Any]]
    ran: int
    skipped: int
    wall_time_s: float


def run_sweep(spec: SweepSpec, out: Path, client: Any, *, resume: bool = False,
              plant_options: PlantOptions = plant_seed_run_options, progress: bool = True,
              stream: TextIO | None = None) -> SweepOutcome:
    """Run every point of `spec` not already finished in `out` on the Dask `client`; write the tables as they go."""
    return run_tasks(tasks_of(spec), functools.partial(run_point, plant_options=plant_options), out, client,
                     columns=columns_of(spec), digest=spec.digest, error_row=error_row, resume=resume,
                     progress=progress, stream=stream)


def run_tasks(tasks: list[Any], run: Callable[[Any], dict[str, Any]], out: Path, client: Any, *,
              columns: list[str], digest: str, error_row: Callable[[Any, str, str], dict[str, Any]],
              resume: bool = False, progress: bool = True, stream: TextIO | None = None,
              ok: Callable[[dict[str, Any]], bool] = lambda row: row["status"] == "ok") -> SweepOutcome:
    """Run `run(task)` for every task (each with an ``index``) not already finished in `out` on the Dask `client`,
    journalling each row as it comes (host_tools/studies/sweep_table.py); a lost worker is that task's ``error_row``."""
    from dask.distributed import as_completed

    try:  # every worker imports pafp now: a worker without it fails here, not once per point
        builds = client.run(warm_up)
    except Exception as e:  # noqa: BLE001 - whatever the worker raised, as one line
        raise ValueError(f"the Dask workers cannot run pafp points ({type(e).__name__}: {e}): install pafp in "
                         "every worker's environment (docs/sweeps.md)") from None
    logging.getLogger(__name__).info("workers: %s", builds)
    t0 = time.perf_counter()
    table = ResultsTable(out, columns, digest, len(tasks), resume)
    todo = [t for t in tasks if t.index not in table.rows]
    bar = Progress(len(todo), progress, stream)
    try:
        futures = {client.submit(run, t, key=f"pafp-point-{digest[:12]}-{t.index}", pure=False): t for t in todo}
        for fut in as_completed(futures):
            t = futures[fut]
            try:
                row = fut.result()
            except Exception as e:  # noqa: BLE001 - a lost worker (KilledWorker, ...) is this point's error
                row = error_row(t, "error", f"{type(e).__name__}: {e}".replace("\n", " "))
            table.add(row)
            bar.step(not ok(row))
            fut.release()
            raise_if_stopped()  # a stop signal whose Interrupted was swallowed on its way out of the wait
    finally:
        table.close()
    return SweepOutcome(table.sorted_rows(), len(todo), len(tasks) - len(todo), time.perf_counter() - t0)

"""What the LocalCluster's worker processes leave off the command's stderr (they share it with the command).

At a stop signal `dask_client` closes the cluster, which closes its workers before its scheduler; a worker still
computing a point may not have left when the scheduler goes, and its next heartbeat then fails: the worker would
print "Failed to communicate with scheduler during heartbeat" and two tracebacks after the command's own stop line.
The scheduler lives in the command's process, so a heartbeat that loses it tells nothing the command does not know.
Every other worker error still shows.
"""

from __future__ import annotations

import logging
from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

__all__ = ["HEARTBEAT_LOST", "QuietHeartbeat", "drop_lost_heartbeat"]

HEARTBEAT_LOST = "Failed to communicate with scheduler during heartbeat"


def drop_lost_heartbeat(record: logging.LogRecord) -> bool:
    """A logging filter: False for a worker's lost-heartbeat error (its traceback is part of the record), True for
    every other record."""
    return not record.getMessage().startswith(HEARTBEAT_LOST)


class QuietHeartbeat(WorkerPlugin):
    """Installs :func:`drop_lost_heartbeat` on the worker's ``distributed.worker`` logger."""

    name = "pafp-quiet-heartbeat"
    idempotent = True

    def setup(self, worker: Any) -> None:
        """Called in the worker process as it joins (or at registration)."""
        logging.getLogger("distributed.worker").addFilter(drop_lost_heartbeat)

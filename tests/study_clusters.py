"""Fixtures that stand in for a study command's LocalCluster of worker processes where it is not what a test checks.

``threads_cluster``: the command's own ``dask_client`` on one worker thread of this process: the same submit, the
same pickling of every task and result (distributed serialises them on the in-process transport too), without
the 3 s of starting worker processes. A test about the cluster itself (signals, worker processes, their stderr)
keeps the real one. ``no_cluster``: the test fails if the command starts one.
"""

from __future__ import annotations

import contextlib

import pytest

from host_tools.studies import sweep_engine


@pytest.fixture
def threads_cluster(monkeypatch):
    """The commands' LocalCluster as a worker thread of this process (fast; the command's own code path)."""
    real = sweep_engine.dask_client

    @contextlib.contextmanager
    def threads(workers=None, scheduler=None, processes=True):
        with real(workers=1, processes=False) as client:
            yield client
    monkeypatch.setattr(sweep_engine, "dask_client", threads)


@pytest.fixture
def no_cluster(monkeypatch):
    """A cluster may not start: the test fails if the command tries."""
    def refuse(*args, **kwargs):
        raise AssertionError("a cluster was started")
    monkeypatch.setattr(sweep_engine, "dask_client", refuse)

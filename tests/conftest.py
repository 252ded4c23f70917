"""Shared pytest set-up: Hypothesis profiles, and the plant fit the plant-fit test files share.

``pafp`` (the default): deterministic, so CI and local runs see the same examples. ``fuzz`` (``make fuzz``, or
``pytest --hypothesis-profile=fuzz``): random seeds and ten times the examples, to explore inputs the default
never draws; a failure prints the seed and the example's blob to reproduce it.
"""

import os

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "pafp",
    deadline=None,
    derandomize=True,
    max_examples=100,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "fuzz",
    parent=settings.get_profile("pafp"),
    derandomize=False,
    max_examples=1000,
    print_blob=True,
    database=None,  # nothing written into the checkout; the printed seed and blob reproduce a failure
)
settings.load_profile("pafp")


def _shared(tmp_path_factory):
    """The session's temporary directory all the pytest-xdist workers see (a worker's basetemp is its own in it)."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session")
def handmade_fit(tmp_path_factory):
    """The hand-made plant's 10 s identification experiment, its fit, a gait run and the fit's validation against it
    (tests/fit_shared.py): made once for all the pytest-xdist workers of a session."""
    from tests.fit_shared import handmade_fit as make

    return make(_shared(tmp_path_factory))


@pytest.fixture(scope="session")
def holds_only_run(tmp_path_factory):
    """A holds-only identification run of the nominal plant with its `pafp fit` in `fit` (tests/fit_shared.py):
    made once for all the pytest-xdist workers of a session; read it, never write into it."""
    from tests.fit_shared import holds_only_fit

    return holds_only_fit(_shared(tmp_path_factory))

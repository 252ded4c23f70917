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


@pytest.fixture(scope="session")
def handmade_fit(tmp_path_factory):
    """The hand-made plant's 10 s identification experiment, its fit and the same fit in another process under
    another BLAS set-up (tests/fit_shared.py): made once for all the pytest-xdist workers of a session."""
    from tests.fit_shared import handmade_fit as make

    base = tmp_path_factory.getbasetemp()  # a worker's is its own directory in the session's
    return make(base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base)

"""Shared pytest set-up: Hypothesis profiles.

``pafp`` (the default): deterministic, so CI and local runs see the same examples. ``fuzz`` (``make fuzz``, or
``pytest --hypothesis-profile=fuzz``): random seeds and ten times the examples, to explore inputs the default
never draws; a failure prints the seed and the example's blob to reproduce it.
"""

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

"""Shared pytest set-up: a deterministic Hypothesis profile (CI and local runs see the same examples)."""

from hypothesis import HealthCheck, settings

settings.register_profile(
    "pafp",
    deadline=None,
    derandomize=True,
    max_examples=100,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.load_profile("pafp")

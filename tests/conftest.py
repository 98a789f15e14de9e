"""Shared pytest configuration."""

from hypothesis import HealthCheck, settings

# Property tests draw random linear systems; a fixed budget keeps CI time predictable.
settings.register_profile(
    "riprs",
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
    derandomize=True,
)
settings.load_profile("riprs")

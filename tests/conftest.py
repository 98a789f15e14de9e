"""Shared pytest configuration, and the one way the tests find rip-rt."""

from __future__ import annotations

from pathlib import Path

import pytest
import scale
from hypothesis import HealthCheck, settings

from riprs._binaries import rip_rt_path

ROOT = Path(__file__).resolve().parents[1]

# Property tests draw random linear systems; a fixed budget keeps CI time predictable.
settings.register_profile(
    "riprs",
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
    derandomize=True,
)
settings.load_profile("riprs")


def pytest_configure(config: pytest.Config) -> None:
    # A typo in RIPRS_TEST_SCALE must not run the small sweeps in a run that asked for the
    # full ones: refused before any test runs.
    try:
        scale.scale()
    except ValueError as e:
        raise pytest.UsageError(str(e)) from None


@pytest.fixture(scope="session")
def rip_rt() -> Path:
    """The rip-rt the suite runs: $RIP_RT, else the installed console script, else cargo's
    release build of this checkout (built if missing), wherever its target directory is."""
    return rip_rt_path(build=True, workspace=ROOT)

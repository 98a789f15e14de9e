"""The size of the suite's sweeps (docs/contributing.md): ``RIPRS_TEST_SCALE``, ``small`` (the
quick and the pull-request tier, the default) or ``full`` (the full tier), by the rule of the
Rust suite's ``rip-test-scale`` crate. A sweep shrinks inside its test, keeping the cases that
once failed; ``conftest.py`` refuses any other value before a test runs."""

from __future__ import annotations

import os

VARIABLE = "RIPRS_TEST_SCALE"


def scale() -> str:
    """``"small"`` or ``"full"``; ``ValueError`` naming the variable for anything else."""
    value = os.environ.get(VARIABLE, "small")
    if value not in ("small", "full"):
        raise ValueError(f'{VARIABLE} must be "small" or "full", got {value!r}')
    return value


def sweep(small: int, full: int) -> int:
    """A sweep's size at this run's scale."""
    return full if scale() == "full" else small

"""``riprs.stats`` against scipy: the Wilson score interval of a success rate and the
binomial count a controller of a given success probability reaches."""

from __future__ import annotations

import pytest
from scipy import stats as sps

import riprs


@pytest.mark.parametrize("confidence", [0.8, 0.95, 0.99])
@pytest.mark.parametrize(
    ("k", "n"), [(0, 1), (1, 1), (0, 10), (7, 10), (10, 10), (909, 1000), (198, 200)]
)
def test_the_wilson_interval_is_scipys(k: int, n: int, confidence: float) -> None:
    want = sps.binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    low, high = riprs.stats.wilson_interval(k, n, confidence)
    assert low == pytest.approx(want.low, abs=1e-12)
    assert high == pytest.approx(want.high, abs=1e-12)


@pytest.mark.parametrize("p", [0.5, 0.9, 0.97, 0.985, 0.999])
@pytest.mark.parametrize("n", [1, 20, 200, 1000, 20_000])
def test_the_guard_is_the_binomial_tail(n: int, p: float) -> None:
    k = riprs.stats.guaranteed_successes(n, p, confidence=0.999)
    # P(X >= k) >= 0.999, and one more success would fall short of it.
    assert sps.binom.sf(k - 1, n, p) >= 0.999 - 1e-12
    if k < n:
        assert sps.binom.sf(k, n, p) < 0.999 + 1e-12


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: riprs.stats.wilson_interval(3, 2), "successes"),
        (lambda: riprs.stats.wilson_interval(0, 0), "runs"),
        (lambda: riprs.stats.wilson_interval(-1, 5), "successes"),
        (lambda: riprs.stats.wilson_interval(1, 5, confidence=1.0), "confidence"),
        (lambda: riprs.stats.guaranteed_successes(10, 1.5), "p"),
        (lambda: riprs.stats.guaranteed_successes(10, float("nan")), "p"),
        (lambda: riprs.stats.guaranteed_successes(10, 0.5, confidence=0.0), "confidence"),
        (lambda: riprs.stats.guaranteed_successes(-3, 0.5), "runs"),
    ],
)
def test_bad_arguments_name_themselves(call, name: str) -> None:
    with pytest.raises(riprs.InvalidParameterError, match=name):
        call()

"""Statistics of Monte Carlo results: how far a success rate measured over ``n`` runs can be
trusted, and how many successes a test may ask of a controller.

:func:`wilson_interval` is the Wilson score interval of ``k`` successes in ``n`` runs (Wilson,
JASA 22, 1927; Brown, Cai & DasGupta, Statistical Science 16, 2001), with
:math:`\\hat p = k/n` and :math:`z = \\Phi^{-1}((1 + c)/2)` for confidence :math:`c`:

.. math::

    \\frac{\\hat p + z^2/2n \\pm z \\sqrt{\\hat p (1 - \\hat p)/n + z^2/4n^2}}{1 + z^2/n}

(scipy's ``binomtest(k, n).proportion_ci(method="wilson")``). :func:`guaranteed_successes`
is the largest ``k`` with :math:`P(X \\ge k) \\ge c`, :math:`X \\sim B(n, p)`: the count a
test over ``n`` runs can ask of a controller of success probability ``p`` and fail it by
chance at most ``1 - c`` of the time. Both are ``rip_core::stats``.

Examples
--------
>>> import riprs
>>> low, high = riprs.stats.wilson_interval(180, 200)
>>> round(low, 4), round(high, 4)
(0.8506, 0.9343)
>>> riprs.stats.guaranteed_successes(200, 0.985, confidence=0.999)
191
"""

from __future__ import annotations

import math
from statistics import NormalDist

from riprs import _riprs
from riprs._riprs import InvalidParameterError

__all__ = ["guaranteed_successes", "wilson_interval"]


def wilson_interval(successes: int, runs: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a success rate (module docs).

    Parameters
    ----------
    successes, runs : int
        Successes and runs, ``0 <= successes <= runs`` and ``runs >= 1``.
    confidence : float, default 0.95
        Two-sided confidence level, in (0, 1).

    Returns
    -------
    tuple of float
        ``(low, high)`` within [0, 1].

    Raises
    ------
    InvalidParameterError
        A count out of range or a confidence outside (0, 1), naming the argument.
    """
    if not (isinstance(confidence, (int, float)) and 0.0 < confidence < 1.0):
        raise InvalidParameterError(f"confidence: must be in (0, 1), got {confidence!r}")
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    return _riprs.wilson(successes, runs, z)


def guaranteed_successes(runs: int, p: float, confidence: float = 0.999) -> int:
    """The most successes of ``runs`` that a controller succeeding with probability ``p``
    reaches with probability at least ``confidence`` (module docs).

    Parameters
    ----------
    runs : int
        Independent runs, ``>= 0``.
    p : float
        Success probability of one run, in [0, 1].
    confidence : float, default 0.999
        In (0, 1).

    Returns
    -------
    int
        The largest ``k`` with ``P(Binomial(runs, p) >= k) >= confidence``.

    Raises
    ------
    InvalidParameterError
        ``runs`` negative, ``p`` or ``confidence`` out of range, naming the argument.
    """
    if not (isinstance(p, (int, float)) and math.isfinite(p)):
        raise InvalidParameterError(f"p: must be a number in [0, 1], got {p!r}")
    return _riprs.guaranteed_successes(runs, float(p), float(confidence))

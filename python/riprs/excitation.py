"""Excitation signals for identification runs: the signals ``rip-rt excite`` applies.

One definition (``rip-core``'s ``excitation`` module) serves the rig and simulation, so a
simulated log built from :func:`excitation` carries exactly the input a rig run of the same
settings would (before the rig's arm-centring feedback, which the rig log records in its ``u``
column). ``docs/rip-rt.md`` documents each signal, its law and its defaults.
"""

from __future__ import annotations

from typing import Literal

from numpy.typing import ArrayLike

from riprs import _riprs
from riprs._typing import FloatArray

__all__ = ["SIGNALS", "excitation", "excitation_defaults"]

#: The signal names ``rip-rt excite --signal`` and :func:`excitation` accept.
SIGNALS = ("chirp", "prbs", "steps", "free-swing")

SignalName = Literal["chirp", "prbs", "steps", "free-swing", "free_swing"]


def excitation(
    signal: SignalName,
    *,
    dt: float = _riprs.TS,
    t: ArrayLike | None = None,
    duration: float | None = None,
    amplitude: float | None = None,
    f_start: float | None = None,
    f_end: float | None = None,
    sweep: Literal["linear", "log", "logarithmic"] | None = None,
    prbs_bits: int | None = None,
    prbs_clock: float | None = None,
    seed: int | None = None,
    step_hold: float | None = None,
    kick: float | None = None,
) -> FloatArray:
    """Sample an excitation signal (V).

    Every setting left at ``None`` takes the signal's default
    (:func:`excitation_defaults`, the same defaults as ``rip-rt excite``).

    Parameters
    ----------
    signal : {"chirp", "prbs", "steps", "free-swing"}
        ``chirp``: ``A sin(phi(t))`` sweeping ``f_start`` to ``f_end`` Hz over ``duration``
        (``sweep`` ``"log"``: ``f(t) = f_start (f_end/f_start)^(t/duration)``, or
        ``"linear"``). ``prbs``: a maximum-length sequence of a ``prbs_bits``-bit shift
        register, ``+A`` for a 1 and ``-A`` for a 0, one bit per ``prbs_clock`` seconds,
        started from ``seed``. ``steps``: levels ``A * (1, 0, -1, 0, 0.5, 0, -0.5, 0)``, each
        held ``step_hold`` seconds, repeated. ``free-swing``: a kick of ``+A`` for ``kick`` seconds
        and ``-A`` for ``kick`` seconds (the arm pushed, then braked), then 0 V.
    dt : float
        Sample time (s), by default ``riprs.TS`` (the loop's default ``loop.period_ms``,
        10 ms). The settings are checked against it (``f_end`` below the Nyquist
        frequency, clocks and holds at least one sample), and the spacing of the default
        times.
    t : array_like, optional
        Times (s) to evaluate at, e.g. a log's ``t`` column. Default ``k * dt`` for
        ``k = 0 .. round(duration / dt) - 1``.
    duration : float, optional
        Length of the signal (s); 0 V from then on.
    amplitude : float, optional
        ``A`` (V).
    f_start : float, optional
        Chirp start frequency (Hz).
    f_end : float, optional
        Chirp end frequency (Hz), below the Nyquist frequency ``1 / (2 dt)``.
    sweep : {"log", "linear"}, optional
        Chirp sweep law.
    prbs_bits : int, optional
        PRBS register length, 2 to 20 (period ``2**prbs_bits - 1`` clocks).
    prbs_clock : float, optional
        PRBS bit length (s).
    seed : int, optional
        PRBS initial state: the same seed gives the same sequence.
    step_hold : float, optional
        Steps: seconds per level.
    kick : float, optional
        Free swing: length of each half of the kick (s).

    Returns
    -------
    numpy.ndarray
        The voltage at each time, float64, shape ``(n,)``.

    Raises
    ------
    InvalidParameterError
        A setting out of range, named as the keyword (``f_end``, ``prbs_bits``, ...).
    NonFiniteError, ShapeError
        ``t`` holds NaN or Inf, or is not 1-D.
    """
    return _riprs.excitation(
        signal,
        dt=dt,
        t=t,
        duration=duration,
        amplitude=amplitude,
        f_start=f_start,
        f_end=f_end,
        sweep=sweep,
        prbs_bits=prbs_bits,
        prbs_clock=prbs_clock,
        seed=seed,
        step_hold=step_hold,
        kick=kick,
    )


def excitation_defaults(signal: SignalName) -> dict[str, float | int | str]:
    """The default settings of ``signal``.

    Parameters
    ----------
    signal : {"chirp", "prbs", "steps", "free-swing"}
        The signal.

    Returns
    -------
    dict
        The keyword arguments of :func:`excitation` with their defaults, and ``centering``
        and ``damping``, the rig's arm-centring gains (V/rad, V s/rad).

    Raises
    ------
    InvalidParameterError
        An unknown signal name.
    """
    return _riprs.excitation_defaults(signal)

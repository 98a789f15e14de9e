"""Riccati, LQR and Kalman design with python-control's and MATLAB's conventions.

Every function accepts array-likes, returns float64 numpy arrays, and raises a subclass of
:class:`riprs.RiprsError` (a :class:`ValueError`) naming the offending argument.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riprs import _riprs
from riprs._riprs import InvalidParameterError, KalmanDesign
from riprs._typing import FloatArray

__all__ = ["KalmanDesign", "c2d", "dare", "dlqe", "dlqr", "kalman"]

ComplexArray = NDArray[np.complex128]


def dare(
    A: ArrayLike,
    B: ArrayLike,
    Q: ArrayLike,
    R: ArrayLike,
    S: ArrayLike | None = None,
    E: ArrayLike | None = None,
) -> tuple[FloatArray, ComplexArray, FloatArray]:
    r"""Solve the discrete-time algebraic Riccati equation (python-control ``dare``).

    Finds the stabilizing solution :math:`X = X^T` of

    .. math::

        A^T X A - E^T X E - (A^T X B + S)(B^T X B + R)^{-1}(B^T X A + S^T) + Q = 0

    by structured doubling, which needs no inverse of ``A``. The answer is checked: the closed
    loop must be Schur stable and the relative residual below ``1e-8``.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q : array_like, shape (n, n)
        Symmetric state weight.
    R : array_like, shape (m, m)
        Symmetric positive semidefinite input weight. A singular ``R`` is allowed wherever
        ``R + B^T X B`` is invertible (the doubling runs on ``R + dI`` to find a stabilizing
        gain, Newton's method finishes on the true ``R``).
    S : array_like, shape (n, m), optional
        Cross weight; zero by default.
    E : array_like, shape (n, n), optional
        Descriptor matrix; identity by default.

    Returns
    -------
    X : ndarray, shape (n, n)
        Stabilizing solution.
    L : ndarray of complex, shape (n,)
        Closed-loop eigenvalues, ``eig(A - B G, E)``.
    G : ndarray, shape (m, n)
        Gain :math:`(B^T X B + R)^{-1}(B^T X A + S^T)`.

    Raises
    ------
    ShapeError, NonFiniteError, NotSymmetricError, NotPositiveDefiniteError
        Malformed arguments.
    NotStabilizableError
        ``(A, B)`` has an unstable mode the input cannot reach.
    NoStabilizingSolutionError
        No stabilizing solution exists (e.g. an unobservable mode of ``Q`` on the unit circle).
    """
    return _riprs.dare(
        A,
        B,
        Q,
        R,
        S,
        E,
    )


def dlqr(
    *args: Any,
    N: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray, ComplexArray]:
    r"""Discrete-time linear-quadratic regulator (python-control / MATLAB ``dlqr``).

    Called as ``dlqr(A, B, Q, R[, N])`` or, like python-control, ``dlqr(sys, Q, R[, N])``
    with a state-space object ``sys`` (anything with ``.A`` and ``.B``, e.g.
    :class:`riprs.StateSpace` or a ``control.StateSpace``).

    Minimises :math:`\sum_k x^T Q x + u^T R u + 2 x^T N u` for :math:`x[k+1] = A x + B u`.
    The optimal law is :math:`u = -K x`.

    Parameters
    ----------
    A, B : array_like
        Plant, shapes (n, n) and (n, m).
    Q, R : array_like
        Weights, shapes (n, n) and (m, m); ``[[Q, N], [N^T, R]]`` must be positive
        semidefinite and ``R`` positive definite.
    N : array_like, shape (n, m), optional
        Cross weight.

    Returns
    -------
    K : ndarray, shape (m, n)
        State-feedback gain.
    S : ndarray, shape (n, n)
        Riccati solution.
    E : ndarray of complex, shape (n,)
        Closed-loop eigenvalues ``eig(A - B K)``.
    """
    if args and hasattr(args[0], "A") and hasattr(args[0], "B"):
        # As python-control: a continuous-time system (dt == 0) has no discrete LQR.
        dt = getattr(args[0], "dt", getattr(args[0], "Ts", None))
        if dt is not None and not isinstance(dt, bool) and dt == 0:
            raise InvalidParameterError(
                "invalid sys: dlqr needs a discrete-time system (dt != 0), got a continuous-time "
                "one (dt = 0); discretise it first, e.g. with riprs.c2d"
            )
        args = (args[0].A, args[0].B, *args[1:])
    if len(args) == 5 and N is None:
        *args, N = args
    if len(args) != 4:
        raise TypeError("dlqr takes (A, B, Q, R[, N]) or (sys, Q, R[, N])")
    A, B, Q, R = args
    return _riprs.dlqr(
        A,
        B,
        Q,
        R,
        N,
    )


def dlqe(
    A: ArrayLike,
    G: ArrayLike,
    C: ArrayLike,
    QN: ArrayLike,
    RN: ArrayLike,
    NN: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray, ComplexArray]:
    r"""Discrete-time linear-quadratic estimator (python-control ``dlqe``).

    For :math:`x[k+1] = A x + B u + G w`, :math:`y = C x + v` with :math:`E\{ww^T\} = QN`,
    :math:`E\{vv^T\} = RN`, :math:`E\{wv^T\} = NN`, returns the *predictor* gain of
    :math:`\hat x[k+1|k] = A \hat x[k|k-1] + B u + L (y - C \hat x[k|k-1])`. Use :func:`kalman`
    for the innovation (filter) gain ``M`` as well.

    Returns
    -------
    L : ndarray, shape (n, p)
        Predictor gain ``(A P C^T + G NN)(C P C^T + RN)^{-1}``.
    P : ndarray, shape (n, n)
        Steady-state prior error covariance.
    E : ndarray of complex, shape (n,)
        Estimator poles ``eig(A - L C)``.
    """
    return _riprs.dlqe(
        A,
        G,
        C,
        QN,
        RN,
        NN,
    )


def kalman(
    A: ArrayLike,
    G: ArrayLike,
    C: ArrayLike,
    Qn: ArrayLike,
    Rn: ArrayLike,
    Nn: ArrayLike | None = None,
    H: ArrayLike | None = None,
) -> KalmanDesign:
    r"""Steady-state Kalman filter, as MATLAB's ``kalman`` for a discrete plant.

    For the plant

    .. math::

        x[k+1] = A x + B u + G w, \qquad y = C x + D u + H w + v,

    with :math:`E\{ww^T\} = Q_n`, :math:`E\{vv^T\} = R_n`, :math:`E\{wv^T\} = N_n`, let
    :math:`\bar Q = G Q_n G^T`, :math:`\bar R = R_n + H N_n + N_n^T H^T + H Q_n H^T`,
    :math:`\bar N = G(Q_n H^T + N_n)`. Then

    .. math::

        L = (A P C^T + \bar N)(C P C^T + \bar R)^{-1}, \quad
        M = P C^T (C P C^T + \bar R)^{-1}, \quad
        Z = (I - MC) P (I - MC)^T + M \bar R M^T,

    where ``P`` solves the filtering Riccati equation. The estimator in "current" form is
    :math:`\hat x[k|k] = \hat x[k|k-1] + M e`,
    :math:`\hat x[k+1|k] = A \hat x[k|k-1] + B u + L e` with :math:`e = y - C\hat x[k|k-1] - Du`
    (the paper's eqs. (4)–(6)).

    Parameters
    ----------
    A : array_like, shape (n, n)
    G : array_like, shape (n, w)
    C : array_like, shape (p, n)
    Qn : array_like, shape (w, w)
    Rn : array_like, shape (p, p)
    Nn : array_like, shape (w, p), optional
    H : array_like, shape (p, w), optional

    Returns
    -------
    KalmanDesign
        With attributes ``L`` (predictor gain), ``M`` (innovation gain), ``P`` (prior
        covariance), ``Z`` (posterior covariance) and ``E`` (poles of ``A - L C``).
    """
    return _riprs.kalman(
        A,
        G,
        C,
        Qn,
        Rn,
        Nn,
        H,
    )


def c2d(A: ArrayLike, B: ArrayLike, Ts: float) -> tuple[FloatArray, FloatArray]:
    r"""Zero-order-hold discretisation (MATLAB ``c2d(sys, Ts, 'zoh')``).

    Returns :math:`A_d = e^{A T_s}` and :math:`B_d = \int_0^{T_s} e^{A\tau}\,d\tau\, B`.
    """
    return _riprs.c2d(A, B, Ts)

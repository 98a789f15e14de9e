"""Riccati, LQR and Kalman design with python-control's and MATLAB's conventions.

Every function accepts array-likes, returns float64 numpy arrays, and raises a subclass of
:class:`riprs.RiprsError` (a :class:`ValueError`) naming the offending argument or value. A call
that is malformed as a call (too few arguments, an unknown keyword, a system object of the wrong
kind, a complex array, ``None`` for a required matrix) raises :class:`TypeError`, as
python-control's ``ControlArgument`` (a ``TypeError``) does for those; see "Coming from MATLAB
and python-control" in the docs.

``None`` means what python-control gives it: the default of an optional matrix (zero for a
cross term, the identity for ``E``) and, in :func:`dare`, the identity for ``R``. Where
python-control gives ``None`` no meaning (every other required matrix) it is a
:class:`TypeError` naming the argument.
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

#: The ``method`` values of python-control's ``dare``, ``dlqr`` and ``dlqe``. riprs has one
#: solver; each of them selects it (its answer agrees with scipy's and SLICOT's to rounding).
RICCATI_METHODS = (None, "scipy", "slycot")


def _check_riccati_method(function: str, method: object) -> None:
    if not (method is None or (isinstance(method, str) and method in RICCATI_METHODS)):
        raise InvalidParameterError(
            f"invalid method: {function} has no method {method!r}; riprs accepts "
            "python-control's None, 'scipy' and 'slycot', which all select riprs's own solver"
        )


def _reject_unknown_keywords(function: str, kwargs: dict[str, Any], accepted: str) -> None:
    if kwargs:
        names = ", ".join(repr(k) for k in sorted(kwargs))
        raise TypeError(f"{function}: unrecognized keywords: {names} (accepted: {accepted})")


def _system_matrices(function: str, first: object) -> tuple[Any, Any, Any] | None:
    """``(A, B, C)`` of a state-space object, ``None`` for a matrix, ``TypeError`` for another
    kind of system (a transfer function); a continuous-time system is refused."""
    if hasattr(first, "A") and hasattr(first, "B"):
        # As python-control: a continuous-time system (dt == 0) has no discrete design.
        dt = getattr(first, "dt", getattr(first, "Ts", None))
        if dt is not None and not isinstance(dt, bool) and dt == 0:
            raise InvalidParameterError(
                f"invalid sys: {function} needs a discrete-time system (dt != 0), got a "
                "continuous-time one (dt = 0); discretise it first, e.g. with riprs.c2d"
            )
        return first.A, first.B, getattr(first, "C", None)
    if hasattr(first, "ninputs") and hasattr(first, "noutputs"):
        raise TypeError(
            f"{function}: the LTI system must be in state-space form (with .A and .B), got "
            f"{type(first).__name__}; convert it first, e.g. with control.ss(sys)"
        )
    return None


def dare(
    A: ArrayLike,
    B: ArrayLike,
    Q: ArrayLike,
    R: ArrayLike | None,
    S: ArrayLike | None = None,
    E: ArrayLike | None = None,
    stabilizing: bool = True,
    method: str | None = None,
    **kwargs: Any,
) -> tuple[FloatArray, ComplexArray, FloatArray]:
    r"""Solve the discrete-time algebraic Riccati equation (python-control ``dare``).

    Finds the stabilizing solution :math:`X = X^T` of

    .. math::

        A^T X A - E^T X E - (A^T X B + S)(B^T X B + R)^{-1}(B^T X A + S^T) + Q = 0

    by structured doubling, which needs no inverse of ``A``, and Newton's method where
    :math:`B^T X B + R` is indefinite. The answer is checked: the closed loop must be Schur
    stable and the relative residual below ``1e-8``.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q : array_like, shape (n, n)
        Symmetric state weight; it may be indefinite.
    R : array_like, shape (m, m), or None
        Symmetric positive semidefinite input weight. A singular ``R`` is allowed wherever
        :math:`R + B^T X B` is invertible, definite or not (SLICOT's DAREX examples 1.2 and
        1.4). ``None`` is the identity, as in python-control (the argument is still
        required).
    S : array_like, shape (n, m), optional
        Cross weight; ``None`` (the default) is zero.
    E : array_like, shape (n, n), optional
        Descriptor matrix; ``None`` (the default) is the identity.
    stabilizing : bool, optional
        python-control's switch to the anti-stabilizing solution. Only ``True`` (the default)
        is supported; ``False`` raises :class:`InvalidParameterError`.
    method : {None, 'scipy', 'slycot'}, optional
        Accepted for python-control compatibility; every value selects riprs's solver.

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
    ShapeError, NonFiniteError, NotSymmetricError, NotPositiveSemidefiniteError
        Malformed arguments.
    NotStabilizableError
        ``(A, B)`` has an unstable mode the input cannot reach.
    NoStabilizingSolutionError
        No stabilizing solution exists (e.g. an unobservable mode of ``Q`` on the unit circle).
    InvalidParameterError
        ``stabilizing=False`` or an unknown ``method``.
    TypeError
        A complex argument (riprs solves real equations only), ``None`` for ``A``, ``B`` or
        ``Q`` (naming it), or an unknown keyword.
    """
    _reject_unknown_keywords("dare", kwargs, "S, E, stabilizing, method")
    _check_riccati_method("dare", method)
    if stabilizing is not True:
        raise InvalidParameterError(
            f"invalid stabilizing: riprs computes the stabilizing solution only, got "
            f"stabilizing={stabilizing!r}"
        )
    return _riprs.dare(A, B, Q, R, S, E)


def dlqr(
    *args: Any,
    N: ArrayLike | None = None,
    method: str | None = None,
    integral_action: ArrayLike | None = None,
    **kwargs: Any,
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
        semidefinite. With ``integral_action`` of ``p`` rows, ``Q`` is (n + p, n + p). Both
        are required: python-control's ``dlqr`` gives ``None`` no meaning here.
    N : array_like, shape (n, m), optional
        Cross weight ((n + p, m) with ``integral_action``); ``None`` (the default), given
        positionally or by keyword, is zero, python-control's omitted ``N``.
    method : {None, 'scipy', 'slycot'}, optional
        Accepted for python-control compatibility; every value selects riprs's solver.
    integral_action : array_like, shape (p, n), optional
        python-control's integral action (``None``, the default, for none): the design is made
        for the plant augmented with the integrators :math:`z[k+1] = z[k] + C_i x[k]` of
        ``C_i = integral_action``,

        .. math::

            A_a = \begin{bmatrix} A & 0 \\ C_i & I \end{bmatrix}, \quad
            B_a = \begin{bmatrix} B \\ 0 \end{bmatrix},

        and ``K = [K_x, K_z]`` (shape (m, n + p)) feeds back both.

    Returns
    -------
    K : ndarray, shape (m, n) or (m, n + p)
        State-feedback gain.
    S : ndarray, shape (n, n) or (n + p, n + p)
        Riccati solution.
    E : ndarray of complex, shape (n,) or (n + p,)
        Closed-loop eigenvalues ``eig(A - B K)`` (of the augmented system with
        ``integral_action``).

    Raises
    ------
    TypeError
        Too few or too many arguments, an unknown keyword, a system that is not in state-space
        form, ``None`` for ``A``, ``B``, ``Q`` or ``R`` (naming it), or a non-numeric
        ``integral_action``.
    ShapeError, NonFiniteError, NotSymmetricError, NotPositiveSemidefiniteError
        Malformed arguments (``integral_action`` without n columns is a ``ShapeError``).
    InvalidParameterError
        A continuous-time system or an unknown ``method``.
    NotStabilizableError, NoStabilizingSolutionError
        As :func:`dare`.
    """
    _reject_unknown_keywords("dlqr", kwargs, "N, method, integral_action")
    _check_riccati_method("dlqr", method)
    if len(args) < 3:
        raise TypeError(
            f"dlqr: not enough input arguments: takes (A, B, Q, R[, N]) or (sys, Q, R[, N]), "
            f"got {len(args)}"
        )
    system = _system_matrices("dlqr", args[0])
    if system is not None:
        args = (system[0], system[1], *args[1:])
    if len(args) == 5 and N is None:
        *args, N = args
    if len(args) != 4:
        raise TypeError(
            f"dlqr: takes (A, B, Q, R[, N]) or (sys, Q, R[, N]), got {len(args)} arguments"
        )
    A, B, Q, R = args
    return _riprs.dlqr(A, B, Q, R, N, integral_action)


def dlqe(
    *args: Any,
    NN: ArrayLike | None = None,
    method: str | None = None,
    **kwargs: Any,
) -> tuple[FloatArray, FloatArray, ComplexArray]:
    r"""Discrete-time linear-quadratic estimator (python-control ``dlqe``).

    Called as ``dlqe(A, G, C, QN, RN[, NN])`` or, like python-control, ``dlqe(sys, QN, RN[,
    NN])`` with a state-space object ``sys``, whose ``B`` is the noise input ``G`` and ``C``
    the output.

    For :math:`x[k+1] = A x + B u + G w`, :math:`y = C x + v` with :math:`E\{ww^T\} = QN`,
    :math:`E\{vv^T\} = RN`, :math:`E\{wv^T\} = NN`, returns the *predictor* gain of
    :math:`\hat x[k+1|k] = A \hat x[k|k-1] + B u + L (y - C \hat x[k|k-1])`. Use :func:`kalman`
    for the innovation (filter) gain ``M`` as well.

    Parameters
    ----------
    A, G, C : array_like
        Plant, noise input and output matrices, shapes (n, n), (n, w) and (p, n).
    QN, RN : array_like
        Process and measurement noise covariances, shapes (w, w) and (p, p). Like ``A``,
        ``G`` and ``C``, required: python-control's ``dlqe`` gives ``None`` no meaning here.
    NN : array_like, shape (w, p), optional
        Noise cross-covariance (python-control 0.10 refuses one; riprs uses it); ``None`` (the
        default), given positionally or by keyword, is zero, python-control's omitted ``NN``.
    method : {None, 'scipy', 'slycot'}, optional
        Accepted for python-control compatibility; every value selects riprs's solver.

    Returns
    -------
    L : ndarray, shape (n, p)
        Predictor gain ``(A P C^T + G NN)(C P C^T + RN)^{-1}``.
    P : ndarray, shape (n, n)
        Steady-state prior error covariance.
    E : ndarray of complex, shape (n,)
        Estimator poles ``eig(A - L C)``.

    Raises
    ------
    TypeError
        Too few or too many arguments, an unknown keyword, a system that is not in
        state-space form, or ``None`` for ``A``, ``G``, ``C``, ``QN`` or ``RN`` (naming it).
    ShapeError, NonFiniteError, NotSymmetricError, NotPositiveSemidefiniteError
        Malformed arguments.
    InvalidParameterError
        A continuous-time system or an unknown ``method``.
    NotDetectableError, NoStabilizingSolutionError
        ``(A, C)`` has an unstable mode the output does not see, or no stabilizing solution.
    """
    _reject_unknown_keywords("dlqe", kwargs, "NN, method")
    _check_riccati_method("dlqe", method)
    if len(args) < 3:
        raise TypeError(
            f"dlqe: not enough input arguments: takes (A, G, C, QN, RN[, NN]) or "
            f"(sys, QN, RN[, NN]), got {len(args)}"
        )
    system = _system_matrices("dlqe", args[0])
    if system is not None:
        if system[2] is None:
            raise TypeError("dlqe: sys has no output matrix C")
        args = (system[0], system[1], system[2], *args[1:])
    if len(args) == 6 and NN is None:
        *args, NN = args
    if len(args) != 5:
        raise TypeError(
            f"dlqe: takes (A, G, C, QN, RN[, NN]) or (sys, QN, RN[, NN]), got {len(args)} "
            "arguments"
        )
    A, G, C, QN, RN = args
    return _riprs.dlqe(A, G, C, QN, RN, NN)


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
        ``None`` (the default) is zero, as an omitted ``Nn`` in MATLAB.
    H : array_like, shape (p, w), optional
        ``None`` (the default) is zero, as an omitted ``H`` in MATLAB.

    Returns
    -------
    KalmanDesign
        With attributes ``L`` (predictor gain), ``M`` (innovation gain), ``P`` (prior
        covariance), ``Z`` (posterior covariance) and ``E`` (poles of ``A - L C``).

    Raises
    ------
    TypeError
        ``None`` for ``A``, ``G``, ``C``, ``Qn`` or ``Rn`` (naming it), or a complex argument.
    ShapeError, NonFiniteError, NotSymmetricError
        Malformed arguments.
    NotPositiveDefiniteError, NotPositiveSemidefiniteError
        Noise covariances that are not covariances (``Rn`` must be definite).
    NotDetectableError, NoStabilizingSolutionError
        As :func:`dlqe`.
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


def c2d(
    A: ArrayLike, B: ArrayLike, Ts: float, method: str = "zoh"
) -> tuple[FloatArray, FloatArray]:
    r"""Zero-order-hold discretisation (MATLAB ``c2d(sys, Ts, 'zoh')``).

    Returns :math:`A_d = e^{A T_s}` and :math:`B_d = \int_0^{T_s} e^{A\tau}\,d\tau\, B`, read
    off one exponential of :math:`[[A, B], [0, 0]] T_s` (Al-Mohy & Higham 2009), and refuses a
    result whose a-posteriori error estimate exceeds ``1e-6`` (see the design page).

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Ts : float
        Sample time, positive.
    method : {'zoh'}, optional
        The discretisation; riprs implements the zero-order hold only, any other value raises
        :class:`InvalidParameterError` naming ``method``.

    Returns
    -------
    Ad : ndarray, shape (n, n)
    Bd : ndarray, shape (n, m)

    Raises
    ------
    TypeError
        ``None`` for ``A``, ``B`` or ``Ts`` (naming it), or a complex argument.
    ShapeError, NonFiniteError
        Malformed arguments.
    InvalidParameterError
        A sample time that is not positive and finite, one at which :math:`e^{A T_s}` cannot be
        computed accurately in double precision (naming ``Ts``), or another ``method``.
    """
    if method != "zoh":
        raise InvalidParameterError(
            f"invalid method: riprs.c2d implements the zero-order hold ('zoh') only, got "
            f"{method!r}; python-control's sample_system has the other discretisations"
        )
    return _riprs.c2d(A, B, Ts)

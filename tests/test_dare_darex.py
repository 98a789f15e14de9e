"""riprs.dare on the DAREX examples where R + B'XB is invertible but indefinite, against a
40-digit Newton solve (mpmath), and on complex data, which riprs refuses.

DAREX: J. Abels and P. Benner, "DAREX - A collection of benchmark examples for discrete-time
algebraic Riccati equations (version 2.0)", SLICOT Working Note 1999-16 (SLICOT's BB02AD).
"""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
import scipy.linalg

import riprs


def _mp_dare(A, B, Q, R, S, X0, digits: int = 40, steps: int = 30):
    """Newton's method for the DARE in `digits`-digit arithmetic from `X0`: each step solves
    the Stein equation Ac' dX Ac - dX = -F(X) of the closed loop Ac = A - B G(X) in Kronecker
    form. Returns X, the 1-norm of the residual F(X) and the closed-loop matrix."""
    with mpmath.workdps(digits):
        A, B, Q, R, S, X = (
            mpmath.matrix(np.asarray(M, float).tolist()) for M in (A, B, Q, R, S, X0)
        )
        n = A.rows

        def gain_and_residual(X):
            G = mpmath.inverse(R + B.T * X * B) * (B.T * X * A + S.T)
            return G, A.T * X * A - X - (A.T * X * B + S) * G + Q

        for _ in range(steps):
            G, F = gain_and_residual(X)
            Ac = A - B * G
            K = mpmath.matrix(n * n, n * n)
            f = mpmath.matrix(n * n, 1)
            for i in range(n):
                for j in range(n):
                    f[i + n * j] = -F[i, j]
                    for k in range(n):
                        for m in range(n):
                            K[i + n * j, k + n * m] = Ac[k, i] * Ac[m, j] - (i == k and j == m)
            d = mpmath.lu_solve(K, f)
            for i in range(n):
                for j in range(n):
                    X[i, j] += d[i + n * j]
            X = (X + X.T) / 2
        G, F = gain_and_residual(X)
        return (
            np.array(X.tolist(), dtype=float),
            float(mpmath.mnorm(F, 1)),
            np.array((A - B * G).tolist(), dtype=float),
        )


def _darex_1_2():
    # Ionescu & Weiss 1992: singular R, nonzero S.
    A = np.array([[0.0, 1.0], [0.0, -1.0]])
    B = np.array([[1.0, 0.0], [2.0, 1.0]])
    Q = np.array([[-4.0, -4.0], [-4.0, 7.0]]) / 11
    R = np.array([[9.0, 3.0], [3.0, 1.0]])
    S = np.array([[3.0, 1.0], [-1.0, 7.0]])
    return A, B, Q, R, S


def _darex_1_4():
    # Sun 1998: R singular, Q indefinite.
    A = np.zeros((3, 3))
    A[0, 1], A[1, 2] = 0.1, 0.01
    B = np.zeros((3, 2))
    B[0, 0] = B[2, 1] = 1.0
    Q = np.diag([1e5, 1e3, -10.0])
    R = np.diag([0.0, 1.0])
    return A, B, Q, R, np.zeros((3, 2))


@pytest.mark.parametrize(
    ("case", "radius"), [(_darex_1_2, 0.6872716916638), (_darex_1_4, 0.0)], ids=["1.2", "1.4"]
)
def test_indefinite_darex_examples_are_solved(case, radius: float) -> None:
    A, B, Q, R, S = case()
    X, L, G = riprs.dare(A, B, Q, R, S)
    X_mp, residual, Ac = _mp_dare(A, B, Q, R, S, scipy.linalg.solve_discrete_are(A, B, Q, R, s=S))
    assert residual < 1e-30
    assert np.linalg.norm(X - X_mp) <= 1e-13 * np.linalg.norm(X_mp)
    np.testing.assert_allclose(np.max(np.abs(L)), radius, atol=1e-10)
    np.testing.assert_allclose(np.max(np.abs(np.linalg.eigvals(Ac))), radius, atol=1e-10)
    np.testing.assert_allclose(G, np.linalg.solve(R + B.T @ X @ B, B.T @ X @ A + S.T), atol=1e-12)
    # R + B'XB is invertible but indefinite at the solution, which the docstring allows.
    eig = np.linalg.eigvalsh(R + B.T @ X @ B)
    assert eig.min() < 0 < eig.max()


def test_darex_1_4_exact_solution() -> None:
    # The (3, 3) equation reads 0.1 - x - 10 = 0: X = diag(1e5, 1e3, -9.9) exactly.
    X, _, _ = riprs.dare(*_darex_1_4())
    np.testing.assert_allclose(X, np.diag([1e5, 1e3, -9.9]), atol=1e-9)


COMPLEX_CASES = [
    # scipy's TestSolveDiscreteAre cases 0-2 and the argument that makes each complex
    (([[2, 1 - 2j], [0, -3j]], [[0], [1]], [[1, 0], [0, 2]], [[1]]), "A"),
    (([[2, 1], [0, -1]], [[-2j], [1j]], [[1, 0], [0, 2]], [[1]]), "B"),
    (([[3, 1], [0, -1]], [[1, 2], [1, 3]], [[1, 1 + 1j], [1 - 1j, 2]], [[2, -2j], [2j, 3]]), "Q"),
]


@pytest.mark.parametrize(("args", "name"), COMPLEX_CASES)
def test_complex_dare_is_refused_naming_the_argument(args, name: str) -> None:
    arrays = [np.array(a) for a in args]
    with pytest.raises(
        TypeError, match=rf"^{name} must be an array of real numbers, got a complex"
    ):
        riprs.dare(*arrays)
    # A complex dtype is refused even with a zero imaginary part: numpy's cast to float would
    # otherwise drop a nonzero one silently.
    with pytest.raises(TypeError, match="complex"):
        riprs.dare(np.eye(2, dtype=complex) * 0.5, np.eye(2), np.eye(2), np.eye(2))

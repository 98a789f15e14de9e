"""riprs.c2d on stiff, badly scaled and non-normal models, against 50-digit mpmath exponentials,
scipy.linalg.expm and closed forms: what can be computed accurately is returned, what cannot is
refused naming ``Ts``.

The acceptance test is the exponential's a-posteriori error estimate (docs/design.md); the
determinant test it replaced refused every model here whose fast mode decays below 1e-16 within
one sample, because the determinant of the correctly rounded e^{A Ts} is then rounding noise.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
import scipy.linalg
from scipy.special import binom

import riprs

EPS = np.finfo(float).eps


def _reference_zoh(
    A: np.ndarray, B: np.ndarray, Ts: float, digits: int = 50
) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order hold from a high-precision exponential of [[A, B], [0, 0]] Ts."""
    n, m = B.shape
    block = np.zeros((n + m, n + m))
    block[:n, :n] = A * Ts
    block[:n, n:] = B * Ts
    with mpmath.workdps(digits):
        e = mpmath.expm(mpmath.matrix(block.tolist()))
        e = np.array(e.tolist(), dtype=float)
    return e[:n, :n], e[:n, n:]


def _rel(got: np.ndarray, want: np.ndarray) -> float:
    return float(np.linalg.norm(got - want, 1) / np.linalg.norm(want, 1))


def _dc_motor(inductance: float) -> tuple[np.ndarray, np.ndarray]:
    # Position, speed, current; J = 0.01 kg m², b = 0.1 N m s, K = 0.01, R = 1 Ω.
    J, b, K, R = 0.01, 0.1, 0.01, 1.0
    A = np.array([[0.0, 1.0, 0.0], [0.0, -b / J, K / J], [0.0, -K / inductance, -R / inductance]])
    B = np.array([[0.0], [0.0], [1.0 / inductance]])
    return A, B


def _det_test_refuses(Ad: np.ndarray, A: np.ndarray, Ts: float) -> bool:
    """The replaced criterion: |ln det e^{A Ts} - tr(A Ts)| > ln 2."""
    det = np.linalg.det(Ad)
    return not (det > 0 and abs(math.log(det) - np.trace(A) * Ts) <= math.log(2))


@pytest.mark.parametrize("Ts", [0.05, 0.1])
def test_dc_motor_with_a_fast_electrical_mode(Ts: float) -> None:
    A, B = _dc_motor(1e-3)
    Ad, Bd = riprs.c2d(A, B, Ts)
    Ad_ref, Bd_ref = _reference_zoh(A, B, Ts)
    assert _rel(Ad, Ad_ref) < 1e-14
    assert _rel(Bd, Bd_ref) < 1e-14
    assert _det_test_refuses(Ad_ref, A, Ts)  # the case the determinant test refused


@pytest.mark.parametrize("fast", [37.0, 50.0, 75.0, 100.0])
def test_two_modes_minus_one_and_a_fast_one_at_one_second(fast: float) -> None:
    # Eigenvalues -1 and -fast in a non-orthogonal basis (not triangular).
    V = np.array([[1.0, 0.6], [0.3, 1.0]])
    A = V @ np.diag([-1.0, -fast]) @ np.linalg.inv(V)
    B = np.array([[1.0], [0.5]])
    Ad, Bd = riprs.c2d(A, B, 1.0)
    Ad_ref, Bd_ref = _reference_zoh(A, B, 1.0)
    assert _rel(Ad, Ad_ref) < 1e-14
    assert _rel(Bd, Bd_ref) < 1e-14


@pytest.mark.parametrize("n", range(3, 80, 3))
def test_scipys_pascal_test(n: int) -> None:
    # scipy's test_pascal (scale 1): e^A of the subdiagonal 1..n has entries binom(i, j).
    A = np.diag(np.arange(1.0, n + 1), -1)
    Ad, _ = riprs.c2d(A, np.zeros((n + 1, 1)), 1.0)
    expected = binom(np.arange(n + 1)[:, None], np.arange(n + 1)[None, :])
    np.testing.assert_allclose(Ad, expected, atol=1e-13 * np.abs(expected).max(), rtol=0)


@pytest.mark.slow
def test_two_hundred_random_stable_systems() -> None:
    rng = np.random.default_rng(27)
    det_refused = 0
    worst = 0.0
    for _ in range(200):
        n = int(rng.integers(2, 7))
        poles = list(-(10.0 ** rng.uniform(-1, 4, size=n)))
        if n >= 3 and rng.random() < 0.5:  # one lightly damped oscillatory pair
            w = 10.0 ** rng.uniform(-1, 2)
            poles[:2] = [complex(-0.05 * w, w), complex(-0.05 * w, -w)]
        T = rng.normal(size=(n, n)) + 2 * np.eye(n)
        Ac = np.diag(np.array(poles, dtype=complex))
        if isinstance(poles[0], complex):
            Ac[:2, :2] = [[poles[0].real, poles[0].imag], [-poles[0].imag, poles[0].real]]
        A = np.real(T @ Ac @ np.linalg.inv(T))
        B = rng.normal(size=(n, int(rng.integers(1, 3))))
        Ts = 10.0 ** rng.uniform(-3, 0)
        Ad, Bd = riprs.c2d(A, B, Ts)
        Ad_ref, Bd_ref = _reference_zoh(A, B, Ts, digits=30)
        block = np.zeros((n + B.shape[1],) * 2)
        block[:n, :n], block[:n, n:] = A * Ts, B * Ts
        scipy_ad = scipy.linalg.expm(block)[:n, :n]
        scale = np.linalg.norm(Ad_ref, 1)
        if scale == 0.0:  # every mode decayed below the smallest double
            assert np.all(Ad == 0.0)
            continue
        # As accurate as scipy.linalg.expm to a factor of ten, or to 1e-12: the non-normal
        # draws lose digits in any scaling and squaring (the worst, with 15 squarings, 1.7e-10
        # here and 5.6e-11 in scipy), and on one draw scipy's compiled expm is better by more
        # than that (1.6e-15 against 3.0e-13, which is also scipy.sparse.linalg.expm's, the
        # reference implementation of the same algorithm).
        err = np.linalg.norm(Ad - Ad_ref, 1) / scale
        err_scipy = np.linalg.norm(scipy_ad - Ad_ref, 1) / scale
        worst = max(worst, err)
        assert err <= max(1e-12, 10 * err_scipy), (A, B, Ts)
        assert np.linalg.norm(Bd - Bd_ref, 1) <= 1e-9 * max(np.linalg.norm(Bd_ref, 1), 1e-300)
        det_refused += _det_test_refuses(Ad_ref, A, Ts)
    print(f"200 random systems: worst relative error {worst:.1e}, {det_refused} refused by det")
    # The draw reaches the regime the determinant test got wrong.
    assert det_refused >= 5


@pytest.mark.parametrize("b", [1e4, 1e8, 1e12, 1e16, 1e50])
def test_no_overscaling_of_a_non_normal_model(b: float) -> None:
    # e^[[1, b], [0, -1]] = [[e, b sinh 1], [0, 1/e]]; scaling by the norm (Higham 2005) lost
    # 7.5e-9 at b = 1e12, Al-Mohy & Higham (2009) need no squaring at all.
    A = np.array([[1.0, b], [0.0, -1.0]])
    Ad, _ = riprs.c2d(A, np.zeros((2, 1)), 1.0)
    with mpmath.workdps(50):
        exact = np.array(
            [[float(mpmath.e), float(b * mpmath.sinh(1))], [0.0, float(mpmath.exp(-1))]]
        )
    ulps = np.abs(Ad - exact) / np.maximum(np.abs(exact), np.finfo(float).tiny) / EPS
    assert ulps.max() <= 4


def test_molers_badly_scaled_example_is_accurate() -> None:
    # Burkardt's 14th test (Moler's example, which defeated MATLAB's expm before 2009); the
    # reference values are Burkardt's, checked here against mpmath.
    A = np.array([[0, 1e-8, 0], [-(2e10 + 4e8 / 6.0), -3, 2e10], [200.0 / 3.0, 0, -200.0 / 3.0]])
    desired = np.array(
        [
            [0.446849468283175, 1.54044157383952e-09, 0.462811453558774],
            [-5743067.77947947, -0.0152830038686819, -4526542.71278401],
            [0.447722977849494, 1.54270484519591e-09, 0.463480648837651],
        ]
    )
    Ad, _ = riprs.c2d(A, np.zeros((3, 1)), 1.0)
    Ad_ref, _ = _reference_zoh(A, np.zeros((3, 1)), 1.0)
    np.testing.assert_allclose(Ad_ref, desired, rtol=1e-13)
    np.testing.assert_allclose(Ad, Ad_ref, rtol=1e-11)


@pytest.mark.parametrize("w", [1e15, 1e20])
def test_a_rotation_beyond_double_precision_is_refused(w: float) -> None:
    # e^{[[0, w], [-w, 0]]} is a rotation by w rad; every one of the ~log2(w) squarings doubles
    # the relative error, and at 1e15 rad nothing is left (the old code returned zeros).
    A = np.array([[0.0, w], [-w, 0.0]])
    with pytest.raises(riprs.InvalidParameterError, match=r"Ts.*estimated relative error"):
        riprs.c2d(A, np.array([[0.0], [1.0]]), 1.0)

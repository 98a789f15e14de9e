"""``None`` for a matrix argument (issue 49): python-control's meaning where it gives one, a
``TypeError`` naming the argument everywhere else.

numpy reads ``None`` as a NaN scalar, so before this rule a missing required matrix was
reported as ``NonFiniteError: R contains NaN or Inf``, a value error about a value the caller
never gave. The expectations below are python-control 0.10's behaviour with ``None``, checked
against the installed python-control wherever it has the function.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import riprs

control = pytest.importorskip("control")

# An unstable mode (1.2) so that the defaults change the answer, and two inputs so that an
# identity R is not mistaken for a scalar one.
A = np.diag([0.5, 1.2])
B = np.eye(2)
Q = np.eye(2)
C = np.array([[1.0, 0.5]])
A3 = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 0.8]])
B3 = np.array([[0.0, 1.0], [1.0, 0.0], [0.5, 0.5]])
C3 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def assert_same_design(got, want) -> None:
    """The same (X or K, eigenvalues, gain) up to the order of the eigenvalues."""
    for g, w in zip(got, want, strict=True):
        g, w = np.asarray(g), np.asarray(w)
        if np.iscomplexobj(g) or np.iscomplexobj(w):
            g, w = np.sort_complex(np.ravel(g)), np.sort_complex(np.ravel(w))
        np.testing.assert_allclose(g, w, rtol=1e-10, atol=1e-12)


# --------------------------------------------------------------------------------------------
# None with a meaning: python-control's
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("a", "b", "q"), [(A, B, Q), (A3, B3, np.eye(3))])
def test_dare_R_none_is_the_identity_as_in_python_control(a, b, q) -> None:
    m = b.shape[1]
    ours = riprs.dare(a, b, q, None)
    assert_same_design(ours, control.dare(a, b, q, None))
    assert_same_design(ours, control.dare(a, b, q, np.eye(m)))
    assert_same_design(ours, riprs.dare(a, b, q, np.eye(m)))


def test_dare_R_none_takes_the_size_of_B_for_a_single_input() -> None:
    b = np.array([[0.0], [1.0]])
    assert_same_design(riprs.dare(A, b, Q, None), control.dare(A, b, Q, None))


def test_dare_S_and_E_none_are_zero_and_the_identity_as_in_python_control() -> None:
    ours = riprs.dare(A, B, Q, None, None, None)
    assert_same_design(ours, control.dare(A, B, Q, None, None, None))
    assert_same_design(ours, riprs.dare(A, B, Q, np.eye(2), np.zeros((2, 2)), np.eye(2)))
    assert_same_design(riprs.dare(A, B, Q, np.eye(2), S=None, E=None), ours)


def test_dlqr_N_none_is_python_controls_omitted_N() -> None:
    # python-control documents N as optional and zero when omitted; riprs's None is that
    # default, positionally and by keyword, for matrices and for a system.
    want = control.dlqr(A3, B3, np.eye(3), np.eye(2))
    assert_same_design(riprs.dlqr(A3, B3, np.eye(3), np.eye(2), None), want)
    assert_same_design(riprs.dlqr(A3, B3, np.eye(3), np.eye(2), N=None), want)
    sys = control.ss(A3, B3, C3, np.zeros((2, 2)), 0.1)
    want = control.dlqr(sys, np.eye(3), np.eye(2))
    assert_same_design(riprs.dlqr(sys, np.eye(3), np.eye(2), None), want)


def test_dlqr_integral_action_none_is_no_integrator_as_in_python_control() -> None:
    assert_same_design(
        riprs.dlqr(A3, B3, np.eye(3), np.eye(2), integral_action=None),
        control.dlqr(A3, B3, np.eye(3), np.eye(2), integral_action=None),
    )


def test_dlqe_NN_none_is_no_cross_covariance() -> None:
    # python-control refuses any NN (not implemented); its omitted NN is zero, which riprs's
    # None is.
    want = control.dlqe(A3, B3, C3, np.eye(2), np.eye(2))
    assert_same_design(riprs.dlqe(A3, B3, C3, np.eye(2), np.eye(2), None), want)
    assert_same_design(riprs.dlqe(A3, B3, C3, np.eye(2), np.eye(2), NN=None), want)


def test_kalman_Nn_and_H_none_are_zero() -> None:
    # MATLAB's kalman (python-control has none): omitted Nn and H are zero, the filter of dlqe.
    design = riprs.kalman(A3, B3, C3, np.eye(2), np.eye(2), None, None)
    explicit = riprs.kalman(A3, B3, C3, np.eye(2), np.eye(2), np.zeros((2, 2)),
                            np.zeros((2, 2)))
    np.testing.assert_allclose(design.L, explicit.L, rtol=1e-12)
    np.testing.assert_allclose(design.M, explicit.M, rtol=1e-12)
    L_ct, P_ct, _ = control.dlqe(A3, B3, C3, np.eye(2), np.eye(2))
    np.testing.assert_allclose(design.L, L_ct, rtol=1e-10)
    np.testing.assert_allclose(design.P, P_ct, rtol=1e-10)


# --------------------------------------------------------------------------------------------
# None without a meaning: a TypeError naming the argument
# --------------------------------------------------------------------------------------------


def _sys():
    return control.ss(A3, B3, C3, np.zeros((2, 2)), 0.1)


I2, I3, I4 = np.eye(2), np.eye(3), np.eye(4)
B4, C4, K4, L4 = np.ones((4, 1)), np.ones((2, 4)), np.ones((1, 4)), np.ones((4, 2))
# (the call on either library, the argument riprs must name). python-control refuses each of
# these too (a ValueError or TypeError of its own), so no None here has a python-control
# meaning that riprs would drop.
REQUIRED = [
    pytest.param(lambda m: m.dare(None, B, Q, I2), "A", id="dare:A"),
    pytest.param(lambda m: m.dare(A, None, Q, I2), "B", id="dare:B"),
    pytest.param(lambda m: m.dare(A, B, None, I2), "Q", id="dare:Q"),
    pytest.param(lambda m: m.dlqr(None, B, Q, I2), "A", id="dlqr:A"),
    pytest.param(lambda m: m.dlqr(A, None, Q, I2), "B", id="dlqr:B"),
    pytest.param(lambda m: m.dlqr(A, B, None, I2), "Q", id="dlqr:Q"),
    pytest.param(lambda m: m.dlqr(A, B, Q, None), "R", id="dlqr:R"),
    pytest.param(lambda m: m.dlqr(A, B, Q, None, None), "R", id="dlqr:R,N"),
    pytest.param(lambda m: m.dlqr(_sys(), None, I2), "Q", id="dlqr(sys):Q"),
    pytest.param(lambda m: m.dlqr(_sys(), I3, None), "R", id="dlqr(sys):R"),
    pytest.param(lambda m: m.dlqe(None, B3, C3, I2, I2), "A", id="dlqe:A"),
    pytest.param(lambda m: m.dlqe(A3, None, C3, I2, I2), "G", id="dlqe:G"),
    pytest.param(lambda m: m.dlqe(A3, B3, None, I2, I2), "C", id="dlqe:C"),
    pytest.param(lambda m: m.dlqe(A3, B3, C3, None, I2), "QN", id="dlqe:QN"),
    pytest.param(lambda m: m.dlqe(A3, B3, C3, I2, None), "RN", id="dlqe:RN"),
    pytest.param(lambda m: m.dlqe(_sys(), None, I2), "QN", id="dlqe(sys):QN"),
    pytest.param(lambda m: m.dlqe(_sys(), I2, None), "RN", id="dlqe(sys):RN"),
]


# riprs functions python-control does not have (MATLAB's kalman, c2d on matrices, the
# controllers): riprs's rule alone.
RIPRS_ONLY = [
    pytest.param(lambda: riprs.kalman(None, B3, C3, I2, I2), "A", id="kalman:A"),
    pytest.param(lambda: riprs.kalman(A3, None, C3, I2, I2), "G", id="kalman:G"),
    pytest.param(lambda: riprs.kalman(A3, B3, None, I2, I2), "C", id="kalman:C"),
    pytest.param(lambda: riprs.kalman(A3, B3, C3, None, I2), "Qn", id="kalman:Qn"),
    pytest.param(lambda: riprs.kalman(A3, B3, C3, I2, None), "Rn", id="kalman:Rn"),
    pytest.param(lambda: riprs.c2d(None, B, 0.1), "A", id="c2d:A"),
    pytest.param(lambda: riprs.c2d(A, None, 0.1), "B", id="c2d:B"),
    pytest.param(lambda: riprs.c2d(A, B, None), "Ts", id="c2d:Ts"),
    pytest.param(lambda: riprs.Mpc(None, B, C, 0.1), "A", id="Mpc:A"),
    pytest.param(lambda: riprs.Mpc(A, None, C, 0.1), "B", id="Mpc:B"),
    pytest.param(lambda: riprs.Mpc(A, B, None, 0.1), "C", id="Mpc:C"),
    pytest.param(lambda: riprs.Mpc(A, B, C, None), "Ts", id="Mpc:Ts"),
    pytest.param(lambda: riprs.Lqr(None), "K", id="Lqr:K"),
    pytest.param(lambda: riprs.Lqr.design(None, B4, I4, [[1.0]]), "A", id="Lqr.design:A"),
    pytest.param(lambda: riprs.Lqr.design(I4, B4, I4, None), "R", id="Lqr.design:R"),
    pytest.param(lambda: riprs.Lqg(None, I4, B4, C4, L4, L4), "K", id="Lqg:K"),
    pytest.param(lambda: riprs.Lqg(K4, I4, B4, C4, L4, None), "M", id="Lqg:M"),
]


def _names(pattern: str) -> str:
    # The argument as a word of the message: "R" must not be satisfied by "RN" or "Rn".
    return rf"(?<![A-Za-z_]){re.escape(pattern)}(?![A-Za-z_])"


@pytest.mark.parametrize(("call", "name"), REQUIRED)
def test_none_for_a_required_matrix_is_a_type_error_naming_it(call, name) -> None:
    with pytest.raises((TypeError, ValueError)):
        call(control)  # python-control gives these None no meaning either
    with pytest.raises(TypeError, match=_names(name)) as info:
        call(riprs)
    assert not isinstance(info.value, riprs.RiprsError)
    assert "NaN" not in str(info.value)


@pytest.mark.parametrize(("call", "name"), RIPRS_ONLY)
def test_none_for_a_required_argument_of_riprs_own_functions_is_a_type_error(call, name) -> None:
    with pytest.raises(TypeError, match=_names(name)) as info:
        call()
    assert "NaN" not in str(info.value)


def test_the_type_error_says_what_the_argument_must_be() -> None:
    with pytest.raises(TypeError, match=r"^R must be an array of real numbers, got None$"):
        riprs.dlqr(A, B, Q, None)

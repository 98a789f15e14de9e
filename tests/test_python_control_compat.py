"""What a user switching from python-control sees (docs/matlab.md, "Switching from
python-control"): the same calls give the same numbers, and the error tables hold against the
installed python-control."""

from __future__ import annotations

import numpy as np
import pytest

import riprs

control = pytest.importorskip("control")

A = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 0.8]])
B = np.array([[0.0, 1.0], [1.0, 0.0], [0.5, 0.5]])
C = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _dsys():
    return control.ss(A, B, C, np.zeros((2, 2)), 0.1)


def test_dlqr_and_dlqe_with_a_python_control_system_agree() -> None:
    sys = _dsys()
    ours, theirs = riprs.dlqr(sys, np.eye(3), np.eye(2)), control.dlqr(sys, np.eye(3), np.eye(2))
    for got, want in zip(ours, theirs, strict=True):
        np.testing.assert_allclose(np.sort_complex(np.ravel(got)), np.sort_complex(np.ravel(want)))
    L, P, E = riprs.dlqe(sys, np.eye(2), np.eye(2))
    L_ct, P_ct, E_ct = control.dlqe(sys, np.eye(2), np.eye(2))
    np.testing.assert_allclose(L, L_ct, rtol=1e-10)
    np.testing.assert_allclose(P, P_ct, rtol=1e-10)
    np.testing.assert_allclose(np.sort_complex(E), np.sort_complex(E_ct), rtol=1e-10)


def test_integral_action_agrees_with_python_control() -> None:
    sys = _dsys()
    C_int = np.array([[1.0, 0.0, 0.0]])
    Q = np.diag([1.0, 1.0, 1.0, 0.1])
    K, S, _ = riprs.dlqr(sys, Q, np.eye(2), integral_action=C_int)
    K_ct, S_ct, _ = control.dlqr(sys, Q, np.eye(2), integral_action=C_int)
    np.testing.assert_allclose(K, K_ct, rtol=1e-9)
    np.testing.assert_allclose(S, S_ct, rtol=1e-9)


@pytest.mark.parametrize("method", [None, "scipy"])
def test_method_keyword_selects_the_same_answer(method) -> None:
    X, _, G = riprs.dare(A, B, np.eye(3), np.eye(2), method=method)
    X_ct, _, G_ct = control.dare(A, B, np.eye(3), np.eye(2), method=method)
    np.testing.assert_allclose(X, X_ct, rtol=1e-10)
    np.testing.assert_allclose(G, G_ct, rtol=1e-10)


def _both(call):
    """The exceptions python-control and riprs raise for the same call."""
    errors = []
    for library in (control, riprs):
        with pytest.raises(Exception) as info:
            call(library)
        errors.append(info.value)
    return errors


def test_a_wrong_shape_is_a_value_error_in_both() -> None:
    ct_err, rp_err = _both(lambda lib: lib.dlqr(A, C.T[:2], np.eye(3), np.eye(3)))
    assert isinstance(ct_err, ValueError)
    assert isinstance(rp_err, riprs.ShapeError) and isinstance(rp_err, ValueError)
    assert "B" in str(rp_err)


@pytest.mark.parametrize(
    "call",
    [
        lambda lib: lib.dlqr(A, B),  # too few arguments
        lambda lib: lib.dlqr(A, B, np.eye(3), np.eye(2), integrator=None),  # unknown keyword
        lambda lib: lib.dlqe(A, C),  # too few arguments
        lambda lib: lib.dlqr(control.tf([1], [1, 0.5], 0.1), [[1.0]], [[1.0]]),  # not state space
    ],
)
def test_a_malformed_call_is_a_type_error_in_both(call) -> None:
    ct_err, rp_err = _both(call)
    assert isinstance(ct_err, TypeError)
    assert isinstance(rp_err, TypeError)


def test_unrecognized_keyword_wording() -> None:
    for function, args in [
        (riprs.dlqr, (A, B, np.eye(3), np.eye(2))),
        (riprs.dlqe, (A, B, C, np.eye(2), np.eye(2))),
        (riprs.dare, (A, B, np.eye(3), np.eye(2))),
    ]:
        with pytest.raises(TypeError, match=r"unrecognized keywords: 'typo' \(accepted: "):
            function(*args, typo=1)


@pytest.mark.parametrize(
    ("call", "riprs_class"),
    [
        (lambda lib: lib.dare(A, B, np.triu(np.ones((3, 3))), np.eye(2)), riprs.NotSymmetricError),
        (
            lambda lib: lib.dlqr(A, B, np.eye(3), np.eye(2), method="nosuchmethod"),
            riprs.InvalidParameterError,
        ),
        (
            lambda lib: lib.dlqr(control.ss(A, B, C, 0), np.eye(3), np.eye(2)),
            riprs.InvalidParameterError,
        ),
    ],
)
def test_value_errors_python_control_reports_as_type_errors(call, riprs_class) -> None:
    # The documented catch-all (TypeError, ValueError) covers both libraries.
    ct_err, rp_err = _both(call)
    assert isinstance(ct_err, (TypeError, ValueError))
    assert isinstance(rp_err, riprs_class) and isinstance(rp_err, ValueError)


def test_inputs_are_untouched_by_a_refused_call() -> None:
    copies = [M.copy() for M in (A, B)]
    with pytest.raises(riprs.ShapeError):
        riprs.dlqr(A, B, np.eye(3), np.eye(2), integral_action=np.eye(2))
    for M, copy in zip((A, B), copies, strict=True):
        np.testing.assert_array_equal(M, copy)

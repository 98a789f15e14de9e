"""Every malformed input raises a specific ValueError subclass that names the argument."""

from __future__ import annotations

import numpy as np
import pytest

import riprs

A = np.array([[1.1, 0.2], [0.0, 0.9]])
B = np.array([[0.0], [1.0]])
Q = np.eye(2)
R = np.array([[1.0]])


@pytest.mark.parametrize(
    ("kwargs", "exc", "name"),
    [
        ({"A": np.ones((2, 3))}, riprs.ShapeError, "A"),
        ({"B": np.ones((3, 1))}, riprs.ShapeError, "B"),
        ({"Q": np.eye(3)}, riprs.ShapeError, "Q"),
        ({"R": np.eye(2)}, riprs.ShapeError, "R"),
        ({"A": np.array([[np.nan, 0], [0, 1]])}, riprs.NonFiniteError, "A"),
        ({"B": np.array([[np.inf], [1.0]])}, riprs.NonFiniteError, "B"),
        ({"Q": np.array([[1.0, 0.5], [0.0, 1.0]])}, riprs.NotSymmetricError, "Q"),
        # A singular R is solved where R + B'XB is invertible (test_dare_scipy.py); an
        # indefinite one is refused.
        ({"R": np.array([[-1.0]])}, riprs.NotPositiveSemidefiniteError, "R"),
        (
            {"A": np.diag([1.5, 0.5]), "B": np.array([[0.0], [1.0]])},
            riprs.NotStabilizableError,
            "(A, B)",
        ),
    ],
)
def test_dare_bad_input(kwargs, exc, name):
    args = {"A": A, "B": B, "Q": Q, "R": R, **kwargs}
    copies = {k: np.array(v, copy=True) for k, v in args.items()}
    with pytest.raises(exc, match=__import__("re").escape(name)) as info:
        riprs.dare(args["A"], args["B"], args["Q"], args["R"])
    assert isinstance(info.value, ValueError)
    for k, v in args.items():
        np.testing.assert_array_equal(v, copies[k])  # inputs untouched


def test_dare_shape_of_s_and_e():
    with pytest.raises(riprs.ShapeError, match="S"):
        riprs.dare(A, B, Q, R, S=np.ones((2, 2)))
    with pytest.raises(riprs.ShapeError, match="E"):
        riprs.dare(A, B, Q, R, E=np.ones((3, 3)))


def test_no_stabilizing_solution_on_unit_circle():
    # A marginal mode that Q does not penalise: X = 0 solves the equation but is not stabilizing.
    with pytest.raises(riprs.NoStabilizingSolutionError):
        riprs.dare([[1.0]], [[1.0]], [[0.0]], [[1.0]])


def test_dlqr_indefinite_weights():
    with pytest.raises(riprs.NotPositiveSemidefiniteError, match="Q"):
        riprs.dlqr(A, B, np.diag([1.0, -1.0]), R)
    with pytest.raises(riprs.NotPositiveSemidefiniteError, match="N"):
        riprs.dlqr(A, B, Q, R, N=np.array([[5.0], [5.0]]))


def test_dlqe_not_detectable():
    # The unstable first state is invisible to C.
    A2 = np.diag([1.3, 0.5])
    with pytest.raises(riprs.NotDetectableError, match=r"\(A, C\)"):
        riprs.dlqe(A2, np.eye(2), [[0.0, 1.0]], np.eye(2), [[1.0]])


def test_kalman_bad_covariances():
    with pytest.raises(riprs.NotPositiveDefiniteError, match="Rn"):
        riprs.kalman(A, np.eye(2), [[1.0, 0.0]], np.eye(2), [[0.0]])
    with pytest.raises(riprs.NotPositiveSemidefiniteError, match="Qn"):
        riprs.kalman(A, np.eye(2), [[1.0, 0.0]], -np.eye(2), [[1.0]])
    with pytest.raises(riprs.ShapeError, match="H"):
        riprs.kalman(A, np.eye(2), [[1.0, 0.0]], np.eye(2), [[1.0]], H=np.ones((2, 2)))


def test_c2d_bad_sample_time():
    for ts in (0.0, -0.1, float("nan"), float("inf")):
        with pytest.raises(riprs.InvalidParameterError, match="Ts"):
            riprs.c2d(A, B, ts)


def test_complex_and_non_numeric_input_raise_type_error():
    with pytest.raises(TypeError, match="A"):
        riprs.dare(A + 1j, B, Q, R)
    with pytest.raises(TypeError, match="Q"):
        riprs.dare(A, B, "not a matrix", R)
    with pytest.raises(riprs.ShapeError, match="A"):
        riprs.dare(np.ones((2, 2, 2)), B, Q, R)


def test_c2d_overflow_raises_instead_of_nan():
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        riprs.c2d(A * 1e300, B, 0.1)

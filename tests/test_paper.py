"""The paper's recovered model reproduces its printed numbers (section 3, eq. (12))."""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl

import riprs
from riprs import paper


def test_kalman_gains_round_to_eq12():
    L, M = paper.kalman_gains()
    np.testing.assert_array_equal(np.round(L, 4), paper.PRINTED["L"])
    decimals = np.full(M.shape, 4)
    decimals[0, 1] = 3  # printed as 0.029
    rounded = np.vectorize(lambda v, d: round(v, d))(M, decimals)
    np.testing.assert_array_equal(rounded, paper.PRINTED["M"])


def test_kalman_gains_from_public_api_equal_scipy_design():
    """riprs.kalman on the eq. (3) model, and an independent scipy design, agree."""
    aug = paper.augmented_model()
    Qn, Rn, Nn = paper.noise_model()
    kf = riprs.kalman(aug.A, np.eye(5), aug.C, Qn, Rn, Nn)
    P = sl.solve_discrete_are(aug.A.T, aug.C.T, Qn, Rn, s=Nn)
    S = aug.C @ P @ aug.C.T + Rn
    np.testing.assert_allclose(kf.L, (aug.A @ P @ aug.C.T + Nn) @ np.linalg.inv(S), atol=1e-9)
    np.testing.assert_allclose(kf.M, P @ aug.C.T @ np.linalg.inv(S), atol=1e-9)
    L, _M = paper.kalman_gains()
    np.testing.assert_allclose(kf.L, L, atol=1e-12)


def test_discrete_model_matches_printed_to_printed_precision():
    plant = paper.discrete_model()
    printed = paper.PRINTED["Ad"].copy()
    printed[0, 1] = 0.0099  # documented typo correction (printed 0.001)
    half_unit = np.full((4, 4), 0.5e-4)
    half_unit[1, 3] = 0.5e-5
    half_unit[2, :] = 0.5e-3
    half_unit[3, 3] = 0.5e-3
    assert np.all(np.abs(plant.A - printed) <= half_unit * 1.0001)
    assert np.all(np.abs(plant.B - paper.PRINTED["Bd"]) <= 0.5e-4)
    Ad, Bd = riprs.c2d(paper.continuous_model().A, paper.continuous_model().B, paper.TS)
    np.testing.assert_allclose(plant.A, Ad, atol=1e-15)
    np.testing.assert_allclose(plant.B, Bd, atol=1e-15)


def test_printed_a_typo_breaks_eq12():
    """Evidence for correction 1: with the printed 0.001 the gains miss eq. (12) badly."""
    aug = paper.augmented_model()
    A = aug.A.copy()
    A[0, 1] = 0.001
    Qn, Rn, Nn = paper.noise_model()
    kf = riprs.kalman(A, np.eye(5), aug.C, Qn, Rn, Nn)
    assert abs(kf.L[0, 0] - paper.PRINTED["L"][0, 0]) > 0.05


def test_noise_model_matches_eq8_to_10():
    Qn, Rn, Nn = paper.noise_model()
    printed_q = np.array(
        [
            [0, 0.0008, 0, 0.0005, 0],
            [0.0008, 0.159, 0.0005, 0.0993, 0],  # eq. (8) prints 0.008 at [1, 0]: see module docs
            [0, 0.0005, 0, 0.0003, 0],
            [0.0005, 0.0993, 0.0003, 0.0621, 0],
            [0, 0, 0, 0, 0.0001],
        ]
    )
    half_unit = np.full((5, 5), 0.5e-4)
    half_unit[1, 1] = 0.5e-3  # printed with three decimals
    assert np.all(np.abs(Qn - printed_q) <= half_unit)
    np.testing.assert_array_equal(Rn, np.eye(2))
    np.testing.assert_array_equal(Nn, np.zeros((5, 2)))


def test_lqr_gain_is_stabilizing_and_matches_python_control():
    import control

    plant = paper.discrete_model()
    Q, R = paper.lqr_weights()
    K_ref, _, _ = control.dlqr(plant.A, plant.B, Q, R)
    np.testing.assert_allclose(paper.lqr_gain(), K_ref, rtol=1e-8)
    assert np.abs(np.linalg.eigvals(plant.A - plant.B @ paper.lqr_gain())).max() < 1


def test_table1_values():
    assert paper.TABLE1["MPC"] == (0.073, 0.005, 0.8)
    assert paper.TABLE1["LQR"] == (0.061, 0.007, 1.75)
    assert paper.TABLE1["LQG"] == (0.341, 0.015, 0.308)


def test_cli_gains_prints_both(capsys):
    from riprs.cli import main

    assert main(["gains"]) == 0
    out = capsys.readouterr().out
    assert "0.0723" in out and "1.0357" in out and "max |round(L, 4) - printed L| = 0.0e+00" in out

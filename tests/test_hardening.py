"""Finite but extreme inputs end quickly with an error naming the cause, never with NaN/Inf."""

from __future__ import annotations

import numpy as np
import pytest

import riprs


@pytest.mark.parametrize("scale", [1e41, 1e60, 1e300])
def test_c2d_of_huge_entries_is_refused(scale: float) -> None:
    A = np.array([[0.0, scale], [-scale, 0.5 * scale]])
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        riprs.c2d(A, np.ones((2, 1)), 0.01)


def test_plant_step_bounds_substeps_and_refuses_overflow() -> None:
    plant = riprs.Plant()
    x = [0.0, 0.0, 0.1, 0.0]
    with pytest.raises(riprs.InvalidParameterError, match="substeps"):
        plant.step(x, 0.0, 0.01, 200_000_000)
    # A step far beyond RK4's stability limit is refused up front: it would return finite
    # nonsense (entries ~1e149 at dt = 1e10) or overflow.
    for dt in (1e10, 1e300):
        with pytest.raises(riprs.InvalidParameterError, match="dt"):
            plant.step(x, 0.0, dt)
    with pytest.raises(riprs.DivergedError):
        plant.integrate(x, np.full(1000, 1000.0), 0.01)
    with pytest.raises(riprs.InvalidParameterError, match="u"):
        plant.integrate(x, np.zeros(1_000_000), 0.01, substeps=100)


def test_diverging_simulation_is_flagged_not_a_fall() -> None:
    plant = riprs.FurutaParams(Dp=1e300)
    ctrl = riprs.Lqr(np.array([[-2.0, -1.5, 30.0, 2.5]]), rate_cutoff=float("inf"))
    res = riprs.simulate(plant, ctrl, duration=1.0, x0=[0.0, 0.0, 0.05, 0.0])
    assert res.diverged
    assert not res.fell
    assert res.fall_time is None
    assert np.all(np.isfinite(res.x_final))
    # A real fall is still a fall and not a divergence.
    idle = riprs.Lqr(np.zeros((1, 4)))
    res = riprs.simulate(riprs.Plant(), idle, duration=2.0, x0=[0.0, 0.0, 0.3, 0.0])
    assert res.fell and not res.diverged


def test_fit_that_never_improves_is_not_converged() -> None:
    Ad, Bd = riprs.Plant.paper().linearize_discrete(0.01)
    _, report = riprs.FurutaParams.fit(Ad * 1e300, Bd, 0.01)
    assert not report["converged"]
    _, report = riprs.FurutaParams.fit(Ad, Bd, 0.01)
    assert report["converged"] and report["max_weighted_residual"] < 1e-6


def test_simulator_refuses_noise_whose_square_overflows() -> None:
    ctrl = riprs.Lqr(np.zeros((1, 4)))
    with pytest.raises(riprs.InvalidParameterError, match="noise_std"):
        riprs.simulate(riprs.Plant(), ctrl, duration=0.1, noise_std=1e300)


def test_mpc_design_errors_name_the_cause() -> None:
    A, B = riprs.Plant.paper().linearize_discrete(0.01)
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    with pytest.raises(riprs.InvalidParameterError, match="prediction_horizon"):
        riprs.Mpc(A, B, C, 0.01, prediction_horizon=10_000, input_rate_weights=[1.0])
    with pytest.raises(riprs.InvalidParameterError, match="output_scales"):
        riprs.Mpc(
            A,
            B,
            C,
            0.01,
            output_scales=[1e300, 1e300],
            output_disturbance=(np.eye(1), np.array([[0.01]]), np.ones((2, 1))),
        )
    with pytest.raises(riprs.InvalidParameterError, match="output_disturbance"):
        riprs.Mpc(
            A, B, C, 0.01, output_disturbance=(np.eye(1), np.array([[1e300]]), np.ones((2, 1)))
        )


def test_ragged_and_overflowing_arguments_are_named() -> None:
    eye = np.eye(2)
    with pytest.raises(riprs.ShapeError, match="B"):
        riprs.dare(eye, [[1.0, 2.0], [3.0]], eye, [[1.0]])
    plant = riprs.Plant()
    with pytest.raises(riprs.InvalidParameterError, match="substeps"):
        plant.step([0, 0, 0.1, 0], 0.0, 0.01, -1)
    with pytest.raises(riprs.InvalidParameterError, match="max_iter"):
        riprs.FurutaParams.fit(np.eye(4), np.ones((4, 1)), 0.01, max_iter=-1)
    A, B = plant.linearize_discrete(0.01)
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    with pytest.raises(riprs.InvalidParameterError, match="prediction_horizon"):
        riprs.Mpc(A, B, C, 0.01, prediction_horizon=2**64)
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        riprs.Mpc(A, B, C, 10**400)
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        riprs.c2d(np.eye(2), np.ones((2, 1)), 10**400)
    with pytest.raises(riprs.InvalidParameterError, match="substeps"):
        riprs.simulate(plant, riprs.Lqr(np.zeros((1, 4))), duration=0.1, substeps=-1)


def test_empty_weights_are_not_the_default() -> None:
    A, B = riprs.Plant().linearize_discrete(0.01)
    C = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    with pytest.raises(riprs.ShapeError, match="input_rate_weights"):
        riprs.Mpc(A, B, C, 0.01, input_rate_weights=[])
    with pytest.raises(riprs.ShapeError, match="input_bounds"):
        riprs.Mpc(A, B, C, 0.01, input_bounds=[])


def test_wrongly_shaped_a_is_named() -> None:
    B, Q, R = np.ones((2, 1)), np.eye(2), np.eye(1)
    for call in (riprs.dare, riprs.dlqr):
        with pytest.raises(riprs.ShapeError, match=r"^A"):
            call(np.eye(3), B, Q, R)


def test_dlqr_refuses_a_continuous_time_system() -> None:
    control = pytest.importorskip("control")
    sys = control.ss(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.eye(2), 0, 0)
    with pytest.raises(riprs.InvalidParameterError, match="discrete"):
        riprs.dlqr(sys, np.eye(2), np.eye(1))
    ct = riprs.StateSpace(np.eye(2), np.ones((2, 1)), np.eye(2), np.zeros((2, 1)), 0.0)
    with pytest.raises(riprs.InvalidParameterError, match="discrete"):
        riprs.dlqr(ct, np.eye(2), np.eye(1))
    # A discrete system (and python-control's unspecified dt=None or True) is accepted.
    A_d, B_d = np.array([[1.0, 0.1], [0.0, 1.0]]), np.array([[0.0], [0.1]])
    dsys = control.ss(A_d, B_d, np.eye(2), np.zeros((2, 1)), 0.1)
    K, _, _ = riprs.dlqr(dsys, np.eye(2), np.eye(1))
    K_ref, _, _ = control.dlqr(dsys, np.eye(2), np.eye(1))
    np.testing.assert_allclose(K, K_ref, rtol=1e-10)

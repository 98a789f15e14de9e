"""LQR and LQG step by step against independent numpy implementations of the paper's laws,
with gains from python-control."""

from __future__ import annotations

import control
import numpy as np
import pytest

import riprs
from riprs import Lqg, Lqr

RNG = np.random.default_rng(3)


def paper_gain() -> np.ndarray:
    plant = riprs.paper.discrete_model()
    Q, R = riprs.paper.lqr_weights()
    K, _, _ = control.dlqr(plant.A, plant.B, Q, R)
    return np.asarray(K)


def test_paper_lqr_gain_is_python_control_dlqr() -> None:
    np.testing.assert_allclose(Lqr.paper().K, paper_gain(), rtol=1e-8)
    np.testing.assert_allclose(Lqg.paper().K, paper_gain(), rtol=1e-8)
    plant = riprs.paper.discrete_model()
    Q, R = riprs.paper.lqr_weights()
    np.testing.assert_allclose(Lqr.design(plant.A, plant.B, Q, R).K, paper_gain(), rtol=1e-8)


@pytest.mark.parametrize("cutoff", [5.0, 20.0, np.inf])
def test_lqr_step_is_the_filtered_difference_law(cutoff: float) -> None:
    K = paper_gain()
    ts = 0.01
    lqr = Lqr(K, ts, rate_cutoff=cutoff, u_min=-5.0, u_max=7.0)
    a = np.exp(-2 * np.pi * cutoff * ts)
    ys = np.cumsum(RNG.normal(size=(60, 2)) * 0.01, axis=0)
    rs = np.column_stack([np.where(np.arange(60) > 20, 1.0, 0.0), np.zeros(60)])
    prev, rate = None, np.zeros(2)
    for y, r in zip(ys, rs, strict=True):
        if prev is not None:
            rate = a * rate + (1 - a) * (y - prev) / ts
        prev = y
        x_hat = np.array([y[0], rate[0], y[1], rate[1]])
        want = np.clip(-(K @ (x_hat - [r[0], 0.0, r[1], 0.0]))[0], -5.0, 7.0)
        u = lqr.step(y, r)
        assert u.shape == (1,)
        assert u[0] == pytest.approx(want, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(lqr.x_hat, x_hat, rtol=1e-12, atol=1e-12)


def test_lqg_step_is_the_current_estimator_law() -> None:
    """Eqs. (4)-(6) with the eq. (11) gains, the unscaled B_d for prediction, and u = -K x_p."""
    K = paper_gain()
    aug = riprs.paper.augmented_model()
    L, M = riprs.paper.kalman_gains()
    Bu = np.zeros((5, 1))
    Bu[:4] = riprs.paper.discrete_model().B
    lqg = Lqg.paper()
    np.testing.assert_allclose(lqg.L, L, rtol=1e-12)
    np.testing.assert_allclose(lqg.M, M, rtol=1e-12)
    custom = Lqg(K, aug.A, Bu, aug.C, L, M, 0.01)
    prior = np.zeros(5)
    for k in range(80):
        y = np.array([0.02 * np.sin(0.1 * k), 0.05 * np.cos(0.3 * k)]) + RNG.normal(size=2) * 0.01
        r = np.array([1.0 if k > 10 else 0.0, 0.0])
        e = y - aug.C @ prior
        post = prior + M @ e
        u = np.clip(-(K @ (post[:4] - [r[0], 0.0, r[1], 0.0]))[0], -12, 12)
        assert lqg.step(y, r)[0] == pytest.approx(u, rel=1e-10, abs=1e-12)
        assert custom.step(y, r)[0] == pytest.approx(u, rel=1e-10, abs=1e-12)
        np.testing.assert_allclose(lqg.x_hat, post, rtol=1e-10, atol=1e-14)
        prior = aug.A @ prior + Bu[:, 0] * u + L @ e


@pytest.mark.parametrize("make", [Lqr.paper, Lqg.paper])
def test_reset_restarts_and_inputs_are_clamped(make) -> None:
    c = make()
    ys = RNG.normal(size=(30, 2)) * 0.3
    first = [c.step(y, [1.0, 0.0])[0] for y in ys]
    assert max(abs(u) for u in first) == 12.0  # large errors saturate at the paper's +-12 V
    c.reset()
    second = [c.step(y, [1.0, 0.0])[0] for y in ys]
    assert first == second
    assert c.u_min == -12.0 and c.u_max == 12.0 and c.Ts == 0.01


def test_bad_arguments_raise_naming_them() -> None:
    K = paper_gain()
    with pytest.raises(riprs.ShapeError, match="K"):
        Lqr(np.ones((1, 3)))
    with pytest.raises(riprs.NonFiniteError, match="K"):
        Lqr([[1.0, np.nan, 0.0, 0.0]])
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        Lqr(K, 0.0)
    with pytest.raises(riprs.InvalidParameterError, match="rate_cutoff"):
        Lqr(K, rate_cutoff=-1.0)
    with pytest.raises(riprs.InvalidParameterError, match="bounds"):
        Lqr(K, u_min=1.0, u_max=-1.0)
    aug = riprs.paper.augmented_model()
    L, M = riprs.paper.kalman_gains()
    with pytest.raises(riprs.ShapeError, match="M"):
        Lqg(K, aug.A, aug.B[:, :1], aug.C, L, M[:4])
    with pytest.raises(riprs.ShapeError, match="A"):
        Lqg(K, np.eye(3), np.ones((3, 1)), np.ones((2, 3)), np.ones((3, 2)), np.ones((3, 2)))
    lqr = Lqr(K)
    with pytest.raises(riprs.ShapeError, match="y"):
        lqr.step([0.0, 0.0, 0.0])
    with pytest.raises(riprs.NonFiniteError, match="r"):
        lqr.step([0.0, 0.0], [np.inf, 0.0])
    # A failed call changes nothing.
    assert lqr.x_hat is not None and not np.any(lqr.x_hat)


def test_one_huge_reading_does_not_disable_the_lqr():
    # 1e308 overflows the rate difference; the sample is discarded, not kept as inf/NaN.
    c = riprs.Lqr.paper()
    fresh = riprs.Lqr.paper()
    c.step([0.0, 0.0])
    c.step([1e308, 0.0])
    assert np.isfinite(c.x_hat).all()
    for _ in range(50):
        u = c.step([0.0, 0.05])
    fresh.step([0.0, 0.0])
    for _ in range(50):
        v = fresh.step([0.0, 0.05])
    # Both have seen the pendulum at 0.05 rad long enough for the rate filters to settle.
    np.testing.assert_allclose(u, v, atol=1e-9)
    assert abs(u[0]) > 1.0


def test_simulating_at_another_sample_time_is_refused():
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        riprs.simulate(riprs.paper.plant(), riprs.Lqg.paper(), 1.0, Ts=0.02)


def test_an_lqr_with_its_observer_cancels_a_constant_input_disturbance() -> None:
    # ``lqr.disturbance_bandwidth``: on python-control's discretisation of the paper's model,
    # with exact angles and a constant 0.8 V at the plant input, the observer's estimate
    # settles on the disturbance and the arm on its reference; the paper's LQR keeps an arm
    # offset instead.
    plant = riprs.paper.discrete_model()
    A, B = np.asarray(plant.A), np.asarray(plant.B).ravel()

    def run(spec: riprs.Spec) -> tuple[np.ndarray, float | None]:
        lqr = spec.build_controllers(0.01)["LQR"]
        x = np.array([0.05, 0.0, 0.02, 0.0])
        for _ in range(800):
            u = float(lqr.step([x[0], x[2]], [0.0, 0.0])[0])
            x = A @ x + B * (u + 0.8)
        return x, lqr.input_disturbance

    x, d = run(riprs.Spec.from_dict({"lqr": {"disturbance_bandwidth": 2.0}}))
    assert d == pytest.approx(0.8, abs=1e-6)
    np.testing.assert_allclose(x, 0.0, atol=1e-6)
    x, d = run(riprs.Spec())
    assert d is None and abs(x[0]) > 1e-3
    with pytest.raises(riprs.ConfigError, match=r"lqr\.disturbance_bandwidth"):
        riprs.Spec.from_dict({"lqr": {"disturbance_bandwidth": -1.0}})

"""Integral action for LQR and LQG (``lqr.integral_weight``, MATLAB's ``lqi``): the gain
against scipy's Riccati solution of the augmented model, the integrator law against a numpy
replay, anti-windup at the voltage bound, and no offset under a constant arm torque."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_discrete_are
from scipy.signal import cont2discrete

import riprs
from riprs.config import Spec

TS = 0.01
QUBE = {"preset": "qube_servo2"}


def _spec(qi: float, **plant: float) -> Spec:
    return Spec.from_dict({"plant": {**QUBE, **plant}, "lqr": {"integral_weight": qi}})


def test_off_by_default_and_for_the_paper_preset():
    assert Spec().lqr.integral_weight == 0.0
    for c in Spec().build_controllers(TS).values():
        assert getattr(c, "integral_gain", None) is None


def test_the_gain_is_lqi_of_the_design_model():
    spec = _spec(20.0)
    a, b = spec.build_plant().linearize()
    ad, bd, *_ = cont2discrete((a, b, np.eye(4), np.zeros((4, 1))), TS, method="zoh")
    ai = np.block([[ad, np.zeros((4, 1))], [-TS * np.eye(1, 4), np.ones((1, 1))]])
    bi = np.vstack([bd, [[0.0]]])
    q = np.diag([*spec.lqr.Q, 20.0])
    r = np.array([[spec.lqr.R]])
    p = solve_discrete_are(ai, bi, q, r)
    k = np.linalg.solve(r + bi.T @ p @ bi, bi.T @ p @ ai)
    built = spec.build_controllers(TS)
    for name in ("LQR", "LQG"):
        c = built[name]
        np.testing.assert_allclose(c.K, k[:, :4], rtol=1e-7, err_msg=name)
        assert c.integral_gain == pytest.approx(k[0, 4], rel=1e-7)
    # The augmented closed loop is stable.
    assert np.max(np.abs(np.linalg.eigvals(ai - bi @ k))) < 1


def test_the_integrator_law_against_a_numpy_replay():
    spec = _spec(20.0)
    lqi = spec.build_controllers(TS)["LQR"]
    plain = riprs.Lqr(lqi.K, TS, rate_cutoff=spec.lqr.rate_cutoff)
    ki = lqi.integral_gain
    rng = np.random.default_rng(1)
    xi, hi = 0.0, 12.0
    saturated = 0
    for k in range(400):
        theta = 0.3 * np.sin(0.02 * k) + 1e-3 * rng.standard_normal()
        y = [theta, 0.01 * np.cos(0.05 * k)]
        ref = [2.5 if 100 <= k < 200 else 0.0, 0.0]
        u = lqi.step(y, ref)[0]
        v = plain.step(y, ref)[0]
        # The plain regulator clamps too; the unclamped state feedback is needed here.
        fb = -(np.asarray(lqi.K) @ (np.asarray(lqi.x_hat) - [ref[0], 0, ref[1], 0]))[0]
        want = np.clip(fb - ki * xi, -hi, hi)
        assert u == pytest.approx(want, abs=1e-9), k
        if abs(fb) < hi:
            assert fb == pytest.approx(v, abs=1e-9)
        # Conditional integration: not deeper into a saturation.
        err = ref[0] - theta
        push = -ki * TS * err
        unclamped = fb - ki * xi
        if (unclamped > hi and push > 0) or (unclamped < -hi and push < 0):
            saturated += 1
        else:
            xi += TS * err
    assert saturated > 10


@pytest.mark.parametrize("name", ["LQR", "LQG"])
def test_no_arm_offset_under_a_constant_arm_torque(name):
    # 0.004 N m on the arm from 2 s on: without integral action the arm settles away from the
    # reference (the torque needs a voltage that only an offset gives); with it, it returns.
    offsets = {}
    for qi in (0.0, 20.0):
        spec = _spec(qi)
        c = spec.build_controllers(TS)[name]
        r = riprs.simulate(
            spec.build_plant(), c, 10.0, reference=0.5, reference_time=1.0,
            torque_disturbance=(2.0, 0.004), encoder_counts=[2048, 2048],
            noise_std=[5e-4, 5e-4],
        )
        assert not r.fell
        t, x = np.asarray(r.t), np.asarray(r.x)
        offsets[qi] = abs(np.mean(x[t >= 7.0, 0]) - 0.5)
    # LQG's output-disturbance state already takes up most of the offset (0.011 rad left,
    # LQR 0.07); the integrator removes the rest.
    assert offsets[0.0] > 0.005, offsets
    assert offsets[20.0] < 0.003 and offsets[20.0] < offsets[0.0] / 5, offsets


def test_bumpless_start_after_the_swing_up():
    # The integrator is zero at the catch: up to it, and at it, the run with integral action
    # is the run without, sample for sample; after it, it balances.
    runs = {}
    for qi in (0.0, 20.0):
        spec = _spec(qi)
        lqr = spec.build_controllers(TS)["LQR"]
        s = riprs.SwingUp(balance=lqr, plant=spec.build_plant(), **spec.swing_up)
        runs[qi] = riprs.simulate(
            spec.build_plant(), s, 15.0, x0=[0.0, 0.0, np.pi, 0.0],
            encoder_counts=[2048, 2048], noise_std=[5e-4, 5e-4],
        )
    plain, lqi = runs[0.0], runs[20.0]
    assert lqi.swing_up_succeeded and lqi.catch_time == plain.catch_time
    k = int(np.searchsorted(np.asarray(lqi.t), lqi.catch_time))
    np.testing.assert_array_equal(np.asarray(lqi.u)[: k + 1], np.asarray(plain.u)[: k + 1])
    assert not np.array_equal(np.asarray(lqi.u)[k + 1 :], np.asarray(plain.u)[k + 1 :])
    t, x = np.asarray(lqi.t), np.asarray(lqi.x)
    assert np.ptp(x[t >= 12.0, 0]) < 0.05


def test_a_negative_weight_is_named():
    with pytest.raises(riprs.ConfigError, match=r"lqr\.integral_weight"):
        _spec(-1.0)

"""The closed-loop simulator: balance and tracking on the nonlinear plant, agreement with a loop
written here around scipy's solve_ivp, the sensor model, disturbances, falls, reproducibility,
the parallel batch and argument errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import riprs
from riprs import FurutaParams, Lqg, Lqr, Plant, simulate, simulate_batch

TILTED = [0.0, 0.0, 0.15, 0.0]


def rhs(plant: Plant, u: float, torque: float = 0.0):
    return lambda _t, x: plant.derivative(x, u, torque)


@pytest.mark.parametrize("make", [Lqr.paper, Lqg.paper])
def test_balances_from_a_tilt_and_tracks_the_1_rad_step(make) -> None:
    res = simulate(
        riprs.paper.plant(),
        make(),
        10.0,
        reference=1.0,
        reference_time=3.0,
        x0=TILTED,
        encoder_counts=2048,
        noise_std=1e-3,
        seed=4,
    )
    assert not res.fell and res.fall_time is None
    assert res.x.shape == (1000, 4) and res.y.shape == (1000, 2) and res.u.shape == (1000,)
    assert res.t[-1] == pytest.approx(9.99)
    # Recovers from the tilt (overshooting to the other side) and is upright before the step.
    assert np.max(np.abs(res.x[:, 2])) < 0.25
    assert np.all(np.abs(res.x[250:300, 2]) < 0.02)
    assert np.all(np.abs(res.x[250:300, 0]) < 0.1)
    # The arm reaches the reference and stays near it.
    assert np.all(np.abs(res.x[-100:, 0] - 1.0) < 0.06)
    assert np.all(np.abs(res.x[-100:, 2]) < 0.02)
    assert np.max(np.abs(res.u)) <= 12.0
    assert res.x_hat is not None and np.all(np.isfinite(res.x_hat))
    assert np.all(res.compute_time > 0)
    # Tab. 1 indices are the RMS errors of the record.
    np.testing.assert_allclose(
        res.rmse,
        [
            np.sqrt(np.mean((res.y[:, 0] - res.r[:, 0]) ** 2)),
            np.sqrt(np.mean((res.y[:, 1] - res.r[:, 1]) ** 2)),
            np.sqrt(np.mean(res.u**2)),
        ],
        rtol=1e-12,
    )


def test_qube_balances_with_its_own_lqr() -> None:
    plant = Plant.qube_servo2()
    Ad, Bd = plant.linearize_discrete(0.01)
    Q, R = riprs.paper.lqr_weights()
    res = simulate(plant, Lqr.design(Ad, Bd, Q, R), 5.0, reference=1.0, x0=TILTED)
    assert not res.fell
    assert res.x_final[0] == pytest.approx(1.0, abs=0.01)


def test_matches_a_solve_ivp_loop() -> None:
    """The same sampled loop run with scipy's integrator between samples."""
    plant = riprs.paper.plant()
    duration, ts = 2.0, 0.01
    res = simulate(plant, Lqg.paper(), duration, reference=1.0, reference_time=0.5, x0=TILTED)
    ctrl = Lqg.paper()
    x = np.array(TILTED)
    for k in range(200):
        np.testing.assert_allclose(res.x[k], x, atol=1e-8)
        r = [1.0 if k * ts >= 0.5 else 0.0, 0.0]
        u = ctrl.step(x[[0, 2]], r)[0]
        assert res.u[k] == pytest.approx(u, abs=1e-6)
        x = solve_ivp(rhs(plant, u), (0, ts), x, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
    np.testing.assert_allclose(res.x_final, x, atol=1e-8)


def test_sensor_quantises_adds_seeded_noise_and_output_steps() -> None:
    counts = np.array([1024, 4096])
    q = 2 * np.pi / counts
    res = simulate(riprs.paper.plant(), Lqr.paper(), 3.0, x0=TILTED, encoder_counts=counts)
    ratio = res.y / q
    np.testing.assert_allclose(ratio, np.round(ratio), atol=1e-9)
    assert np.all(np.abs(res.y - res.x[:, [0, 2]]) <= q / 2 + 1e-12)

    std = np.array([2e-3, 5e-3])
    a = simulate(riprs.paper.plant(), Lqg.paper(), 5.0, x0=TILTED, noise_std=std, seed=11)
    b = simulate(riprs.paper.plant(), Lqg.paper(), 5.0, x0=TILTED, noise_std=std, seed=11)
    c = simulate(riprs.paper.plant(), Lqg.paper(), 5.0, x0=TILTED, noise_std=std, seed=12)
    np.testing.assert_array_equal(a.y, b.y)
    np.testing.assert_array_equal(a.x, b.x)
    assert not np.array_equal(a.y, c.y)
    noise = a.y - a.x[:, [0, 2]]
    # 500 samples: the sample std is within ~15 % of the true one with overwhelming probability.
    np.testing.assert_allclose(noise.std(axis=0), std, rtol=0.15)
    assert np.all(np.abs(noise.mean(axis=0)) < 4 * std / np.sqrt(500))

    d = np.array([0.05, -0.02])
    res = simulate(riprs.paper.plant(), Lqg.paper(), 3.0, x0=TILTED, output_disturbance=(1.0, d))
    offset = res.y - res.x[:, [0, 2]]
    np.testing.assert_allclose(offset[res.t < 1.0], 0.0, atol=1e-15)
    np.testing.assert_allclose(offset[res.t >= 1.0], np.broadcast_to(d, offset[res.t >= 1.0].shape))


def test_torque_disturbance_gives_the_static_lqr_offset() -> None:
    """With no integral action the LQR settles where its voltage cancels the torque:
    kt u / Rm + tau = 0 and u = -K0 (theta - r), so theta - r = tau Rm / (kt K0)."""
    params = FurutaParams.paper()
    lqr = Lqr.paper()
    tau = 0.002
    res = simulate(Plant(params), lqr, 15.0, x0=TILTED, torque_disturbance=(1.0, tau))
    assert not res.fell
    k0 = lqr.K[0, 0]
    expected = tau * params.Rm / (params.kt * k0)
    assert res.x_final[0] == pytest.approx(expected, rel=1e-3)
    assert res.u[-1] == pytest.approx(-tau * params.Rm / params.kt, rel=1e-3)


def test_a_fall_is_flagged_and_the_record_stops_there() -> None:
    res = simulate(riprs.paper.plant(), Lqr(np.zeros((1, 4))), 10.0, x0=TILTED)
    assert res.fell
    assert 0.0 < res.fall_time < 2.0
    assert len(res.t) == int(np.ceil(res.fall_time / 0.01 - 1e-9))
    assert np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.y))
    assert abs(res.x_final[2]) > np.pi / 2
    assert np.all(np.abs(res.x[:, 2]) <= np.pi / 2)
    small = simulate(riprs.paper.plant(), Lqr(np.zeros((1, 4))), 10.0, x0=TILTED, fall_limit=0.3)
    assert small.fall_time < res.fall_time


def test_reference_sequence_equals_the_step() -> None:
    n = 300
    seq = np.where(np.arange(n) * 0.01 >= 1.0, 1.0, 0.0)
    plant = riprs.paper.plant()
    a = simulate(plant, Lqr.paper(), 3.0, x0=TILTED, reference=1.0, reference_time=1.0)
    b = simulate(riprs.paper.plant(), Lqr.paper(), 3.0, x0=TILTED, reference=seq)
    c = simulate(
        riprs.paper.plant(), Lqr.paper(), 3.0, x0=TILTED, reference=np.column_stack([seq, 0 * seq])
    )
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.x, c.x)
    np.testing.assert_array_equal(a.r[:, 0], seq)


def test_batch_equals_serial_runs_in_plant_major_order() -> None:
    variants = [FurutaParams.paper(), FurutaParams.paper().replace(mp=0.028), Plant.qube_servo2()]
    seeds = [5, 9]
    opts = {"x0": TILTED, "noise_std": 2e-3, "encoder_counts": 2048, "reference": 1.0}
    batch = simulate_batch(variants, Lqg.paper(), seeds, 3.0, **opts)
    assert len(batch) == 6
    for i, res in enumerate(batch):
        serial = simulate(variants[i // 2], Lqg.paper(), 3.0, seed=seeds[i % 2], **opts)
        np.testing.assert_array_equal(res.x, serial.x)
        np.testing.assert_array_equal(res.y, serial.y)
        np.testing.assert_array_equal(res.u, serial.u)
    assert len(simulate_batch(riprs.paper.plant(), Lqr.paper(), 3, 1.0)) == 3


def test_simulate_does_not_touch_the_callers_controller() -> None:
    lqg = Lqg.paper()
    lqg.step([0.1, 0.02], [0.0, 0.0])
    before = lqg.x_hat.copy()
    simulate(riprs.paper.plant(), lqg, 1.0, x0=TILTED)
    np.testing.assert_array_equal(lqg.x_hat, before)


def test_bad_arguments_raise_naming_them() -> None:
    plant = riprs.paper.plant()
    with pytest.raises(TypeError, match="controller"):
        simulate(plant, object())
    with pytest.raises(TypeError, match="plant"):
        simulate("paper", Lqr.paper())
    with pytest.raises(riprs.InvalidParameterError, match="x0"):
        simulate(plant, Lqr.paper(), x0=[0, 0, 2.0, 0])
    with pytest.raises(riprs.ShapeError, match="reference"):
        simulate(plant, Lqr.paper(), 1.0, reference=np.zeros(50))
    with pytest.raises(riprs.InvalidParameterError, match="noise_std"):
        simulate(plant, Lqr.paper(), noise_std=-1.0)
    with pytest.raises(riprs.InvalidParameterError, match="encoder_counts"):
        simulate(plant, Lqr.paper(), encoder_counts=0)
    with pytest.raises(riprs.InvalidParameterError, match="Ts"):
        simulate(plant, Lqr.paper(), Ts=-0.01)
    with pytest.raises(riprs.InvalidParameterError, match="duration"):
        simulate(plant, Lqr.paper(), duration=0.0)
    with pytest.raises(riprs.InvalidParameterError, match="substeps"):
        simulate(plant, Lqr.paper(), substeps=0)
    with pytest.raises(riprs.NonFiniteError, match="x0"):
        simulate(plant, Lqr.paper(), x0=[np.nan, 0, 0, 0])
    with pytest.raises(riprs.InvalidParameterError, match="seed"):
        simulate(plant, Lqr.paper(), seed=-1)
    with pytest.raises(riprs.InvalidParameterError, match="seeds"):
        simulate_batch(plant, Lqr.paper(), [])
    with pytest.raises(TypeError, match="seeds"):
        simulate_batch(plant, Lqr.paper(), seed=3)


def test_paired_batch_equals_individual_runs():
    params = [riprs.FurutaParams.paper(), riprs.FurutaParams.paper().replace(mp=0.03)]
    ctrl = riprs.Lqr.paper()
    opts = {"noise_std": 1e-3, "x0": [0.0, 0.0, 0.05, 0.0], "reference": 1.0}
    batch = riprs.simulate_batch(params, ctrl, [11, 12], 2.0, paired=True, **opts)
    assert len(batch) == 2
    for p, seed, got in zip(params, [11, 12], batch, strict=True):
        ref = riprs.simulate(p, ctrl, 2.0, seed=seed, **opts)
        np.testing.assert_array_equal(got.x, ref.x)
        np.testing.assert_array_equal(got.u, ref.u)
    with pytest.raises(riprs.InvalidParameterError, match="seeds"):
        riprs.simulate_batch(params, ctrl, [1, 2, 3], 1.0, paired=True)

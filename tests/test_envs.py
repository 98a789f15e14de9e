"""riprs.envs: the Gymnasium environments, the native vector environment, randomisation, the
log replay, and riprs.simulate with a Python callable as the controller."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import riprs

gymnasium = pytest.importorskip("gymnasium")
from gymnasium.utils.env_checker import check_env  # noqa: E402
from gymnasium.vector import SyncVectorEnv  # noqa: E402

import riprs.envs as envs  # noqa: E402

TS = 0.01
IDS = list(envs.TASKS.values())


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_passes_without_warnings(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(gymnasium.make(env_id).unwrapped)
        check_env(gymnasium.make(env_id, randomize=True, action_delay=2).unwrapped)


@pytest.mark.parametrize("env_id", IDS)
def test_make_vec_returns_the_native_vector_env(env_id: str) -> None:
    venv = gymnasium.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(venv, envs.PendulumVecEnv)
    assert venv.metadata["autoreset_mode"] == gymnasium.vector.AutoresetMode.NEXT_STEP
    obs, _ = venv.reset(seed=0)
    assert obs.shape == (3, envs.OBS_DIM) and obs.dtype == np.float32
    assert venv.observation_space.contains(obs)


SETTINGS = [
    {"max_episode_steps": 37},
    {
        "max_episode_steps": 23,
        "randomize": True,
        "action_delay": 1,
        "observation_latency": 2,
    },
]


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("settings", SETTINGS)
def test_vector_env_matches_single_envs_bit_for_bit(env_id: str, settings: dict) -> None:
    n, steps = 5, 120
    native = gymnasium.make_vec(
        env_id, num_envs=n, vectorization_mode="vector_entry_point", **settings
    )
    # Gymnasium's own vectoriser over the single-pendulum env: the reference semantics of
    # seeding (seed + i) and next-step autoreset.
    sync = SyncVectorEnv([lambda: gymnasium.make(env_id, **settings) for _ in range(n)])
    o1, _ = native.reset(seed=1234)
    o2, _ = sync.reset(seed=1234)
    np.testing.assert_array_equal(o1, o2)
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(steps):
        a = rng.uniform(-1, 1, size=(n, 1)).astype(np.float32)
        r1 = native.step(a)
        r2 = sync.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            np.testing.assert_array_equal(x, y)
        ended += int(np.sum(r1[2] | r1[3]))
    assert ended >= n  # autoresets happened and matched
    # Partial resets follow Gymnasium's reset_mask as well.
    mask = np.array([True, False, True, False, False])
    o1, _ = native.reset(seed=7, options={"reset_mask": mask})
    o2, _ = sync.reset(seed=7, options={"reset_mask": mask})
    np.testing.assert_array_equal(o1[mask], o2[mask])


def test_parallel_stepping_is_bit_for_bit_the_serial_one() -> None:
    # 300 environments are stepped on rayon's threads; their first three are the serial ones.
    big = envs.PendulumVecEnv(300, randomize=True)
    small = envs.PendulumVecEnv(3, randomize=True)
    ob, _ = big.reset(seed=5)
    os_, _ = small.reset(seed=5)
    np.testing.assert_array_equal(ob[:3], os_)
    rng = np.random.default_rng(1)
    for _ in range(50):
        a = rng.uniform(-1, 1, size=(300, 1)).astype(np.float32)
        ob = big.step(a)[0]
        os_ = small.step(a[:3])[0]
        np.testing.assert_array_equal(ob[:3], os_)


def test_the_environment_steps_rip_cores_plant_and_sensor() -> None:
    params = riprs.FurutaParams.qube_servo2()
    # Limits it never reaches: the test follows the plant past where an episode would end.
    env = envs.PendulumEnv(
        params=params,
        init_spread=0.0,
        noise_std=0.0,
        encoder_counts=2048,
        fall_limit=10.0,
        arm_limit=100.0,
    )
    env.reset(seed=3)
    plant = riprs.Plant(params)
    actions = np.sin(np.arange(80) * 0.2).astype(np.float32)
    x = plant.integrate(np.zeros(4), 12.0 * actions.astype(np.float64), TS, 10)
    q = 2 * np.pi / 2048
    for k, a in enumerate(actions):
        obs, *_ = env.step(np.array([a]))
        np.testing.assert_array_equal(env.state, x[k + 1])
        y = q * np.round(x[k + 1, [0, 2]] / q)
        np.testing.assert_allclose(
            obs[:4], [np.cos(y[0]), np.sin(y[0]), np.cos(y[1]), np.sin(y[1])], atol=1e-7
        )


def test_measurement_noise_has_the_configured_standard_deviation() -> None:
    env = envs.PendulumEnv(
        "swing_up", encoder_counts=None, noise_std=[2e-3, 5e-4], max_episode_steps=5000
    )
    env.reset(seed=11)
    errors = []
    for _ in range(4000):
        obs, *_ = env.step(np.zeros(1, dtype=np.float32))
        x = env.state
        measured = np.arctan2(obs[[1, 3]], obs[[0, 2]]).astype(np.float64)
        errors.append(np.angle(np.exp(1j * (measured - x[[0, 2]]))))
    e = np.array(errors)
    # float32 observations add about 1e-7 rad; 4000 samples estimate a std to about 2 %.
    np.testing.assert_allclose(e.std(axis=0), [2e-3, 5e-4], rtol=0.06)
    assert np.all(np.abs(e.mean(axis=0)) < 4 * np.array([2e-3, 5e-4]) / np.sqrt(4000))


def test_observed_rates_are_the_lqr_rate_filter_of_the_measurements() -> None:
    env = envs.PendulumEnv(init_spread=0.0, noise_std=0.0, encoder_counts=None, rate_cutoff=20.0)
    env.reset(seed=0)
    a_f = np.exp(-2 * np.pi * 20.0 * TS)
    rates = np.zeros(2)
    prev = env.state[[0, 2]]
    for k in range(40):
        obs, *_ = env.step(np.array([0.4 if k % 3 else -0.6], dtype=np.float32))
        y = env.state[[0, 2]]
        rates = a_f * rates + (1 - a_f) * (y - prev) / TS
        prev = y
        np.testing.assert_allclose(obs[4:], rates, rtol=1e-6, atol=1e-6)


def test_swing_up_starts_hanging_and_balance_terminates_past_the_fall_limit() -> None:
    env = envs.PendulumEnv("swing_up", init_spread=0.0, noise_std=0.0)
    obs, _ = env.reset(seed=0)
    assert obs[2] == pytest.approx(-1.0)  # cos(pi)
    for _ in range(200):
        _, r, term, _, _ = env.step(np.zeros(1, dtype=np.float32))
        assert not term
        assert r == pytest.approx(1 - 0.8, abs=1e-3)  # hanging: |alpha| = pi
    bal = envs.PendulumEnv(fall_limit=0.3)
    bal.reset(seed=0)
    for _ in range(500):
        _, _, term, _, _ = bal.step(np.ones(1, dtype=np.float32))
        if term:
            break
    assert term and (abs(bal.state[2]) > 0.3 or abs(bal.state[0]) > 1.5)


def test_seeds_reproduce_and_randomisation_stays_in_its_ranges() -> None:
    a = envs.PendulumVecEnv(4, randomize=True)
    b = envs.PendulumVecEnv(4, randomize=True)
    oa, _ = a.reset(seed=[9, 8, 7, 6])
    ob, _ = b.reset(seed=[9, 8, 7, 6])
    np.testing.assert_array_equal(oa, ob)
    nominal = riprs.FurutaParams.paper()
    draws = []
    single = envs.PendulumEnv(randomize=True)
    for s in range(200):
        single.reset(seed=s)
        p = single.episode_params
        draws.append((p.mp / nominal.mp, p.Dr / nominal.Dr, p.Vd, p.Cr))
        delay, noise = single.native.episode_sensor(0)
        assert 0 <= delay <= 2 and all(0 <= v <= 2e-3 for v in noise)
    d = np.array(draws)
    assert np.all(np.abs(d[:, 0] - 1) <= 0.1) and np.all(np.abs(d[:, 1] - 1) <= 0.5)
    assert np.all((d[:, 2] >= 0) & (d[:, 2] <= 0.3)) and np.all((d[:, 3] >= 0) & (d[:, 3] <= 0.003))
    # Uniform draws: the sample spans most of the range.
    assert d[:, 0].min() < 0.92 and d[:, 0].max() > 1.08
    single.reset(seed=3)
    first = single.episode_params
    single.reset(seed=3)
    assert single.episode_params == first


def test_an_experiment_file_configures_plant_sensor_and_voltage(tmp_path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(
        '[plant]\npreset = "qube_servo2"\nmp = 0.03\n\n'
        "[sensor]\nencoder_counts = [512, 4096]\nnoise_std = [0.0, 0.0]\n\n"
        "[mpc]\ninput_bounds = [[-6.0, 6.0]]\n"
    )
    env = envs.PendulumEnv(config=rig, init_spread=0.0, fall_limit=10.0, arm_limit=100.0)
    assert env.u_limit == 6.0
    assert env.episode_params == riprs.FurutaParams.qube_servo2().replace(mp=0.03)
    env.reset(seed=0)
    for _ in range(30):
        obs, *_ = env.step(np.array([0.5], dtype=np.float32))
    theta, alpha = env.state[0], env.state[2]
    q = 2 * np.pi / np.array([512, 4096])
    y = q * np.round(np.array([theta, alpha]) / q)
    np.testing.assert_allclose(obs[[1, 3]], np.sin(y), atol=1e-7)
    # Full voltage is 6 V: the same actions on a 12 V environment move the arm further.
    big = envs.PendulumEnv(
        params=env.episode_params, init_spread=0.0, noise_std=0.0, fall_limit=10.0, arm_limit=100.0
    )
    big.reset(seed=0)
    for _ in range(30):
        big.step(np.array([0.5], dtype=np.float32))
    assert abs(big.state[0]) > 1.5 * abs(theta)


def test_covariance_draws_have_the_stated_covariance(tmp_path) -> None:
    cov = [[4e-8, 1e-9], [1e-9, 1e-10]]
    rig = tmp_path / "rig.toml"
    rig.write_text(
        '[plant]\npreset = "qube_servo2"\n\n'
        '[plant_covariance]\nparameters = ["Dr", "Dp"]\n'
        f"matrix = {cov}\n"
    )
    env = envs.PendulumEnv(config=rig)
    nominal = riprs.FurutaParams.qube_servo2()
    samples = []
    for s in range(3000):
        env.reset(seed=s)
        p = env.episode_params
        samples.append((p.Dr - nominal.Dr, p.Dp - nominal.Dp))
    got = np.cov(np.array(samples).T)
    np.testing.assert_allclose(got, cov, rtol=0.1, atol=2e-12)


def test_bad_settings_are_named_and_bad_actions_change_nothing() -> None:
    with pytest.raises(riprs.InvalidParameterError, match="action_delay"):
        envs.PendulumEnv(action_delay=17)
    with pytest.raises(riprs.InvalidParameterError, match=r"randomize\.mp"):
        envs.PendulumEnv(randomize={"relative": {"mp": 1.5}})
    with pytest.raises(KeyError, match="Jx"):
        envs.PendulumEnv(randomize={"relative": {"Jx": 0.1}})
    with pytest.raises(TypeError, match="unknown environment setting"):
        envs.PendulumEnv(colour="red")
    with pytest.raises(riprs.InvalidParameterError, match="task"):
        envs.PendulumEnv("juggle")
    venv = envs.PendulumVecEnv(2)
    venv.reset(seed=0)
    before = venv.state(1).copy()
    with pytest.raises(riprs.InvalidParameterError, match="actions"):
        venv.step(np.array([[0.0], [np.nan]], dtype=np.float32))
    np.testing.assert_array_equal(venv.state(1), before)
    with pytest.raises(riprs.InvalidParameterError, match="actions"):
        venv.step(np.zeros(3, dtype=np.float32))


def _lqr_callable(lqr: riprs.Lqr):
    """The documented LQR (filtered-difference rates, u = sat(-K x_hat)) written in Python."""
    k = np.asarray(lqr.K).reshape(4)
    a_f = np.exp(-2 * np.pi * lqr.rate_cutoff * lqr.Ts)
    state: dict[str, np.ndarray] = {}

    def controller(y: np.ndarray) -> float:
        if "prev" in state:
            state["rates"] = a_f * state["rates"] + (1 - a_f) * (y - state["prev"]) / lqr.Ts
        else:
            state["rates"] = np.zeros(2)
        state["prev"] = y.copy()
        x_hat = np.array([y[0], state["rates"][0], y[1], state["rates"][1]])
        return float(np.clip(-k @ x_hat, lqr.u_min, lqr.u_max))

    return controller


def test_simulate_accepts_a_callable_and_it_matches_lqr() -> None:
    plant = riprs.Plant.paper()
    lqr = riprs.Lqr.paper()
    opts = {"x0": [0.0, 0.0, 0.1, 0.0], "encoder_counts": 2048, "noise_std": 1e-3, "seed": 4}
    native = riprs.simulate(plant, lqr, 3.0, **opts)
    mine = riprs.simulate(plant, _lqr_callable(lqr), 3.0, **opts)
    assert not native.fell and not mine.fell
    np.testing.assert_allclose(mine.u, native.u, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(mine.x, native.x, atol=1e-6)


def test_callable_errors_propagate() -> None:
    plant = riprs.Plant.paper()

    def broken(y):
        raise RuntimeError("policy crashed")

    with pytest.raises(RuntimeError, match="policy crashed"):
        riprs.simulate(plant, broken, 1.0, x0=[0, 0, 0.05, 0])
    calls = []

    def fails_at_ten(y):
        calls.append(y.copy())
        if len(calls) == 10:
            raise KeyboardInterrupt
        return 0.0

    with pytest.raises(KeyboardInterrupt):
        riprs.simulate(plant, fails_at_ten, 100.0, x0=[0, 0, 0.05, 0])
    assert len(calls) == 10  # the run ended at the failing sample
    assert all(c.shape == (2,) and c.dtype == np.float64 for c in calls)
    with pytest.raises(riprs.NonFiniteError, match="finite"):
        riprs.simulate(plant, lambda y: float("nan"), 1.0, x0=[0, 0, 0.05, 0])
    with pytest.raises(TypeError):
        riprs.simulate(plant, lambda y: "volts", 1.0, x0=[0, 0, 0.05, 0])


def test_a_policy_on_the_env_observation_runs_through_simulate_like_lqr() -> None:
    # An "agent" that is LQR on the environment's observation: through policy_controller and
    # riprs.simulate it must balance the plant as riprs.Lqr does (float32 observations aside).
    env = envs.PendulumEnv()
    lqr = riprs.Lqr.paper()
    k = np.asarray(lqr.K).reshape(4)

    def policy(obs: np.ndarray) -> np.ndarray:
        theta, alpha = np.arctan2(obs[1], obs[0]), np.arctan2(obs[3], obs[2])
        x_hat = np.array([theta, obs[4], alpha, obs[5]], dtype=np.float64)
        return np.array([-k @ x_hat / env.u_limit])

    plant = riprs.Plant.paper()
    # Exact angles: with an encoder, float32 rounding would now and then move a reading across
    # a count boundary and the runs would part ways.
    opts = {"x0": [0.0, 0.0, 0.1, 0.0]}
    ref = riprs.simulate(plant, lqr, 5.0, **opts)
    got = riprs.simulate(plant, envs.policy_controller(policy, env), 5.0, **opts)
    assert not got.fell
    np.testing.assert_allclose(got.u, ref.u, atol=1e-3)


def _rtlog(res: riprs.SimResult) -> riprs.RtLog:
    n = len(res.t)
    return riprs.RtLog(
        t=res.t,
        seq=np.arange(n, dtype=np.int64),
        theta=res.y[:, 0],
        alpha=res.y[:, 1],
        theta_ref=np.zeros(n),
        u=res.u,
        xhat=np.zeros((n, 0)),
        compute_us=np.zeros(n),
        jitter_us=np.zeros(n),
        status=np.zeros(n, dtype=np.int64),
        phase=np.full(n, "balance"),
        meta={},
    )


def test_replay_reports_the_fit_of_a_log() -> None:
    # A log made by riprs.simulate on the QUBE-Servo 2: a hanging pendulum driven open loop
    # by a multisine (a Python callable as the controller), as `rip-rt excite` would drive it.
    spec = riprs.Spec.from_toml('[plant]\npreset = "qube_servo2"\n')
    plant = spec.build_plant()
    clock = iter(range(10**6))

    def excite(y: np.ndarray) -> float:
        t = next(clock) * TS
        return 2.0 * np.sin(2 * np.pi * 0.7 * t) + 1.5 * np.sin(2 * np.pi * 2.3 * t)

    # A callable is a balance controller to simulate: a fall limit beyond pi never stops it.
    res = riprs.simulate(
        plant, excite, 4.0, x0=[0, 0, np.pi, 0], encoder_counts=2048, fall_limit=4.0
    )
    assert len(res.t) == 400
    log = _rtlog(res)
    fit = envs.replay(log, spec)
    assert fit.y_sim.shape == (len(res.t), 2)
    # Its own plant: only quantisation and the start's rate estimate differ.
    assert max(fit.nrmse) < 0.05, fit.nrmse
    # Identical definition to MATLAB's NRMSE, recomputed here.
    y = fit.y
    expect = np.linalg.norm(y - fit.y_sim, axis=0) / np.linalg.norm(y - y.mean(axis=0), axis=0)
    np.testing.assert_allclose(fit.nrmse, expect, rtol=1e-9)
    wrong = spec.params.replace(kt=spec.params.kt * 0.6, Dr=spec.params.Dr * 3)
    bad = envs.replay(log, spec, params=wrong)
    assert min(bad.nrmse) > 3 * max(fit.nrmse), (bad.nrmse, fit.nrmse)

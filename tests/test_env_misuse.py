"""riprs.envs under misuse: shared between threads, pickled and copied, stepped past the end of
an episode, and given bad settings, actions, options and seeds."""

from __future__ import annotations

import copy
import pickle
import warnings
from typing import Any

import numpy as np
import pytest
from threads import run_threads

import riprs

gymnasium = pytest.importorskip("gymnasium")
from gymnasium.utils.env_checker import check_env  # noqa: E402
from gymnasium.vector import SyncVectorEnv  # noqa: E402

import riprs.envs as envs  # noqa: E402

# -- threads ---------------------------------------------------------------------------------


def test_one_env_stepped_from_four_threads_applies_every_step_whole() -> None:
    # Hanging at rest with no voltage never terminates, and every step's action is the same, so
    # whatever order the threads' steps run in, the environment must end where 400 serial steps
    # end, and the 400 observations handed out must be exactly the serial ones.
    settings: dict[str, Any] = {"max_episode_steps": 10_000}
    shared = envs.PendulumEnv("swing_up", **settings)
    shared.reset(seed=3)
    zero = np.zeros(1, dtype=np.float32)
    got: list[np.ndarray] = []

    def stepper() -> None:
        for _ in range(100):
            obs, _, terminated, truncated, _ = shared.step(zero)
            assert not terminated and not truncated
            got.append(obs)
            _ = shared.state

    errors = run_threads(stepper, stepper, stepper, stepper)
    assert not errors, errors
    alone = envs.PendulumEnv("swing_up", **settings)
    alone.reset(seed=3)
    expected = [alone.step(zero)[0] for _ in range(400)]
    np.testing.assert_array_equal(shared.state, alone.state)
    key = lambda o: o.tobytes()  # noqa: E731
    assert sorted(map(key, got)) == sorted(map(key, expected))


def test_one_vector_env_stepped_from_four_threads_applies_every_step_whole() -> None:
    # 300 environments: the steps run on rayon's threads with the GIL released the longest.
    shared = envs.PendulumVecEnv(300, "swing_up", max_episode_steps=10_000)
    shared.reset(seed=8)
    zero = np.zeros((300, 1), dtype=np.float32)
    rewards: list[np.ndarray] = []

    def stepper() -> None:
        for _ in range(8):
            rewards.append(shared.step(zero)[1])
            shared.state(299)

    errors = run_threads(stepper, stepper, stepper, stepper)
    assert not errors, errors
    alone = envs.PendulumVecEnv(300, "swing_up", max_episode_steps=10_000)
    alone.reset(seed=8)
    expected = [alone.step(zero)[1] for _ in range(32)]
    np.testing.assert_array_equal(shared.state(299), alone.state(299))
    key = lambda r: r.tobytes()  # noqa: E731
    assert sorted(map(key, rewards)) == sorted(map(key, expected))


# -- pickle and copies -----------------------------------------------------------------------


def _actions(n: int, seed: int, shape: tuple[int, ...]) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1, 1, size=shape).astype(np.float32) for _ in range(n)]


def _run_single(env: envs.PendulumEnv, actions: list[np.ndarray]) -> list[Any]:
    """Steps through episode ends, resetting without a seed: the generator must continue."""
    out: list[Any] = []
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        out.append((obs.tobytes(), reward, terminated, truncated, env.state.tobytes()))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append((obs.tobytes(), env.episode_params))
    return out


SINGLE = {
    "randomize": True,
    "action_delay": 2,
    "observation_latency": 1,
    "max_episode_steps": 25,
}


@pytest.mark.parametrize(
    "duplicate",
    [
        lambda e: pickle.loads(pickle.dumps(e)),
        copy.deepcopy,
        copy.copy,
    ],
    ids=["pickle", "deepcopy", "copy"],
)
def test_a_copied_env_is_independent_and_continues_identically(duplicate) -> None:
    env = envs.PendulumEnv("balance", **SINGLE)
    env.reset(seed=21)
    for a in _actions(30, 0, (1,)):
        env.step(a)
    twin = duplicate(env)
    assert twin.native is not env.native
    actions = _actions(120, 1, (1,))
    # The original runs first: had the copy shared any of its state, the copy's run would
    # differ from it.
    first = _run_single(env, actions)
    second = _run_single(twin, actions)
    assert first == second
    assert any(len(r) == 2 for r in first)  # episodes ended and restarted on the way


@pytest.mark.parametrize(
    "duplicate",
    [lambda e: pickle.loads(pickle.dumps(e)), copy.deepcopy, copy.copy],
    ids=["pickle", "deepcopy", "copy"],
)
def test_a_copied_vector_env_is_independent_and_continues_identically(duplicate) -> None:
    venv = envs.PendulumVecEnv(5, randomize=True, action_delay=1, max_episode_steps=17)
    venv.reset(seed=4)
    for a in _actions(9, 2, (5, 1)):
        venv.step(a)
    twin = duplicate(venv)
    actions = _actions(60, 3, (5, 1))
    first = [tuple(x.tobytes() for x in venv.step(a)[:4]) for a in actions]
    second = [tuple(x.tobytes() for x in twin.step(a)[:4]) for a in actions]
    assert first == second
    assert [venv.state(i).tobytes() for i in range(5)] == [
        twin.state(i).tobytes() for i in range(5)
    ]


def test_copies_before_the_first_reset_and_through_gymnasium_wrappers() -> None:
    fresh = envs.PendulumEnv(randomize=True)
    clone = pickle.loads(pickle.dumps(fresh))
    with pytest.raises(gymnasium.error.ResetNeeded):
        clone.step(np.zeros(1, dtype=np.float32))
    made = gymnasium.make("riprs/SwingUp-v0", randomize=True)
    made.reset(seed=2)
    twin = copy.deepcopy(made)
    actions = _actions(40, 5, (1,))
    assert [made.step(a)[0].tobytes() for a in actions] == [
        twin.step(a)[0].tobytes() for a in actions
    ]
    # Gymnasium's checker, an independent reference, on an unpickled environment.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        made = gymnasium.make("riprs/Balance-v0", randomize=True, action_delay=1)
        check_env(pickle.loads(pickle.dumps(made.unwrapped)))
        check_env(copy.copy(made.unwrapped))


def test_a_corrupt_pickle_is_refused_with_a_clear_error() -> None:
    env = envs.PendulumEnv()
    env.reset(seed=0)
    state = env.native.__reduce__()[1][0]
    with pytest.raises(riprs.InvalidParameterError, match="state"):
        riprs._riprs.NativeVecEnv._from_state(state[:-3])
    with pytest.raises(riprs.InvalidParameterError, match="state"):
        riprs._riprs.NativeVecEnv._from_state(b"\x00" * len(state))


# -- stepping after the end ------------------------------------------------------------------


def _fall(env: envs.PendulumEnv) -> None:
    for _ in range(500):
        if env.step(np.ones(1, dtype=np.float32))[2]:
            return
    raise AssertionError("the pendulum did not fall")


def test_stepping_after_terminated_warns_once_per_episode_as_gymnasiums_envs_do() -> None:
    env = envs.PendulumEnv(fall_limit=0.3)
    env.reset(seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _fall(env)
        assert not caught
        for _ in range(3):
            env.step(np.zeros(1, dtype=np.float32))
    assert len(caught) == 1, [str(w.message) for w in caught]
    assert "terminated = True" in str(caught[0].message)
    assert "reset()" in str(caught[0].message)
    env.reset()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _fall(env)
        env.step(np.zeros(1, dtype=np.float32))
        env.step(np.zeros(1, dtype=np.float32))
    assert len(caught) == 1


# -- bad settings ----------------------------------------------------------------------------


BAD_SETTINGS = [
    ({"max_episode_steps": -1}, "max_episode_steps"),
    ({"max_episode_steps": 2**40}, "max_episode_steps"),
    ({"encoder_counts": 1}, "encoder_counts"),
    ({"encoder_counts": 2048.5}, "encoder_counts"),
    ({"encoder_counts": [2048, 2**25]}, "encoder_counts"),
    ({"Ts": 1e-12}, "Ts"),
    ({"Ts": 0.5}, "Ts"),
    ({"randomize": {"Vd": (100, 200)}}, r"randomize\.Vd"),
    ({"params": riprs.FurutaParams.paper().replace(Vd=15.0)}, "Vd"),
]


@pytest.mark.parametrize(("settings", "name"), BAD_SETTINGS)
def test_bad_settings_are_value_errors_naming_them(settings: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        envs.PendulumEnv(**settings)
    with pytest.raises(ValueError, match=name):
        envs.PendulumVecEnv(2, **settings)
    with pytest.raises(ValueError, match=name):
        gymnasium.make_vec(
            "riprs/Balance-v0", num_envs=2, vectorization_mode="vector_entry_point", **settings
        )


def test_rig_settings_follow_the_rig_files_rules() -> None:
    # One rule each: an environment refuses what an experiment file's [sensor] and [loop] do.
    with pytest.raises(ValueError, match="encoder_counts") as in_file:
        riprs.Spec.from_toml("[sensor]\nencoder_counts = [1, 2048]\n")
    with pytest.raises(ValueError, match="encoder_counts") as in_env:
        envs.PendulumEnv(encoder_counts=1)
    assert "128..=16777216" in str(in_file.value) and "128..=16777216" in str(in_env.value)
    envs.PendulumEnv(encoder_counts=128, Ts=0.001)
    envs.PendulumEnv(encoder_counts=2**24, Ts=0.02)


@pytest.mark.parametrize("num_envs", [-1, 0, 2**70])
def test_a_bad_num_envs_is_a_value_error_naming_it(num_envs: int) -> None:
    with pytest.raises(ValueError, match="num_envs"):
        envs.PendulumVecEnv(num_envs)
    with pytest.raises(ValueError, match="num_envs"):
        gymnasium.make_vec(
            "riprs/Balance-v0", num_envs=num_envs, vectorization_mode="vector_entry_point"
        )


# -- bad actions, options and seeds ----------------------------------------------------------


BAD_ACTIONS = [
    np.array([0.5 + 1j]),
    0.5 + 1j,
    None,
    "0.5",
    np.array([object()]),
    [None],
]


@pytest.mark.parametrize(
    "action", BAD_ACTIONS, ids=["complex-array", "complex", "None", "str", "object", "[None]"]
)
def test_a_bad_action_is_a_type_error_naming_it_and_changes_nothing(action: Any) -> None:
    env = envs.PendulumEnv(randomize=True)
    twin = envs.PendulumEnv(randomize=True)
    env.reset(seed=1)
    twin.reset(seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TypeError, match="action"):
            env.step(action)
    a = np.array([0.3], dtype=np.float32)
    assert env.step(a)[0].tobytes() == twin.step(a)[0].tobytes()
    venv = envs.PendulumVecEnv(1)
    venv.reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TypeError, match="actions"):
            venv.step(action if action is None or isinstance(action, str) else [action])


def test_unknown_reset_options_are_refused_naming_them() -> None:
    env = envs.PendulumEnv()
    env.reset(seed=0)
    env.step(np.ones(1, dtype=np.float32))
    before = env.state.copy()
    with pytest.raises(ValueError, match=r"options.*'foo'"):
        env.reset(options={"foo": 1})
    with pytest.raises(TypeError, match="options"):
        env.reset(options=5)  # type: ignore[arg-type]
    np.testing.assert_array_equal(env.state, before)
    env.reset(options={})
    venv = envs.PendulumVecEnv(2)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"options.*'reset_maks'"):
        venv.reset(options={"reset_maks": np.array([True, False])})
    with pytest.raises(TypeError, match="options"):
        venv.reset(options=[1])  # type: ignore[arg-type]


def test_vector_seeds_never_wrap_and_follow_the_single_envs() -> None:
    n = 3
    venv = envs.PendulumVecEnv(n)
    venv.reset(seed=0)
    before = [venv.state(i).copy() for i in range(n)]
    for seed in (2**64 - 1, 2**64 - n + 1):
        with pytest.raises(ValueError, match="seed"):
            venv.reset(seed=seed)
    for seed in (-1, 2**64):
        with pytest.raises(ValueError, match="seed"):
            venv.reset(seed=seed)
    with pytest.raises(TypeError, match="seed"):
        venv.reset(seed=1.5)  # type: ignore[arg-type]
    for i in range(n):
        np.testing.assert_array_equal(venv.state(i), before[i])
    # Gymnasium's own vectoriser seeds environment i with seed + i: the last seed that fits
    # 64 bits for every environment is accepted by both, and they agree.
    top = 2**64 - n
    sync = SyncVectorEnv([lambda: envs.PendulumEnv() for _ in range(n)])
    np.testing.assert_array_equal(venv.reset(seed=top)[0], sync.reset(seed=top)[0])
    with pytest.raises(ValueError, match="seed"):
        sync.reset(seed=top + 1)


def test_the_native_environment_queues_calls_from_threads() -> None:
    # Below riprs.envs's lock: each thread brings its own buffers, the native object is shared.
    native = envs.PendulumVecEnv(64, "swing_up", max_episode_steps=10_000).native
    native.reset(np.zeros((64, envs.OBS_DIM), dtype=np.float32), 5)

    def stepper() -> None:
        obs = np.zeros((64, envs.OBS_DIM), dtype=np.float32)
        reward, flags = np.zeros(64), np.zeros((2, 64), dtype=bool)
        for _ in range(50):
            native.step(np.zeros(64, dtype=np.float32), True, obs, reward, flags[0], flags[1])
            native.state(63)

    errors = run_threads(stepper, stepper, stepper, stepper)
    assert not errors, errors
    alone = envs.PendulumVecEnv(64, "swing_up", max_episode_steps=10_000)
    alone.reset(seed=5)
    for _ in range(200):
        alone.step(np.zeros((64, 1), dtype=np.float32))
    np.testing.assert_array_equal(native.state(63), alone.state(63))

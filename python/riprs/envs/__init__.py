"""Gymnasium environments of the pendulum riprs models (``pip install "riprs[gym]"``).

Importing this module registers

- ``riprs/Balance-v0``: start near upright, keep the pendulum up and the arm centred;
- ``riprs/SwingUp-v0``: start hanging, swing up and balance;

each with a single-pendulum entry point (:class:`PendulumEnv`, ``gymnasium.make``) and a native
vectorised one (:class:`PendulumVecEnv`, ``gymnasium.make_vec(id, num_envs=N,
vectorization_mode="vector_entry_point")``), which steps all ``N`` pendulums in one Rust call
with the GIL released. Both run ``rip-core``'s nonlinear plant, sensor model (encoder
quantisation, noise), voltage bound and control period (``rip_core::sim::vec_env``); the model
is not copied into Python. The observation, reward, termination, delays and randomisation are
documented in ``docs/gym.md``.
"""

from __future__ import annotations

import copy as _copy
import os
import sys
import threading
import types
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence, Union

import numpy as np

try:
    import gymnasium
    from gymnasium import spaces
    from gymnasium.vector import AutoresetMode, VectorEnv
    from gymnasium.vector.utils import batch_space
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise ImportError('riprs.envs needs Gymnasium 1.x: pip install "riprs[gym]"') from exc

from riprs import _riprs
from riprs._riprs import FurutaParams, InvalidParameterError, Plant, Spec, load_config
from riprs.identify import IdentifyError, read_plant_covariance
from riprs.log import RtLog, load_log

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "DEFAULT_RANDOMIZATION",
    "MAX_OBS_RATE",
    "OBS_DIM",
    "TASKS",
    "PendulumEnv",
    "PendulumVecEnv",
    "ReplayFit",
    "policy_controller",
    "replay",
]

#: Length of an observation ``[cos theta, sin theta, cos alpha, sin alpha, rate_theta,
#: rate_alpha]``.
OBS_DIM: int = _riprs.ENV_OBS_DIM
#: The tasks and their registered ids.
TASKS: dict[str, str] = {"balance": "riprs/Balance-v0", "swing_up": "riprs/SwingUp-v0"}

ConfigLike = Union[str, "os.PathLike[str]", Spec, None]

#: Bound of the observed rates (rad/s); they are clipped to it.
MAX_OBS_RATE: float = _riprs.ENV_MAX_OBS_RATE
_OBS_HIGH = np.array([1.0, 1.0, 1.0, 1.0, MAX_OBS_RATE, MAX_OBS_RATE], dtype=np.float32)
_SEED_LIMIT = 2**63


def _covariance_from_file(path: str) -> tuple[list[str], list[list[float]]] | None:
    """The ``[plant_covariance]`` of a rig file, or else of the identification file beside it
    (:func:`riprs.identify.read_plant_covariance`, the one reader of the format)."""
    try:
        found = read_plant_covariance(path)
    except IdentifyError as exc:
        raise InvalidParameterError(str(exc)) from None
    if found is None:
        return None
    return found[0], found[1].tolist()


def _spec_of(config: ConfigLike) -> tuple[Spec, tuple[list[str], list[list[float]]] | None]:
    if config is None:
        return Spec(), None
    if isinstance(config, Spec):
        return config, None
    path = os.fspath(config)
    cov = _covariance_from_file(path)
    with open(path, "rb") as f:
        if cov is None or "plant_covariance" not in tomllib.load(f):
            return load_config(path), cov
    # The covariance table is this module's hook (docs/gym.md); the rest is an experiment file.
    with open(path, "rb") as f:
        data = tomllib.load(f)
    data.pop("plant_covariance")
    for runtime in ("loop", "device", "safety", "calibration"):
        data.pop(runtime, None)
    return Spec.from_dict(data), cov


def _native(num_envs: int, task: str, config: ConfigLike, settings: dict[str, Any]) -> Any:
    if task not in TASKS:
        raise InvalidParameterError(f"invalid task: must be one of {sorted(TASKS)}, got {task!r}")
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
        raise TypeError(f"num_envs must be an int, got {type(num_envs)}")
    num_envs = int(num_envs)
    spec, cov = _spec_of(config)
    settings = dict(settings)
    randomize = settings.get("randomize")
    if randomize is True:
        randomize = dict(DEFAULT_RANDOMIZATION)
    elif randomize is False:
        randomize = None
    elif isinstance(randomize, Mapping):
        randomize = {k: dict(v) if isinstance(v, Mapping) else v for k, v in randomize.items()}
    if cov is not None:
        randomize = dict(randomize or {})
        randomize.setdefault("covariance", cov)
    settings["randomize"] = randomize
    if settings.get("encoder_counts", 0) is None:
        settings.pop("encoder_counts")
        settings["exact_angles"] = True
    return _riprs.NativeVecEnv(num_envs, spec, task, settings)


#: The ranges of ``randomize=True``: what sim-to-real reports on Furuta pendulums blame
#: (friction, stiction, delay, noise) over the envelope of ``docs/design.md``, and +-10 % (+-50 %
#: for the damping, which sources give orders of magnitude apart) on the physical parameters.
DEFAULT_RANDOMIZATION: Mapping[str, Any] = types.MappingProxyType(
    {
        "relative": {
            "mr": 0.1,
            "Lr": 0.1,
            "Jr": 0.1,
            "mp": 0.1,
            "Lp": 0.1,
            "Jp": 0.1,
            "Rm": 0.1,
            "kt": 0.1,
            "km": 0.1,
            "Dr": 0.5,
            "Dp": 0.5,
        },
        "Vd": (0.0, 0.3),
        "Cr": (0.0, 0.003),
        "Cp": (0.0, 2.5e-5),
        "action_delay": (0, 2),
        "noise_std": (0.0, 2e-3),
    }
)


def _spaces() -> tuple[spaces.Box, spaces.Box]:
    obs = spaces.Box(-_OBS_HIGH, _OBS_HIGH, shape=(OBS_DIM,), dtype=np.float32)
    act = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
    return obs, act


def _check_seed(seed: Any, name: str) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(seed)}")
    if not 0 <= int(seed) < 2**64:
        raise InvalidParameterError(f"invalid {name}: must be in [0, 2**64), got {seed}")
    return int(seed)


def _real_array(values: Any, name: str) -> np.ndarray:
    """``values`` as a float32 array; anything but real numbers is a ``TypeError`` naming
    ``name`` (numpy alone would turn None into NaN and drop an imaginary part with a
    warning)."""
    try:
        a = np.asarray(values)
    except (TypeError, ValueError):  # e.g. a ragged nested sequence
        raise TypeError(f"{name} must be real numbers, got {values!r}") from None
    if a.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be real numbers, got {values!r} (dtype {a.dtype})")
    return np.ascontiguousarray(a, dtype=np.float32)


def _check_options(options: Any, known: tuple[str, ...]) -> Mapping[str, Any]:
    """``reset``'s ``options``, refused if not a mapping or holding a key no reset reads (a
    misspelt option would otherwise be ignored)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise TypeError(f"options must be a dict, got {type(options).__name__}")
    unknown = [k for k in options if k not in known]
    if unknown:
        takes = f"it takes {', '.join(map(repr, known))}" if known else "it takes none"
        raise InvalidParameterError(
            f"invalid options: unknown reset option {', '.join(map(repr, unknown))}; {takes}"
        )
    return options


class _Shareable:
    """What both environments share: a lock that serialises ``reset`` and ``step`` across
    threads (the native call releases the GIL; without it a second thread's call would fail
    or interleave with the first's buffers), and copies and pickles that share nothing
    mutable with the original."""

    #: The instance's own output buffers: copied, never shared, by a copy or a pickle.
    _BUFFERS = ("_obs", "_reward", "_terminated", "_truncated", "_action")
    native: Any
    _lock: threading.Lock

    def __getstate__(self) -> dict[str, Any]:
        # A snapshot taken between two steps: the native environments, buffers and seeding
        # generator copied under the lock, so another thread's step cannot tear it.
        with self._lock:
            state = self.__dict__.copy()
            del state["_lock"]
            state["native"] = _copy.copy(self.native)
            for name in self._BUFFERS:
                if name in state:
                    state[name] = state[name].copy()
            if state.get("_np_random") is not None:
                state["_np_random"] = _copy.deepcopy(state["_np_random"])
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def __copy__(self) -> Any:
        # A shallow copy would step the same native environments as the original: a copy of
        # an environment is an independent environment.
        return _copy.deepcopy(self)


class PendulumEnv(_Shareable, gymnasium.Env[np.ndarray, np.ndarray]):
    r"""One rotary inverted pendulum as a ``gymnasium.Env`` (``docs/gym.md``).

    Observation (float32, shape (6,)): ``[cos theta, sin theta, cos alpha, sin alpha,
    rate_theta, rate_alpha]`` of the *measured* angles (encoder counts, noise), the rates a
    filtered difference as the rig's LQR estimates them; alpha = 0 is upright. Action (float32,
    shape (1,)) in [-1, 1]: the motor voltage as a fraction of ``u_limit``. Reward per step
    :math:`1 - (0.8|\alpha| + 0.2|\theta|)/\pi - c_u a^2` on the true state.

    Parameters
    ----------
    task : {"balance", "swing_up"}
    config : path, Spec or None
        An experiment file (any ``[plant]`` and ``[sensor]``, e.g. an identified rig; its
        ``[mpc] input_bounds`` give the voltage bound, ``[lqr] rate_cutoff`` the rate filter,
        ``[swing_up] arm_limit`` the arm's travel) or a :class:`riprs.Spec`; the paper's
        defaults without one.
    render_mode : None
        No rendering.
    **settings
        Overrides: ``params`` (FurutaParams), ``Ts`` (s), ``substeps``, ``u_limit`` (V),
        ``encoder_counts`` (None for exact angles), ``noise_std``, ``encoder_offsets`` (rad),
        ``rate_cutoff`` (Hz), ``max_episode_steps``, ``fall_limit``, ``arm_limit`` (rad),
        ``action_delay``, ``observation_latency`` (periods, at most 16), ``init_spread``,
        ``action_cost``, ``randomize`` (True for :data:`DEFAULT_RANDOMIZATION`, or a dict of
        ``relative``, ``covariance``, ``Vd``, ``Cr``, ``Cp``, ``action_delay``,
        ``noise_std``).

    Notes
    -----
    Thread safety: ``reset`` and ``step`` may be called from several threads; each call runs
    whole, one after the other, in the order the threads take the environment's lock, so no
    step is lost or torn. The steps of one episode then interleave between the threads, which
    is rarely what training wants: give each thread its own environment (``copy.deepcopy``).

    ``pickle``, ``copy.deepcopy`` and ``copy.copy`` give an independent environment that
    continues exactly as the original would: the same observations for the same actions.

    Stepping after an episode terminated goes on simulating, with a warning on the first such
    step, as Gymnasium's own environments do; call ``reset`` instead.
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        task: str = "balance",
        *,
        config: ConfigLike = None,
        render_mode: str | None = None,
        **settings: Any,
    ) -> None:
        if render_mode is not None:
            raise InvalidParameterError(
                f"invalid render_mode: none is supported, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.task = task
        self.native = _native(1, task, config, settings)
        self.observation_space, self.action_space = _spaces()
        self.metadata = {"render_modes": [], "render_fps": round(1.0 / self.native.Ts)}
        self._obs = np.zeros((1, OBS_DIM), dtype=np.float32)
        self._reward = np.zeros(1)
        self._terminated = np.zeros(1, dtype=bool)
        self._truncated = np.zeros(1, dtype=bool)
        self._action = np.zeros(1, dtype=np.float32)
        self._started = False
        self._lock = threading.Lock()
        #: Steps taken since one returned ``terminated``; None before (Gymnasium's CartPole).
        self.steps_beyond_terminated: int | None = None

    @property
    def Ts(self) -> float:
        """Control period (s)."""
        return float(self.native.Ts)

    @property
    def u_limit(self) -> float:
        """Voltage of the action 1 (V)."""
        return float(self.native.u_limit)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``seed`` restarts the environment's generator (module docs).

        Parameters
        ----------
        seed : int, optional
            In ``[0, 2**64)``.
        options : dict, optional
            None are read; any key is an error.
        """
        checked = None if seed is None else _check_seed(seed, "seed")
        _check_options(options, ())
        with self._lock:
            super().reset(seed=checked)
            if checked is not None:
                seeds: list[int] | None = [checked]
            elif not self._started:
                seeds = [int(self.np_random.integers(_SEED_LIMIT))]
            else:
                seeds = None
            self.native.reset(self._obs, seeds)
            self._started = True
            self.steps_beyond_terminated = None
            return self._obs[0].copy(), {}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply ``action`` (shape (1,), real, in [-1, 1]) for one control period."""
        a = _real_array(action, "action")
        if a.size != 1:
            raise InvalidParameterError(f"invalid action: expected shape (1,), got {a.shape}")
        with self._lock:
            if not self._started:
                raise gymnasium.error.ResetNeeded("call reset() before step()")
            self._action[0] = a.reshape(())
            self.native.step(
                self._action, False, self._obs, self._reward, self._terminated, self._truncated
            )
            terminated = bool(self._terminated[0])
            if self.steps_beyond_terminated is not None:
                if self.steps_beyond_terminated == 0:
                    gymnasium.logger.warn(
                        "You are calling 'step()' even though this environment has already "
                        "returned terminated = True. You should always call 'reset()' once you "
                        "receive 'terminated = True' -- any further steps are undefined "
                        "behavior."
                    )
                self.steps_beyond_terminated += 1
            elif terminated:
                self.steps_beyond_terminated = 0
            return (
                self._obs[0].copy(),
                float(self._reward[0]),
                terminated,
                bool(self._truncated[0]),
                {},
            )

    @property
    def state(self) -> np.ndarray:
        """The true state ``[theta, theta_dot, alpha, alpha_dot]``."""
        return self.native.state(0)

    @property
    def episode_params(self) -> FurutaParams:
        """The plant parameters drawn for this episode."""
        return self.native.episode_params(0)


class PendulumVecEnv(_Shareable, VectorEnv):
    """``num_envs`` pendulums stepped in one native call (``gymnasium.vector.VectorEnv``).

    Autoreset in Gymnasium's next-step mode: the step after an episode ends resets that
    environment, ignores its action and returns its first observation with reward 0.
    ``reset(seed=s)`` seeds environment ``i`` with ``s + i`` (as ``SyncVectorEnv`` does; a seed
    for which ``s + num_envs - 1`` would not fit 64 bits is refused rather than wrapped), a list
    seeds each; environment ``i`` then produces exactly what a :class:`PendulumEnv` reset with
    the same seed and given the same actions does. ``options={"reset_mask": mask}`` resets only
    where ``mask`` is true.

    Threads, copies and pickles as :class:`PendulumEnv`. With ``copy=False`` the returned
    arrays are the environment's own buffers, which the next ``step`` or ``reset`` from any
    thread overwrites.

    Parameters
    ----------
    num_envs : int
    task, config, **settings
        As :class:`PendulumEnv`.
    copy : bool
        Return new arrays each call (default). With False, ``step`` and ``reset`` return the
        environment's own buffers, overwritten by the next call: no copy at all.
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012

    def __init__(
        self,
        num_envs: int = 1,
        task: str = "balance",
        *,
        config: ConfigLike = None,
        copy: bool = True,
        render_mode: str | None = None,
        **settings: Any,
    ) -> None:
        if render_mode is not None:
            raise InvalidParameterError(
                f"invalid render_mode: none is supported, got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.task = task
        self.native = _native(num_envs, task, config, settings)
        self.num_envs = int(num_envs)
        self.copy = bool(copy)
        self.single_observation_space, self.single_action_space = _spaces()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = {
            "autoreset_mode": AutoresetMode.NEXT_STEP,
            "render_modes": [],
            "render_fps": round(1.0 / self.native.Ts),
        }
        n = self.num_envs
        self._obs = np.zeros((n, OBS_DIM), dtype=np.float32)
        self._reward = np.zeros(n)
        self._terminated = np.zeros(n, dtype=bool)
        self._truncated = np.zeros(n, dtype=bool)
        self._started = False
        self._lock = threading.Lock()

    def _out(self, a: np.ndarray) -> np.ndarray:
        return a.copy() if self.copy else a

    def reset(
        self,
        *,
        seed: int | Sequence[int] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every environment (or those of ``options["reset_mask"]``).

        Parameters
        ----------
        seed : int or sequence of int, optional
            ``s`` seeds environment ``i`` with ``s + i`` (every one in ``[0, 2**64)``); a
            sequence gives each its own.
        options : dict, optional
            ``reset_mask`` (bool, shape (num_envs,)) only; any other key is an error.
        """
        n = self.num_envs
        options = _check_options(options, ("reset_mask",))
        seeds: int | list[int] | None
        if seed is None:
            if self._started:
                seeds = None
            else:
                rng = np.random.default_rng()
                seeds = [int(s) for s in rng.integers(_SEED_LIMIT, size=n)]
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            # The native side derives s + i, refusing a seed that would not fit 64 bits.
            seeds = _check_seed(seed, "seed")
        elif isinstance(seed, (str, bytes)) or not isinstance(seed, (Sequence, np.ndarray)):
            raise TypeError(f"seed must be an int or a sequence of ints, got {type(seed)}")
        else:
            seeds = [_check_seed(s, f"seed[{i}]") for i, s in enumerate(seed)]
            if len(seeds) != n:
                raise InvalidParameterError(
                    f"invalid seed: expected {n} seeds, one per environment, got {len(seeds)}"
                )
        mask = None
        if "reset_mask" in options:
            mask = np.ascontiguousarray(options["reset_mask"], dtype=bool)
            if mask.shape != (n,):
                raise InvalidParameterError(
                    f"invalid reset_mask: expected shape ({n},), got {mask.shape}"
                )
        if not self._started and mask is not None and not mask.all():
            raise InvalidParameterError(
                "invalid reset_mask: the first reset must reset every environment"
            )
        with self._lock:
            self.native.reset(self._obs, seeds, mask)
            self._started = True
            if mask is not None:
                self._terminated[mask] = False
                self._truncated[mask] = False
            return self._out(self._obs), {}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every environment with its action (shape (num_envs, 1) or (num_envs,))."""
        a = _real_array(actions, "actions")
        if a.size != self.num_envs:
            raise InvalidParameterError(
                f"invalid actions: expected shape ({self.num_envs}, 1), got {a.shape}"
            )
        with self._lock:
            if not self._started:
                raise gymnasium.error.ResetNeeded("call reset() before step()")
            self.native.step(
                a.reshape(self.num_envs),
                True,
                self._obs,
                self._reward,
                self._terminated,
                self._truncated,
            )
            return (
                self._out(self._obs),
                self._out(self._reward),
                self._out(self._terminated),
                self._out(self._truncated),
                {},
            )

    def state(self, i: int) -> np.ndarray:
        """The true state of environment ``i``."""
        return self.native.state(i)

    def episode_params(self, i: int) -> FurutaParams:
        """The plant parameters drawn for environment ``i``'s episode."""
        return self.native.episode_params(i)


@dataclass(frozen=True)
class ReplayFit:
    """A log's voltages replayed through an environment's plant.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Sample times (s) on the log's regular grid.
    y : ndarray, shape (n, 2)
        Logged angles ``[theta, alpha]`` (alpha made continuous).
    y_sim : ndarray, shape (n, 2)
        The plant's angles under the same voltages from the logged start.
    nrmse : tuple of float
        ``||y - y_sim|| / ||y - mean(y)||`` per output: 0 a perfect fit, 1 no better than the
        mean (MATLAB's NRMSE; ``riprs identify``'s fit % is ``100 (1 - NRMSE)``).
    """

    t: np.ndarray
    y: np.ndarray
    y_sim: np.ndarray
    nrmse: tuple[float, float]


def replay(
    log: RtLog | str | os.PathLike[str],
    config: ConfigLike = None,
    *,
    params: FurutaParams | None = None,
    substeps: int | None = None,
) -> ReplayFit:
    """Replay a ``rip-rt`` log's voltages through the environment's plant; report the fit.

    Run it before training: a policy can only transfer to a rig its environment predicts. An
    NRMSE near 0 on both angles means the plant (parameters, friction, dead zone) matches the
    rig over the logged motion; a large one says to identify the rig first (``riprs
    identify``) and train on the identified ``[plant]``.

    Parameters
    ----------
    log : RtLog or path
        A ``rip-rt run`` or ``rip-rt excite`` log (``riprs.load_log``).
    config : path, Spec or None
        The environment's experiment file (its ``[plant]``, ``substeps``).
    params : FurutaParams, optional
        Overrides the file's plant.
    substeps : int, optional
        RK4 steps per period (the file's by default).

    Returns
    -------
    ReplayFit
    """
    from riprs.identify import _arrays

    rtlog = log if isinstance(log, RtLog) else load_log(log)
    ts, u, y = _arrays(rtlog)
    spec, _ = _spec_of(config)
    plant = Plant(params if params is not None else spec.params)
    steps = spec.plant.substeps if substeps is None else substeps
    y_sim, nrmse = _riprs.env_replay(plant, y, u, ts, steps)
    t = rtlog.t[0] + ts * np.arange(len(u))
    return ReplayFit(t=t, y=y, y_sim=y_sim, nrmse=(float(nrmse[0]), float(nrmse[1])))


def policy_controller(
    policy: Callable[[np.ndarray], Any],
    env: PendulumEnv | PendulumVecEnv | None = None,
    *,
    Ts: float | None = None,
    rate_cutoff: float | None = None,
    u_limit: float | None = None,
) -> Callable[[np.ndarray], float]:
    """A trained policy as a :func:`riprs.simulate` controller (measured angles -> voltage).

    The returned callable turns each measurement into the environment's observation with the
    environment's own observer (rate filter and cos/sin, ``rip-core``), calls ``policy(obs)``
    and scales its action to volts. Its observer keeps state: use one per run.

    Parameters
    ----------
    policy : callable
        Observation (float32, shape (6,)) to an action in [-1, 1], e.g.
        ``lambda o: model.predict(o, deterministic=True)[0]`` for Stable-Baselines3.
    env : PendulumEnv or PendulumVecEnv, optional
        The environment the policy was trained on; gives ``Ts``, ``rate_cutoff``, ``u_limit``.
    Ts, rate_cutoff, u_limit : float, optional
        Without ``env``, or to override it.
    """
    native = env.native if env is not None else None
    ts = Ts if Ts is not None else (native.Ts if native is not None else _riprs.TS)
    cutoff = (
        rate_cutoff
        if rate_cutoff is not None
        else (native.rate_cutoff if native is not None else Spec().lqr.rate_cutoff)
    )
    limit = (
        u_limit
        if u_limit is not None
        else (native.u_limit if native is not None else _riprs.DEFAULT_U_LIMIT)
    )
    observer = _riprs.EnvObserver(ts, cutoff)

    def controller(y: np.ndarray) -> float:
        action = np.asarray(policy(observer.observe(y)), dtype=np.float64).reshape(-1)
        return float(limit * np.clip(action[0], -1.0, 1.0))

    return controller


for _task, _id in TASKS.items():
    if _id not in gymnasium.registry:
        gymnasium.register(
            id=_id,
            entry_point="riprs.envs:PendulumEnv",
            vector_entry_point="riprs.envs:PendulumVecEnv",
            kwargs={"task": _task},
        )

"""Train a Stable-Baselines3 agent (PPO or SAC) to balance on riprs/Balance-v0 under domain
randomisation, evaluate it on 100 randomised episodes, then run it through riprs.simulate
against LQR.

Not run by CI (it needs ``pip install ".[rl]"``, i.e. Stable-Baselines3 and PyTorch, and
minutes of training). ``examples/gym_balance.py`` trains a linear policy on the same
environment in seconds.

Usage: python benches/gym_train_sb3.py [--algo ppo|sac] [--steps 200000] [--envs 16] [--save FILE]
"""

from __future__ import annotations

import argparse
import time
from typing import Any, Sequence

import numpy as np
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.vec_env import VecEnv

import riprs
import riprs.envs as envs


class Sb3VecEnv(VecEnv):
    """Stable-Baselines3's VecEnv interface over riprs's native vector environment.

    SB3 resets an environment in the step that ends its episode and reports the last
    observation as ``terminal_observation``; the native environment resets on the next step
    (Gymnasium's default). The adapter resets the ended environments at once with
    ``reset_mask``, which also clears their pending autoreset.
    """

    def __init__(self, num_envs: int, **settings: Any) -> None:
        self.venv = envs.PendulumVecEnv(num_envs, copy=True, **settings)
        super().__init__(
            num_envs, self.venv.single_observation_space, self.venv.single_action_space
        )
        self._actions: np.ndarray | None = None
        self._next_seed = 0

    def reset(self) -> np.ndarray:
        seeds = [s for s in getattr(self, "_seeds", []) if s is not None]
        seed = seeds[0] if seeds else self._next_seed
        self._next_seed += self.num_envs
        obs, _ = self.venv.reset(seed=seed)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, reward, terminated, truncated, _ = self.venv.step(self._actions)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            for i in np.flatnonzero(done):
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            fresh, _ = self.venv.reset(options={"reset_mask": done})
            obs[done] = fresh[done]
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kw: Any) -> list:
        return [getattr(self.venv, method_name)(*args, **kw)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, int) else list(indices)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--algo", choices=["ppo", "sac"], default="ppo")
    ap.add_argument("--steps", type=int, default=200_000)
    ap.add_argument("--envs", type=int, default=16)
    ap.add_argument("--save", default=None)
    args = ap.parse_args()

    train = Sb3VecEnv(args.envs, randomize=True, max_episode_steps=500)
    algo = {"ppo": PPO, "sac": SAC}[args.algo]
    model = algo("MlpPolicy", train, verbose=0, seed=0, device="cpu")
    start = time.perf_counter()
    model.learn(total_timesteps=args.steps)
    print(f"trained {args.steps:,} env-steps in {time.perf_counter() - start:.0f} s")
    if args.save:
        model.save(args.save)

    def act(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs, deterministic=True)[0]

    evaluation = envs.PendulumVecEnv(100, randomize=True)
    obs, _ = evaluation.reset(seed=10**6)
    fell = np.zeros(100, dtype=bool)
    for _ in range(evaluation.native.max_episode_steps):
        obs, _, term, trunc, _ = evaluation.step(act(obs))
        fell |= term
        if trunc.any():
            break
    print(f"held the pendulum for the full episode in {100 - fell.sum()} of 100 episodes")

    plant = riprs.paper.plant()
    policy = envs.policy_controller(act, evaluation)
    opts = {"x0": [0.0, 0.0, 0.1, 0.0], "encoder_counts": 2048, "noise_std": 1e-3, "seed": 0}
    for name, ctrl in [(args.algo.upper(), policy), ("LQR", riprs.Lqr.paper())]:
        run = riprs.simulate(plant, ctrl, 10.0, **opts)
        print(f"{name}: fell={run.fell} RMSE theta, alpha, u = {np.round(run.rmse, 4)}")


if __name__ == "__main__":
    main()

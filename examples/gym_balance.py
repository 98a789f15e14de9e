"""Train a balance policy on the native vector environment, check it under domain randomisation,
then run it through riprs.simulate against LQR on the same plant.

The policy is linear in the observation's sines and rates, ``a = clip(w . [sin theta,
rate_theta, sin alpha, rate_alpha], -1, 1)``, found by the cross-entropy method: each generation
evaluates a population of weight vectors on a few randomised episodes each, all in one
``PendulumVecEnv`` stepped natively. No deep-learning library is needed; the same environment
trains Stable-Baselines3 agents (``benches/gym_train_sb3.py``).

    python examples/gym_balance.py

With RIPRS_EXAMPLES_SMALL=1 fewer generations run (the test suite's size).
"""

from __future__ import annotations

import argparse
import os
import time

# --8<-- [start:setup]
import gymnasium
import numpy as np

import riprs
import riprs.envs  # registers riprs/Balance-v0 and riprs/SwingUp-v0

# --8<-- [end:setup]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default=None, help="unused: this example writes no files")
args = parser.parse_args()
small = os.environ.get("RIPRS_EXAMPLES_SMALL") == "1"


# --8<-- [start:train]
def features(obs: np.ndarray) -> np.ndarray:
    """[sin theta, rate_theta, sin alpha, rate_alpha] of one observation or a batch."""
    return obs[..., [1, 4, 3, 5]]


population, episodes, horizon = 32, 4, 300
venv = gymnasium.make_vec(
    "riprs/Balance-v0",
    num_envs=population * episodes,
    vectorization_mode="vector_entry_point",
    randomize=True,  # parameters +-10 %, friction, dead zone, delay 0-2 periods, noise
    max_episode_steps=horizon,
)
rng = np.random.default_rng(0)
mean, std = np.zeros(4), np.array([2.0, 1.0, 15.0, 3.0])
start = time.perf_counter()
for generation in range(12 if small else 20):
    w = mean + std * rng.standard_normal((population, 4))
    weights = np.repeat(w, episodes, axis=0)  # env i runs candidate i // episodes
    obs, _ = venv.reset(seed=1000 * generation)
    ret, alive = np.zeros(len(weights)), np.ones(len(weights), dtype=bool)
    for _ in range(horizon):
        a = np.clip(np.sum(weights * features(obs), axis=1, keepdims=True), -1, 1)
        obs, r, term, trunc, _ = venv.step(a.astype(np.float32))
        ret += r * alive
        alive &= ~(term | trunc)  # next-step autoreset: later rewards belong to a new episode
    score = ret.reshape(population, episodes).mean(axis=1)
    elite = w[np.argsort(score)[-6:]]
    mean, std = elite.mean(axis=0), elite.std(axis=0) + 0.05 * np.abs(elite.mean(axis=0))
train_time = time.perf_counter() - start
steps = (generation + 1) * horizon * population * episodes
print(f"trained in {train_time:.1f} s, {steps:,} env-steps; weights {np.round(mean, 3)}")
# --8<-- [end:train]

# --8<-- [start:evaluate]
# 100 full-length episodes (10 s), randomised, from seeds the training never used.
evaluation = riprs.envs.PendulumVecEnv(100, randomize=True)
obs, _ = evaluation.reset(seed=10**6)
fell = np.zeros(100, dtype=bool)
for _ in range(evaluation.native.max_episode_steps):
    a = np.clip(features(obs) @ mean, -1, 1)[:, None]
    obs, _, term, trunc, _ = evaluation.step(a.astype(np.float32))
    fell |= term
    if trunc.any():
        break
held = 100 - int(fell.sum())
print(f"held the pendulum for the full episode in {held} of 100 randomised episodes")
assert held >= 90
# --8<-- [end:evaluate]

# --8<-- [start:simulate]
plant = riprs.paper.plant()
env = riprs.envs.PendulumEnv()
policy = riprs.envs.policy_controller(lambda o: features(o) @ mean, env)
opts = {"x0": [0.0, 0.0, 0.1, 0.0], "encoder_counts": 2048, "noise_std": 1e-3, "seed": 0}
learned = riprs.simulate(plant, policy, 10.0, **opts)
lqr = riprs.simulate(plant, riprs.Lqr.paper(), 10.0, **opts)
for name, run in [("learned", learned), ("LQR", lqr)]:
    rmse = ", ".join(f"{v:.4f}" for v in run.rmse)
    print(f"{name:>8}: fell={run.fell}  RMSE theta, alpha, u = {rmse}")
assert not learned.fell and not lqr.fell
# --8<-- [end:simulate]

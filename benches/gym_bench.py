"""Environment steps per second: riprs's native vector environment against two Python baselines.

- native: ``riprs.envs.PendulumVecEnv`` (``gymnasium.make_vec(..., "vector_entry_point")``) at
  N = 1, 64, 1024, buffers reused (``copy=False``);
- (a) a single-pendulum ``gymnasium.Env`` written the way gym-brt's QUBE simulator is: Python
  floats and ``math``, one pendulum per object, the equations of motion integrated in a Python
  loop;
- (b) the same model vectorised with numpy over N pendulums (one array operation per term).

All three integrate the same equations (``riprs.Plant``: the paper preset, no Coulomb friction or
dead zone) with classical RK4, 10 substeps per 10 ms period, quantise both angles to 2048 counts,
add 1 mrad noise, run the 20 Hz filtered-difference rate estimate and compute the same reward and
termination. The baselines are checked against riprs (same trajectory without noise) before they
are timed. Prints the median over ``--repeats`` runs of each, in one run, and the ratios.

Usage: python benches/gym_bench.py [--repeats 5] [--steps 200]
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

import riprs
import riprs.envs  # registers riprs/Balance-v0

TS, SUBSTEPS, U_LIMIT, COUNTS, NOISE, CUTOFF = 0.01, 10, 12.0, 2048, 1e-3, 20.0
FALL, ARM, MAX_STEPS, ACTION_COST = math.pi / 2, 1.5, 1000, 0.01


def _coefficients(p: riprs.FurutaParams) -> tuple[float, ...]:
    j0 = p.Jr + p.mr * p.Lr**2 / 4 + p.mp * p.Lr**2
    ja = p.Jp + p.mp * p.Lp**2 / 4
    m12 = p.mp * p.Lr * p.Lp / 2
    grav = p.mp * p.g * p.Lp / 2
    return j0, ja, m12, grav, p.kt / p.Rm, p.Dr + p.kt * p.km / p.Rm, p.Dp


class GymBrtStyleEnv(gymnasium.Env[np.ndarray, np.ndarray]):
    """(a) One pendulum in Python floats, as gym-brt's ``QubeSimulator`` + ``QubeBaseEnv``."""

    def __init__(self, params: riprs.FurutaParams) -> None:
        self.c = _coefficients(params)
        high = np.array([1, 1, 1, 1, np.inf, np.inf], dtype=np.float32)
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)
        self.a = math.exp(-2 * math.pi * CUTOFF * TS)
        self.q = 2 * math.pi / COUNTS

    def _f(self, th: float, thd: float, al: float, ald: float, u: float) -> tuple[float, ...]:
        j0, ja, m12, grav, b, c_arm, dp = self.c
        s, c = math.sin(al), math.cos(al)
        m11, m21 = j0 + ja * s * s, -m12 * c
        f1 = b * u - c_arm * thd - 2 * ja * s * c * thd * ald - m12 * s * ald * ald
        f2 = -dp * ald + ja * s * c * thd * thd + grav * s
        det = m11 * ja - m21 * m21
        return thd, (ja * f1 - m21 * f2) / det, ald, (m11 * f2 - m21 * f1) / det

    def _measure(self) -> tuple[float, float]:
        q = self.q
        th = q * round(self.x[0] / q) + NOISE * self.rng.standard_normal()
        al = q * round(self.x[2] / q) + NOISE * self.rng.standard_normal()
        return th, al

    def _obs(self, y: tuple[float, float]) -> np.ndarray:
        if self.prev is not None:
            for i in range(2):
                d = (y[i] - self.prev[i]) / TS
                self.rates[i] = self.a * self.rates[i] + (1 - self.a) * d
        self.prev = y
        return np.array(
            [math.cos(y[0]), math.sin(y[0]), math.cos(y[1]), math.sin(y[1]), *self.rates],
            dtype=np.float32,
        )

    def reset(self, *, seed: int | None = None, options: Any = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.rng = np.random.default_rng(seed)
        self.x = [float(v) for v in self.rng.uniform(-0.05, 0.05, 4)]
        self.prev: tuple[float, float] | None = None
        self.rates = [0.0, 0.0]
        self.steps = 0
        return self._obs(self._measure()), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        a = min(max(float(action[0]), -1.0), 1.0)
        u = a * U_LIMIT
        h = TS / SUBSTEPS
        th, thd, al, ald = self.x
        for _ in range(SUBSTEPS):
            k1 = self._f(th, thd, al, ald, u)
            k2 = self._f(*(v + 0.5 * h * k for v, k in zip((th, thd, al, ald), k1, strict=True)), u)
            k3 = self._f(*(v + 0.5 * h * k for v, k in zip((th, thd, al, ald), k2, strict=True)), u)
            k4 = self._f(*(v + h * k for v, k in zip((th, thd, al, ald), k3, strict=True)), u)
            th, thd, al, ald = (
                v + h / 6 * (p + 2 * q + 2 * r + s)
                for v, p, q, r, s in zip((th, thd, al, ald), k1, k2, k3, k4, strict=True)
            )
        self.x = [th, thd, al, ald]
        self.steps += 1
        obs = self._obs(self._measure())
        alpha = math.remainder(al, 2 * math.pi)
        reward = (
            1 - (0.8 * abs(alpha) + 0.2 * min(abs(th), math.pi)) / math.pi - ACTION_COST * a * a
        )
        terminated = abs(alpha) > FALL or abs(th) > ARM
        truncated = not terminated and self.steps >= MAX_STEPS
        return obs, reward, terminated, truncated, {}


class NumpyVecEnv:
    """(b) N pendulums, one numpy operation per term of the same model."""

    def __init__(self, params: riprs.FurutaParams, n: int, seed: int = 0) -> None:
        self.c = _coefficients(params)
        self.n = n
        self.rng = np.random.default_rng(seed)
        self.a = math.exp(-2 * math.pi * CUTOFF * TS)
        self.q = 2 * math.pi / COUNTS
        self.x = self.rng.uniform(-0.05, 0.05, (4, n))
        self.prev = self._measure()
        self.rates = np.zeros((2, n))
        self.steps = np.zeros(n, dtype=np.int64)

    def _f(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        j0, ja, m12, grav, b, c_arm, dp = self.c
        thd, al, ald = x[1], x[2], x[3]
        s, c = np.sin(al), np.cos(al)
        m11, m21 = j0 + ja * s * s, -m12 * c
        f1 = b * u - c_arm * thd - 2 * ja * s * c * thd * ald - m12 * s * ald * ald
        f2 = -dp * ald + ja * s * c * thd * thd + grav * s
        det = m11 * ja - m21 * m21
        return np.stack([thd, (ja * f1 - m21 * f2) / det, ald, (m11 * f2 - m21 * f1) / det])

    def _measure(self) -> np.ndarray:
        y = self.q * np.round(self.x[[0, 2]] / self.q)
        return y + NOISE * self.rng.standard_normal((2, self.n))

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, ...]:
        a = np.clip(actions, -1.0, 1.0)
        u = a * U_LIMIT
        h = TS / SUBSTEPS
        x = self.x
        for _ in range(SUBSTEPS):
            k1 = self._f(x, u)
            k2 = self._f(x + 0.5 * h * k1, u)
            k3 = self._f(x + 0.5 * h * k2, u)
            k4 = self._f(x + h * k3, u)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self.x = x
        self.steps += 1
        y = self._measure()
        self.rates = self.a * self.rates + (1 - self.a) * (y - self.prev) / TS
        self.prev = y
        obs = np.concatenate([np.cos(y), np.sin(y), self.rates]).T.astype(np.float32)
        alpha = np.remainder(x[2] + np.pi, 2 * np.pi) - np.pi
        reward = (
            1
            - (0.8 * np.abs(alpha) + 0.2 * np.minimum(np.abs(x[0]), np.pi)) / np.pi
            - ACTION_COST * a * a
        )
        terminated = (np.abs(alpha) > FALL) | (np.abs(x[0]) > ARM)
        truncated = ~terminated & (self.steps >= MAX_STEPS)
        done = terminated | truncated
        if done.any():  # autoreset in place
            self.x[:, done] = self.rng.uniform(-0.05, 0.05, (4, int(done.sum())))
            self.steps[done] = 0
            self.rates[:, done] = 0.0
        return obs, reward, terminated, truncated


def _check_baselines(params: riprs.FurutaParams) -> float:
    """Largest state difference from riprs's plant over 30 steps (0.3 s) near upright, before
    the pendulum falls (and the numpy baseline resets it)."""
    plant = riprs.Plant(params)
    u = 12.0 * 0.3 * np.sin(np.arange(30) * 0.3)
    x0 = [0.01, 0.0, 0.02, 0.0]
    ref = plant.integrate(x0, u, TS, SUBSTEPS)
    env = GymBrtStyleEnv(params)
    env.reset(seed=0)
    env.x = list(x0)
    vec = NumpyVecEnv(params, 1)
    vec.x = np.array(x0).reshape(4, 1)
    worst = 0.0
    for k in range(30):
        env.step(np.array([u[k] / 12.0]))
        vec.step(np.array([u[k] / 12.0]))
        worst = max(worst, np.max(np.abs(np.array(env.x) - ref[k + 1])))
        worst = max(worst, np.max(np.abs(vec.x[:, 0] - ref[k + 1])))
    return worst


def _time(fn: Any, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--steps", type=int, default=200)
    args = ap.parse_args()
    params = riprs.FurutaParams.paper()
    print(f"baselines vs riprs.Plant: max state difference {_check_baselines(params):.2e}")
    steps = args.steps
    rng = np.random.default_rng(0)

    single = GymBrtStyleEnv(params)
    single.reset(seed=0)
    acts = rng.uniform(-0.2, 0.2, (steps, 1)).astype(np.float32)

    def run_single() -> None:
        for a in acts:
            _, _, te, tr, _ = single.step(a)
            if te or tr:
                single.reset()

    rate_a = steps / _time(run_single, args.repeats)
    print(f"(a) gym-brt-style Python env: {rate_a:12,.0f} env-steps/s (one pendulum)")
    print(f"{'N':>6} {'native':>14} {'numpy (b)':>14} {'native/(a)':>11} {'native/(b)':>11}")
    for n in (1, 64, 1024):
        native = gymnasium.make_vec(
            "riprs/Balance-v0", num_envs=n, vectorization_mode="vector_entry_point", copy=False
        )
        native.reset(seed=0)
        actions = rng.uniform(-0.2, 0.2, (steps, n, 1)).astype(np.float32)

        def run_native(native: Any = native, actions: np.ndarray = actions) -> None:
            for a in actions:
                native.step(a)

        vec = NumpyVecEnv(params, n)
        flat = actions[..., 0].astype(np.float64)

        def run_numpy(vec: NumpyVecEnv = vec, flat: np.ndarray = flat) -> None:
            for a in flat:
                vec.step(a)

        rate_n = n * steps / _time(run_native, args.repeats)
        rate_b = n * steps / _time(run_numpy, args.repeats)
        ratios = f"{rate_n / rate_a:>10.0f}x {rate_n / rate_b:>10.1f}x"
        print(f"{n:>6} {rate_n:>14,.0f} {rate_b:>14,.0f} {ratios}")


if __name__ == "__main__":
    main()

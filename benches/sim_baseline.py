"""A 10 s closed-loop LQR run of the paper's plant: riprs.simulate against the same loop written
in numpy (RK4, 10 substeps per 10 ms period) and against scipy's solve_ivp between samples.

Prints the median wall time of each, the ratios, and the largest state difference between the
implementations (noise-free, so the runs must agree).

Usage: python benches/sim_baseline.py [--repeats N]
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Callable

import numpy as np
from scipy.integrate import solve_ivp

import riprs

TS, SUBSTEPS, DURATION = 0.01, 10, 10.0
X0 = np.array([0.0, 0.0, 0.1, 0.0])


def equations(p: riprs.FurutaParams) -> Callable[[np.ndarray, float], np.ndarray]:
    """The plant's equations of motion (see riprs.Plant) in plain numpy."""
    j0 = p.Jr + p.mr * p.Lr**2 / 4 + p.mp * p.Lr**2
    ja = p.Jp + p.mp * p.Lp**2 / 4
    m12 = p.mp * p.Lr * p.Lp / 2
    grav = p.mp * p.g * p.Lp / 2
    b, c_arm = p.kt / p.Rm, p.Dr + p.kt * p.km / p.Rm

    def f(x: np.ndarray, u: float) -> np.ndarray:
        _, thd, a, ad = x
        s, c = np.sin(a), np.cos(a)
        m11, m21 = j0 + ja * s * s, -m12 * c
        f1 = b * u - c_arm * thd - 2 * ja * s * c * thd * ad - m12 * s * ad * ad
        f2 = -p.Dp * ad + ja * s * c * thd * thd + grav * s
        det = m11 * ja - m21 * m21
        return np.array([thd, (ja * f1 - m21 * f2) / det, ad, (m11 * f2 - m21 * f1) / det])

    return f


class NumpyLqr:
    """The paper's LQR with the filtered-difference rates, as riprs.Lqr."""

    def __init__(self, K: np.ndarray, cutoff: float) -> None:
        self.K = K[0]
        self.a = np.exp(-2 * np.pi * cutoff * TS)
        self.prev: np.ndarray | None = None
        self.rate = np.zeros(2)

    def step(self, y: np.ndarray, r: np.ndarray) -> float:
        if self.prev is not None:
            self.rate = self.a * self.rate + (1 - self.a) * (y - self.prev) / TS
        self.prev = y
        x = np.array([y[0] - r[0], self.rate[0], y[1] - r[1], self.rate[1]])
        return float(np.clip(-self.K @ x, -12.0, 12.0))


def reference(k: int) -> np.ndarray:
    return np.array([1.0 if k * TS >= 1.0 else 0.0, 0.0])


def run_numpy_rk4(f, lqr: riprs.Lqr) -> np.ndarray:
    ctrl = NumpyLqr(lqr.K, lqr.rate_cutoff)
    h = TS / SUBSTEPS
    x = X0.copy()
    out = np.empty((round(DURATION / TS), 4))
    for k in range(out.shape[0]):
        out[k] = x
        u = ctrl.step(x[[0, 2]], reference(k))
        for _ in range(SUBSTEPS):
            k1 = f(x, u)
            k2 = f(x + 0.5 * h * k1, u)
            k3 = f(x + 0.5 * h * k2, u)
            k4 = f(x + h * k3, u)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return out


def run_solve_ivp(f, lqr: riprs.Lqr) -> np.ndarray:
    ctrl = NumpyLqr(lqr.K, lqr.rate_cutoff)
    x = X0.copy()
    out = np.empty((round(DURATION / TS), 4))
    for k in range(out.shape[0]):
        out[k] = x
        u = ctrl.step(x[[0, 2]], reference(k))
        x = solve_ivp(lambda _t, s, u=u: f(s, u), (0, TS), x, rtol=1e-8, atol=1e-10).y[:, -1]
    return out


def run_riprs(plant: riprs.Plant, lqr: riprs.Lqr) -> np.ndarray:
    res = riprs.simulate(
        plant, lqr, DURATION, reference=1.0, reference_time=1.0, x0=X0, substeps=SUBSTEPS
    )
    assert not res.fell
    return res.x


def median_time(fn: Callable[[], np.ndarray], repeats: int) -> tuple[float, np.ndarray]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    assert result is not None
    return statistics.median(times), result


def baseline_rows(repeats: int = 5) -> list[tuple[str, str, float, float]]:
    """``(case, baseline, riprs seconds, baseline seconds)`` rows for ``benches/baselines.py``."""
    plant, lqr = riprs.paper.plant(), riprs.Lqr.paper()
    f = equations(plant.params)
    t_riprs, x_riprs = median_time(lambda: run_riprs(plant, lqr), max(50, repeats))
    t_numpy, x_numpy = median_time(lambda: run_numpy_rk4(f, lqr), repeats)
    t_ivp, x_ivp = median_time(lambda: run_solve_ivp(f, lqr), max(1, repeats // 2))
    # The implementations must agree, or the timing compares different work.
    assert np.max(np.abs(x_riprs - x_numpy)) < 1e-9
    assert np.max(np.abs(x_riprs - x_ivp)) < 1e-6
    case = "10 s closed-loop LQR (1000 steps)"
    return [(case, "numpy RK4 loop", t_riprs, t_numpy), (case, "scipy solve_ivp", t_riprs, t_ivp)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    plant, lqr = riprs.paper.plant(), riprs.Lqr.paper()
    f = equations(plant.params)

    t_riprs, x_riprs = median_time(lambda: run_riprs(plant, lqr), max(50, args.repeats))
    t_numpy, x_numpy = median_time(lambda: run_numpy_rk4(f, lqr), args.repeats)
    t_ivp, x_ivp = median_time(lambda: run_solve_ivp(f, lqr), max(1, args.repeats // 2))

    print(f"10 s closed-loop LQR, Ts = {TS} s, {SUBSTEPS} RK4 substeps (medians)")
    print(f"  riprs.simulate     {t_riprs * 1e3:10.3f} ms")
    print(f"  numpy RK4 loop     {t_numpy * 1e3:10.3f} ms   ratio {t_numpy / t_riprs:8.0f}x")
    print(f"  scipy solve_ivp    {t_ivp * 1e3:10.3f} ms   ratio {t_ivp / t_riprs:8.0f}x")
    print(f"  max |x_riprs - x_numpy|     = {np.max(np.abs(x_riprs - x_numpy)):.2e}")
    print(f"  max |x_riprs - x_solve_ivp| = {np.max(np.abs(x_riprs - x_ivp)):.2e}")


if __name__ == "__main__":
    main()

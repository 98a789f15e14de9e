"""One MPC step on the paper's settings: riprs vs the Python a user would write.

Every variant does the same work per sample: the current-form Kalman update (eqs. (4)-(6)) and
the constrained QP over ``z = [du(k..k+2), eps]`` (P = 50, m = 3, 107 constraint rows).

- ``riprs active_set`` / ``riprs clarabel``: ``Mpc.step(y, r)``.
- ``python clarabel, condensed``: the condensed QP built once in numpy (its state-dependent
  ``q`` and ``b`` as affine maps), the estimator in numpy, and ``clarabel.DefaultSolver`` kept
  alive with ``solver.update(q=..., b=...)`` each step.
- ``cvxpy, parameters``: the MPC written in cvxpy over the prediction (DPP parameters for the
  estimate, previous input and reference), compiled once, solved each step with Clarabel.

Inputs replay a closed loop on the paper's linear model (pendulum released at 0.1 rad, arm
reference 0 -> 1 rad at 1 s), which saturates the input and uses the slack. Each timed call is
one sample; the median over many calls is reported. The baselines' moves are checked against
riprs in a closed loop on the linear model first.

Usage: ``python benches/mpc_baseline.py [--min-time SECONDS]``.
"""

from __future__ import annotations

import argparse
import math
import time
from typing import Any, Callable

import clarabel
import cvxpy as cp
import numpy as np
import scipy.sparse as sp

import riprs

STEPS = 400
P, M = 50, 3
BOUND = math.pi / 6


def make_trace() -> tuple[np.ndarray, np.ndarray]:
    plant = riprs.paper.discrete_model()
    mpc = riprs.paper.mpc("active_set")
    x = np.array([0.0, 0.0, 0.1, 0.0])
    ys, rs = [], []
    for k in range(STEPS):
        y = plant.C @ x
        r = np.array([0.0 if k < 100 else 1.0, 0.0])
        u = mpc.step(y, r)
        ys.append(y)
        rs.append(r)
        x = plant.A @ x + plant.B @ u
    return np.array(ys), np.array(rs)


class Replay:
    """Cycles through the trace, resetting the controller at each wrap."""

    def __init__(self, ys: np.ndarray, rs: np.ndarray, step: Callable[[Any, Any], Any],
                 reset: Callable[[], None]):
        self.ys, self.rs, self.step, self.reset, self.k = ys, rs, step, reset, 0

    def __call__(self) -> Any:
        if self.k == 0:
            self.reset()
        u = self.step(self.ys[self.k], self.rs[self.k])
        self.k = (self.k + 1) % len(self.ys)
        return u


class PythonClarabelMpc:
    """Estimator in numpy + the condensed QP in python clarabel with data updates."""

    def __init__(self) -> None:
        ref = riprs.paper.mpc("active_set")
        self.A, self.B, self.C = ref.model
        self.L, self.M = ref.L, ref.M
        nx = self.A.shape[0]
        # The QP's data is affine in (x, u_prev, r): read the maps off at basis points once.
        H, f0, Ac, b0 = ref.qp_matrices(np.zeros(nx), [0.0], [0.0, 0.0])
        basis = np.eye(nx + 3)
        F, G = [], []
        for e in basis:
            _, f, _, b = ref.qp_matrices(e[:nx], e[nx:nx + 1], e[nx + 1:])
            F.append(f - f0)
            G.append(b - b0)
        self.F, self.G = np.array(F).T, np.array(G).T
        self.f0, self.b0 = f0, b0
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        settings.presolve_enable = False
        settings.tol_gap_abs = settings.tol_gap_rel = 1e-10
        self.solver = clarabel.DefaultSolver(
            sp.csc_matrix(np.triu(H)), f0, sp.csc_matrix(Ac), b0,
            [clarabel.NonnegativeConeT(Ac.shape[0])], settings,
        )
        self.reset()

    def reset(self) -> None:
        self.prior = np.zeros(self.A.shape[0])
        self.u_prev = np.zeros(1)

    def step(self, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        e = y - self.C @ self.prior
        post = self.prior + self.M @ e
        p = np.concatenate([post, self.u_prev, r])
        self.solver.update(q=self.f0 + self.F @ p, b=self.b0 + self.G @ p)
        sol = self.solver.solve()
        u = np.clip(self.u_prev + np.asarray(sol.x[:1]), -12.0, 12.0)
        self.prior = self.A @ self.prior + self.B @ u + self.L @ e
        self.u_prev = u
        return u


class CvxpyMpc:
    """Estimator in numpy + the MPC written in cvxpy with parameters (compiled once)."""

    def __init__(self) -> None:
        ref = riprs.paper.mpc("active_set")
        self.A, self.B, self.C = ref.model
        self.L, self.M = ref.L, ref.M
        nx = self.A.shape[0]
        self.x = cp.Parameter(nx)
        self.up = cp.Parameter(1)
        self.r = cp.Parameter(2)
        du = cp.Variable(M)
        eps = cp.Variable()
        # Prediction matrices (the user condenses the dynamics so the problem stays small).
        Phi = np.vstack([self.C @ np.linalg.matrix_power(self.A, i) for i in range(1, P + 1)])
        S = [np.zeros((nx, 1))]
        for i in range(1, P + 1):
            S.append(S[-1] + np.linalg.matrix_power(self.A, i - 1) @ self.B)
        Gam = np.vstack([self.C @ S[i] for i in range(1, P + 1)])
        Gdu = np.zeros((2 * P, M))
        for i in range(1, P + 1):
            for j in range(min(i, M)):
                Gdu[2 * (i - 1):2 * i, j] = (self.C @ S[i - j])[:, 0]
        y = Phi @ self.x + Gam @ self.up + Gdu @ du
        u = self.up + cp.cumsum(du)
        wy = np.tile([25.0, 50.0], P)
        cost = (cp.sum_squares(cp.multiply(wy, cp.hstack([self.r] * P) - y))
                + cp.sum_squares(du / 10.0) + 100 * cp.square(eps))
        alpha = y[1::2]
        cons = [u <= 12, u >= -12, alpha <= BOUND + eps, alpha >= -BOUND - eps, eps >= 0]
        self.du = du
        self.prob = cp.Problem(cp.Minimize(cost), cons)
        assert self.prob.is_dpp()
        self.reset()
        self.x.value, self.up.value, self.r.value = np.zeros(nx), np.zeros(1), np.zeros(2)
        self.prob.solve(solver=cp.CLARABEL)

    def reset(self) -> None:
        self.prior = np.zeros(self.A.shape[0])
        self.u_prev = np.zeros(1)

    def step(self, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        e = y - self.C @ self.prior
        self.x.value = self.prior + self.M @ e
        self.up.value = self.u_prev
        self.r.value = r
        self.prob.solve(solver=cp.CLARABEL, tol_gap_abs=1e-10, tol_gap_rel=1e-10)
        u = np.clip(self.u_prev + self.du.value[:1], -12.0, 12.0)
        self.prior = self.A @ self.prior + self.B @ u + self.L @ e
        self.u_prev = u
        return u


def median_seconds(fn: Callable[[], Any], min_time: float) -> float:
    """Median wall time of single calls, collected for at least ``min_time`` seconds."""
    fn()
    samples = []
    deadline = time.perf_counter() + min_time
    while time.perf_counter() < deadline or len(samples) < 50:
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return float(np.median(samples))


def _controllers() -> dict[str, Any]:
    ys, rs = make_trace()
    out: dict[str, Any] = {}
    for solver in ("active_set", "clarabel"):
        mpc = riprs.paper.mpc(solver)
        out[f"riprs {solver}"] = Replay(ys, rs, mpc.step, mpc.reset)
    py = PythonClarabelMpc()
    out["python clarabel, condensed"] = Replay(ys, rs, py.step, py.reset)
    cv = CvxpyMpc()
    out["cvxpy, parameters"] = Replay(ys, rs, cv.step, cv.reset)
    return out


def agreement(controllers: dict[str, Any]) -> dict[str, float]:
    """Max |u - u_riprs_active_set| over a closed loop on the linear model, per variant.

    (A replay of recorded outputs is not used here: with the outputs fixed, the estimator and
    controller form an open loop that amplifies solver round-off differences.)"""
    plant = riprs.paper.discrete_model()
    traj = {}
    for name, replay in controllers.items():
        replay.reset()
        x = np.array([0.0, 0.0, 0.1, 0.0])
        us = []
        for k in range(STEPS):
            y = plant.C @ x
            u = replay.step(y, np.array([0.0 if k < 100 else 1.0, 0.0]))
            us.append(float(u[0]))
            x = plant.A @ x + plant.B @ u
        replay.k = 0
        traj[name] = np.array(us)
    base = traj["riprs active_set"]
    return {name: float(np.abs(u - base).max()) for name, u in traj.items()}


def baseline_rows(min_time: float) -> list[tuple[str, str, float, float]]:
    """Rows ``(case, baseline, riprs seconds, baseline seconds)`` for ``baselines.py``."""
    ctl = _controllers()
    times = {name: median_seconds(fn, min_time) for name, fn in ctl.items()}
    rows = []
    for ours in ("riprs active_set", "riprs clarabel"):
        for theirs in ("python clarabel, condensed", "cvxpy, parameters"):
            label = f"MPC step (paper, P=50 m=3), {ours.split()[1]}"
            rows.append((label, theirs, times[ours], times[theirs]))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-time", type=float, default=2.0, help="seconds per variant")
    args = parser.parse_args()
    ctl = _controllers()
    diff = agreement(ctl)
    times = {name: median_seconds(fn, args.min_time) for name, fn in ctl.items()}
    print(f"MPC step on the paper's settings, median of single calls over {STEPS}-sample replay")
    print(f"{'variant':<30}{'median':>12}{'vs active_set':>15}{'vs clarabel':>13}"
          f"{'max |u - u_active_set|':>25}")
    for name, t in times.items():
        print(f"{name:<30}{t * 1e6:>10.1f}us{t / times['riprs active_set']:>14.1f}x"
              f"{t / times['riprs clarabel']:>12.2f}x{diff[name]:>25.1e}")


if __name__ == "__main__":
    main()

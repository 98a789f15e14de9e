"""Designing controllers: DARE, LQR, Kalman filter, LQG and MPC from Python, each checked
against an independent computation (scipy, python-control), then run on the nonlinear plant.

    python examples/design_controllers.py --out design-out

With RIPRS_EXAMPLES_SMALL=1 the closed-loop runs last 2 s (the test suite's size).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

# --8<-- [start:imports]
import control
import numpy as np
import scipy.linalg

import riprs
from riprs import paper

# --8<-- [end:imports]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="riprs-design", help="output directory for the figure")
args = parser.parse_args()
small = os.environ.get("RIPRS_EXAMPLES_SMALL") == "1"
duration = 2.0 if small else 10.0
np.set_printoptions(precision=4, suppress=True)

# --8<-- [start:dare]
plant = paper.discrete_model()  # A_d (4x4), B_d (4x1), C (2x4), Ts = 0.01 s
Q, R = paper.lqr_weights()  # eq. (13): diag(25, 0, 50, 0), 0.1

X, poles, G = riprs.dare(plant.A, plant.B, Q, R)
X_scipy = scipy.linalg.solve_discrete_are(plant.A, plant.B, Q, R)
print("DARE: max |X - scipy| / max |X| =", np.abs(X - X_scipy).max() / np.abs(X).max())
assert np.allclose(X, X_scipy, rtol=1e-9, atol=0)
# --8<-- [end:dare]

# --8<-- [start:dlqr]
K, S, E = riprs.dlqr(plant.A, plant.B, Q, R)  # u = -K x
K_ct, S_ct, E_ct = control.dlqr(plant.A, plant.B, Q, R)
print("K =", K, " python-control:", K_ct)
print("closed-loop |eig(A - B K)| max =", np.abs(E).max())
assert np.allclose(K, K_ct, rtol=1e-8) and np.allclose(G, K) and np.allclose(S, X)
# --8<-- [end:dlqr]

# --8<-- [start:kalman]
aug = paper.augmented_model()  # eq. (3): plant + output-disturbance state
Qn, Rn, Nn = paper.noise_model()  # eqs. (8)-(10): B B^T, D D^T, B D^T
kf = riprs.kalman(aug.A, np.eye(5), aug.C, Qn, Rn, Nn)
print("predictor gain L (eq. (4)):\n", kf.L)
print("innovation gain M (eq. (5)):\n", kf.M)

# The same gains from scipy's DARE and MATLAB's formulas (filter DARE = dual of the control one).
P = scipy.linalg.solve_discrete_are(aug.A.T, aug.C.T, Qn, Rn, s=Nn)
S_y = aug.C @ P @ aug.C.T + Rn
assert np.allclose(kf.L, (aug.A @ P @ aug.C.T + Nn) @ np.linalg.inv(S_y), atol=1e-9)
assert np.allclose(kf.M, P @ aug.C.T @ np.linalg.inv(S_y), atol=1e-9)
# python-control's dlqe returns the predictor gain only, and so does riprs.dlqe.
L_ct, _, _ = control.dlqe(aug.A, np.eye(5), aug.C, Qn, Rn)
assert np.allclose(kf.L, L_ct, atol=1e-8)
assert np.array_equal(np.round(kf.L, 4), paper.PRINTED["L"])  # eq. (12), every digit
# --8<-- [end:kalman]

# --8<-- [start:c2d]
cont = paper.continuous_model()  # dx/dt = A x + B u
Ad, Bd = riprs.c2d(cont.A, cont.B, 0.01)  # zero-order hold, MATLAB c2d(sys, Ts, 'zoh')
n, m = cont.B.shape
block = scipy.linalg.expm(np.block([[cont.A, cont.B], [np.zeros((m, n + m))]]) * 0.01)
assert np.allclose(Ad, block[:n, :n], atol=1e-14) and np.allclose(Bd, block[:n, n:], atol=1e-14)
print("c2d agrees with the matrix exponential of [[A, B], [0, 0]] Ts")
# --8<-- [end:c2d]

# --8<-- [start:controllers]
lqr = riprs.Lqr.design(plant.A, plant.B, Q, R, plant.Ts)  # angles measured, rates filtered
lqg = riprs.Lqg(K, aug.A, aug.B[:, :1] / paper.INPUT_SCALE, aug.C, kf.L, kf.M, plant.Ts)
mpc = riprs.Mpc(
    plant.A, plant.B, plant.C, plant.Ts,
    prediction_horizon=50, control_horizon=3,
    output_weights=[25, 50], input_rate_weights=[1], input_weights=[0],
    input_scales=[paper.INPUT_SCALE], output_scales=[1, 1],
    input_bounds=[(-12, 12)], output_bounds=[None, (-np.pi / 6, np.pi / 6)],
    ecr_weight=100,
    output_disturbance=(np.eye(1), 0.01 * np.eye(1), np.ones((2, 1))),
    solver="active_set",
)  # fmt: skip
# The MPC built by hand is the paper's: the same Kalman gains and the same first move.
assert np.allclose(mpc.L, kf.L) and np.allclose(mpc.M, kf.M)
reference_mpc = paper.mpc("active_set")
assert np.allclose(mpc.step([0.0, 0.05], [1.0, 0.0]), reference_mpc.step([0.0, 0.05], [1.0, 0.0]))
mpc.reset()
# --8<-- [end:controllers]

# --8<-- [start:simulate]
nonlinear = paper.plant()  # the Furuta pendulum fitted to A_d, B_d
runs = {}
for name, ctrl in {"LQR": lqr, "LQG": lqg, "MPC": mpc}.items():
    run = riprs.simulate(
        nonlinear, ctrl, duration, reference=1.0, reference_time=1.0,
        encoder_counts=2048, noise_std=1e-3, seed=0,
    )  # fmt: skip
    runs[name] = run
    print(f"{name}: fell={run.fell}, RMSE (arm, pendulum, voltage) = {np.round(run.rmse, 4)}")
# --8<-- [end:simulate]
assert not any(run.fell for run in runs.values())

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 4.5), constrained_layout=True)
for name, run in runs.items():
    ax1.plot(run.t, run.y[:, 1], label=name, lw=1)
    ax2.plot(run.t, run.u, label=name, lw=1)
ax1.set_ylabel("pendulum angle [rad]")
ax2.set_ylabel("voltage [V]")
ax2.set_xlabel("time [s]")
ax1.legend(ncol=3)
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
fig.savefig(out / "controllers.svg")
print("wrote", out / "controllers.svg")

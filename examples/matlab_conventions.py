"""Coming from MATLAB and python-control: each convention of the mapping table, checked.

    python examples/matlab_conventions.py
"""

from __future__ import annotations

import argparse

# --8<-- [start:imports]
import control
import numpy as np

import riprs
from riprs import paper

# --8<-- [end:imports]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", help="unused: this example writes no files")
parser.parse_args()
np.set_printoptions(precision=4, suppress=True)

# --8<-- [start:dare]
# MATLAB's published idare/dare example (Control System Toolbox documentation):
#   [X,K,L] = idare(A,B,Q,R,[],[])   X = [4.7687 0.9438; 0.9438 3.2369],
#                                    K = [-0.2216 -0.1297], L = [-0.4460; -0.0027]
#   [X,L,G] = dare(A,B,Q,R)          the same numbers, gain last
A = np.array([[-0.9, -0.3], [0.7, 0.1]])
B = np.array([[1.0], [1.0]])
Q = np.array([[1.0, 0.0], [0.0, 3.0]])
R = np.array([[0.1]])
X, eigs, G = riprs.dare(A, B, Q, R)  # python-control's and MATLAB dare's order: X, L, G
print("X =\n", X, "\nG =", G, "\nclosed-loop eigenvalues =", np.sort_complex(eigs))
assert np.allclose(X, [[4.7687, 0.9438], [0.9438, 3.2369]], atol=5e-5)
assert np.allclose(G, [[-0.2216, -0.1297]], atol=5e-5)
assert np.allclose(np.sort(eigs.real), [-0.4460, -0.0027], atol=5e-5)
assert np.allclose(eigs.imag, 0)
# --8<-- [end:dare]

# --8<-- [start:dlqr]
# dlqr: [K,S,e] = dlqr(A,B,Q,R,N) in MATLAB and python-control; the law is u = -K x.
plant = paper.discrete_model()
Qw, Rw = paper.lqr_weights()
K, S, E = riprs.dlqr(plant.A, plant.B, Qw, Rw)
K_ct, S_ct, E_ct = control.dlqr(plant.A, plant.B, Qw, Rw)
assert np.allclose(K, K_ct, rtol=1e-8) and np.allclose(S, S_ct, rtol=1e-8)
assert np.allclose(np.sort_complex(E), np.sort_complex(np.linalg.eigvals(plant.A - plant.B @ K)))
assert np.abs(E).max() < 1  # A - B K is the stable closed loop: the sign is u = -K x
# --8<-- [end:dlqr]

# --8<-- [start:kalman]
# kalman: MATLAB's [kest, L, P, M, Z] = kalman(ss(A, [B G], C, [D H], Ts), Qn, Rn, Nn).
# L is the predictor gain (x[k+1|k]), M the innovation gain (x[k|k]); riprs returns both.
aug = paper.augmented_model()
Qn, Rn, Nn = paper.noise_model()
kf = riprs.kalman(aug.A, np.eye(5), aug.C, Qn, Rn, Nn)
# With no cross covariance (N = 0, as in the paper) the two are related by L = A M.
assert np.allclose(kf.L, aug.A @ kf.M, atol=1e-12)

# dlqe: python-control's (and riprs's) returns the predictor gain L ...
L_dlqe, P_dlqe, _ = riprs.dlqe(aug.A, np.eye(5), aug.C, Qn, Rn)
L_ct, P_ct, _ = control.dlqe(aug.A, np.eye(5), aug.C, Qn, Rn)
assert np.allclose(L_dlqe, kf.L) and np.allclose(L_dlqe, L_ct, atol=1e-8)
# ... while MATLAB's obsolete dlqe, [M,P,Z,E] = dlqe(A,G,C,Q,R), returns the innovation gain M.
print("dlqe (predictor) L[:, 1] =", L_dlqe[:, 1], "\nkalman M[:, 1]           =", kf.M[:, 1])
# P is the prior (x[k|k-1]) covariance in all three; Z the posterior one.
assert np.allclose(P_dlqe, kf.P) and np.allclose(P_ct, kf.P, atol=1e-8)
# --8<-- [end:kalman]

# --8<-- [start:c2d]
# c2d: MATLAB c2d(ss(A, B, C, D), Ts, 'zoh') and python-control c2d(sys, Ts, 'zoh').
cont = paper.continuous_model()
Ad, Bd = riprs.c2d(cont.A, cont.B, 0.01)
sys_d = control.c2d(control.ss(cont.A, cont.B, cont.C, cont.D), 0.01, method="zoh")
assert np.allclose(Ad, sys_d.A, atol=1e-12) and np.allclose(Bd, sys_d.B, atol=1e-12)
# --8<-- [end:c2d]

# --8<-- [start:mpc]
# The mpc object: weights multiply inside the square and scale factors divide, as in MATLAB,
# so the cost of the first move is ((w_du / s_u) * du)^2. With the output weights at zero the
# Hessian's input-rate block is 2 (w_du / s_u)^2 I:
m = riprs.Mpc(
    plant.A, plant.B, plant.C, plant.Ts, prediction_horizon=10, control_horizon=3,
    output_weights=[0, 0], input_rate_weights=[1.0], input_scales=[10.0],
)  # fmt: skip
H, f, Aineq, b = m.qp_matrices(np.zeros(4), [0.0])
print("input-rate block of H with w_du = 1, s_u = 10:", np.diag(H)[:3])
assert np.allclose(H[:3, :3], 2 * (1.0 / 10.0) ** 2 * np.eye(3))

# ECR: one slack eps >= 0 for every soft output bound, weighted rho_eps eps^2 (Weights.ECR).
mpc = paper.mpc("active_set")  # rho_eps = 100, soft bound on the pendulum angle
H, f, Aineq, b = mpc.qp_matrices(np.zeros(5), [0.0])
assert H[-1, -1] == 2 * 100.0

# Output disturbance: the paper's eq. (1), one integrator feeding both (scaled) outputs.
A_aug, B_aug, C_aug = mpc.model
print("augmented C (outputs / output scales, then the disturbance column):\n", C_aug)
assert np.allclose(C_aug[:, 4], [1.0, 1.0]) and A_aug[4, 4] == 1.0

# mpcmove: Mpc.step(y, r) is one mpcmove: correct the estimate with y (x[k|k] = x[k|k-1] + M e),
# solve the QP from x[k|k] and u(k-1), apply u(k) = u(k-1) + du(k), predict x[k+1|k].
# Mpc.solve(x, u_prev, r) is the QP alone, for a state you estimated yourself.
y, r = np.array([0.01, 0.002]), np.array([0.0, 0.0])
u_step = mpc.step(y, r)
fresh = paper.mpc("active_set")
x_post = fresh.M @ y  # the estimate starts at x[0|-1] = 0, output scales are 1
u_solve = fresh.solve(x_post, [0.0], r).u
print("step:", u_step, " solve from M y:", u_solve)
assert np.allclose(u_step, u_solve, atol=1e-9) and 0 < abs(u_step[0]) < 12  # not at a bound
# --8<-- [end:mpc]
print("all conventions checked")

"""The paper reproduced: the printed matrices of section 3 against riprs's recovered model, and
the evidence for each correction. Every number printed here is also asserted.

    python examples/paper_model.py
"""

from __future__ import annotations

import argparse

# --8<-- [start:imports]
import numpy as np

import riprs
from riprs import paper

# --8<-- [end:imports]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", help="unused: this example writes no files")
parser.parse_args()

# --8<-- [start:model]
np.set_printoptions(precision=6, suppress=True, linewidth=100)
plant = paper.discrete_model()  # recovered A_d, B_d (unrounded)
printed = paper.PRINTED  # eq. (3) and eq. (12) exactly as printed
print("A_d, recovered:\n", plant.A)
print("A_d, printed:\n", printed["Ad"])
print("B_d, recovered:", plant.B.ravel(), " printed:", printed["Bd"].ravel())

L, M = paper.kalman_gains()  # eq. (11) on the recovered model
print("max |round(L, 4) - printed L| =", np.abs(np.round(L, 4) - printed["L"]).max())
print("max |M - printed M|          =", np.abs(M - printed["M"]).max())
# --8<-- [end:model]
assert np.array_equal(np.round(L, 4), printed["L"])
assert np.abs(M - printed["M"]).max() < 5e-4  # M[0, 1] is printed with three decimals

# --8<-- [start:correction1]
# Correction 1: A_d[0, 1] is printed 0.001; a sampled double integrator has ~Ts = 0.01 there.
# Design eq. (11) from the printed A_d and B_d, with that one entry replaced.
aug = paper.augmented_model()
Qn, Rn, Nn = paper.noise_model()


def design_from_printed(a01: float) -> riprs.KalmanDesign:
    A = np.eye(5)
    A[:4, :4] = printed["Ad"]
    A[0, 1] = a01
    B = np.zeros((5, 2))
    B[:4, 0] = printed["Bd"].ravel() * paper.INPUT_SCALE
    B[4, 1] = 0.01
    return riprs.kalman(A, np.eye(5), aug.C, B @ B.T, np.eye(2), np.zeros((5, 2)))


for a01 in (0.001, 0.0099):
    kf = design_from_printed(a01)
    miss = max(np.abs(kf.L - printed["L"]).max(), np.abs(kf.M - printed["M"]).max())
    print(f"printed A_d with A_d[0, 1] = {a01}: L[0, 0] = {kf.L[0, 0]:.4f} (printed 0.0723), "
          f"largest miss on eq. (12) {miss:.1e}")
print(f"recovered model, A_d[0, 1] = {plant.A[0, 1]:.6f}: L[0, 0] = {L[0, 0]:.4f}")
# --8<-- [end:correction1]
assert round(design_from_printed(0.001).L[0, 0], 4) == 0.0143
assert round(design_from_printed(0.0099).L[0, 0], 4) == 0.0721
assert round(L[0, 0], 4) == 0.0723 and round(plant.A[0, 1], 6) == 0.009916

# --8<-- [start:correction2]
# Correction 2: eq. (8) prints Q[1, 0] = 0.008, but Q = B B^T is symmetric.
print("Q = B B^T, rows 0-1:\n", Qn[:2])
print("Q[0, 1] = B[0, 0] * B[1, 0] =", aug.B[0, 0] * aug.B[1, 0], "= Q[1, 0]")
# --8<-- [end:correction2]
assert np.allclose(Qn, Qn.T) and round(Qn[1, 0], 4) == 0.0008

# --8<-- [start:correction3]
# Correction 3: A_d[2, 1] is printed 0; row 2 is printed with three decimals (1.003).
print(f"A_d[2, 1] = {plant.A[2, 1]:.6f}, rounds to {round(plant.A[2, 1], 3) + 0.0}")
# --8<-- [end:correction3]
assert round(plant.A[2, 1], 6) == -0.000053 and round(plant.A[2, 1], 3) == 0

# --8<-- [start:scaled]
# Not a correction: the u column of eq. (3)'s B is B_d * L_su (L_su = 10), the MPC's input
# scale, which is why eq. (8) has Q[1, 1] = 0.398^2 = 0.159 while eq. (11) prints B_u = B_d.
print("B column of eq. (3):", aug.B[:4, 0], "= B_d *", paper.INPUT_SCALE)
# --8<-- [end:scaled]
assert np.allclose(aug.B[:4, 0], plant.B.ravel() * paper.INPUT_SCALE)
assert round(Qn[1, 1], 3) == 0.159

"""Swing-up in simulation: energy pumping from hanging at rest, then a bumpless catch by the
balance controller (riprs.SwingUp around LQR, LQG or MPC).

    python examples/swing_up.py --out swing-out

With RIPRS_EXAMPLES_SMALL=1 only the LQR catch is simulated (the test suite's size).
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

# --8<-- [start:imports]
import numpy as np

import riprs

# --8<-- [end:imports]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="riprs-swing-up", help="output directory for the figure")
args = parser.parse_args()
small = os.environ.get("RIPRS_EXAMPLES_SMALL") == "1"

# --8<-- [start:setup]
hanging = [0.0, 0.0, math.pi, 0.0]  # arm, arm rate, pendulum (0 = upright), pendulum rate
balancers = {"LQR": riprs.Lqr.paper(), "MPC": riprs.paper.mpc(solver="active_set")}
# --8<-- [end:setup]
if small:
    balancers.pop("MPC")
# --8<-- [start:swing]
runs = {}
for name, balance in balancers.items():
    ctrl = riprs.SwingUp(balance, riprs.paper.plant())
    run = riprs.simulate(
        riprs.paper.plant(), ctrl, 15.0, x0=hanging,
        encoder_counts=2048, noise_std=1e-3, seed=0,
    )  # fmt: skip
    runs[name] = run
    upright = abs(math.remainder(run.x[-1, 2], 2 * math.pi))
    print(f"{name}: caught at {run.catch_time:.2f} s, |alpha| at the end {upright:.4f} rad, "
          f"peak |u| {np.abs(run.u).max():.1f} V, arm within {np.abs(run.x[:, 0]).max():.2f} rad")
print("settings:", ctrl.settings)
# --8<-- [end:swing]

for run in runs.values():
    assert not run.fell and run.catch_time is not None
    assert abs(math.remainder(run.x[-1, 2], 2 * math.pi)) < 0.05

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 4.5), constrained_layout=True)
for name, run in runs.items():
    ax1.plot(run.t, np.abs(np.remainder(run.x[:, 2] + np.pi, 2 * np.pi) - np.pi), label=name, lw=1)
    ax2.plot(run.t, run.u, label=name, lw=1)
    ax1.axvline(run.catch_time, ls=":", lw=0.8, color=ax1.lines[-1].get_color())
ax1.set_ylabel("|pendulum angle| [rad]\n(0 = upright)")
ax2.set_ylabel("voltage [V]")
ax2.set_xlabel("time [s]")
ax1.legend()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
fig.savefig(out / "swing_up.svg")
print("wrote", out / "swing_up.svg")

"""The paper's hardware column: the rig its study fitted, its Tab. 1, and where the paper's
rankings hold. Reads the study's committed results (scripts/paper_rig_study.py wrote them),
runs the paper's controllers once more on the fitted rig (`riprs compare --hardware`) and draws
the map of the rankings over the cable's stiffness and the dead zone.

    python examples/paper_rig.py --out paper-rig-out
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

# --8<-- [start:imports]
import matplotlib
import numpy as np

from riprs import hardware, paper

# --8<-- [end:imports]

matplotlib.use("Agg")
import matplotlib.pyplot as plt

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="paper-rig-out", help="output directory")
args = parser.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
data = Path(__file__).resolve().parent / "data"

# --8<-- [start:rig]
study = json.loads((data / "paper_rig_study.json").read_text())
print("fitted rig:", ", ".join(f"{k} = {v:.3g}" for k, v in hardware.RIG.items()))
summary = hardware.run()  # the paper's controllers as printed on that rig, seeds 0-2
print(hardware.format_table(summary))
# --8<-- [end:rig]
for name, values in summary.items():
    ratios = [np.log(s / p) for s, p in zip(values, paper.TABLE1[name], strict=True)]
    print(f"{name}: ln(riprs / paper) = " + ", ".join(f"{r:+.2f}" for r in ratios))
print("each controller alone (the sample's closest rig to its own three numbers):")
for name, best in study["each_controller_alone"].items():
    print(
        f"  {name}: J = {best['objective']:.2f}, "
        + " / ".join(f"{v:.3f}" for v in best["summary"])
        + " with "
        + ", ".join(f"{k} {v:.3g}" for k, v in best["rig"].items())
    )
# The committed study and this run agree: the same rig, seeds and window.
assert abs(hardware.objective(summary) - study["objective"]) < 1e-9, study["objective"]

# --8<-- [start:map]
with open(data / "paper_rig_map.csv", newline="") as f:
    rows = list(csv.DictReader(f))
kc = np.unique([float(r["Kc"]) for r in rows])
vd = np.unique([float(r["Vd"]) for r in rows])


def grid(key: str) -> np.ndarray:
    g = np.full((len(vd), len(kc)), np.nan)
    for r in rows:
        g[np.searchsorted(vd, float(r["Vd"])), np.searchsorted(kc, float(r["Kc"]))] = float(r[key])
    return g


lqg_arm, mpc_arm = grid("LQG_arm"), grid("MPC_arm")
fell = np.isnan(lqg_arm)
fig, axes = plt.subplots(2, 2, figsize=(10, 8), constrained_layout=True)
orders = {"arm": "LQR < MPC < LQG", "pendulum": "MPC < LQR < LQG", "voltage": "LQG < MPC < LQR"}
for ax, (signal, order) in zip(axes.flat, orders.items(), strict=False):
    # 1: the ranking holds, 0: it does not, blank: LQG falls (no ranking).
    shown = np.where(fell, np.nan, grid(f"holds_{signal}"))
    ax.pcolormesh(kc * 1e3, vd, shown, cmap="RdYlGn", vmin=0, vmax=1, shading="nearest")
    ax.set_title(f"{signal}: {order} (green: holds; blank: LQG falls)", fontsize=9)
ax = axes[1, 1]
m = ax.pcolormesh(kc * 1e3, vd, lqg_arm, cmap="magma", shading="nearest")
fig.colorbar(m, ax=ax, label="LQG arm RMSE (rad)")
ax.contour(kc * 1e3, vd, lqg_arm, levels=[0.341], colors="cyan")
ax.contour(kc * 1e3, vd, mpc_arm, levels=[0.073], colors="white", linestyles="--")
ax.set_title("LQG arm (cyan: 0.341 rad); MPC arm 0.073 rad (dashed)", fontsize=9)
for ax in axes.flat:
    ax.plot(hardware.RIG["Kc"] * 1e3, hardware.RIG["Vd"], "bx", ms=10, mew=2)
    ax.set_xlabel("cable stiffness Kc (1e-3 N m/rad)")
    ax.set_ylabel("dead zone Vd (V)")
for ext in ("svg", "png"):
    fig.savefig(out / f"paper_rig_map.{ext}")
# --8<-- [end:map]
holds = sum(grid(f"holds_{s}") for s in orders)
print(
    f"map: {len(rows)} rigs; all three rankings hold on {int(np.sum(holds == 3))}, "
    f"arm {int(np.nansum(grid('holds_arm')))}, pendulum {int(np.nansum(grid('holds_pendulum')))},"
    f" voltage {int(np.nansum(grid('holds_voltage')))}; LQG falls on "
    f"{int(np.sum(np.isnan(lqg_arm)))}"
)

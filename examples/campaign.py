"""Campaigns: how far can the pendulum mass and the arm length be off before LQR, LQG and MPC
fall? A coarse version of `riprs campaign --example`, run in process, read back as an Arrow
table and drawn as robustness maps. Needs the campaign extra (pip install ".[campaign]").

    python examples/campaign.py --out campaign-out

With RIPRS_EXAMPLES_SMALL=1 the grid is 3 x 3 with 2 seeds of 3 s (the test suite's size).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

# --8<-- [start:imports]
import numpy as np

from riprs import campaign

# --8<-- [end:imports]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="riprs-campaign", help="output directory")
args = parser.parse_args()
small = os.environ.get("RIPRS_EXAMPLES_SMALL") == "1"
points, seeds, duration = (3, 2, 3.0) if small else (7, 4, 10.0)

# --8<-- [start:campaign]
spec = f"""
[campaign]
controllers = ["LQR", "LQG", "MPC"]
seeds = {seeds}                # noise seeds per grid point
duration = {duration}          # s per run

[[campaign.axis]]
name = "mp"              # pendulum mass, as a factor on the designed-for value
scale = [0.7, 1.3]
points = {points}

[[campaign.axis]]
name = "Lr"              # arm length
scale = [0.8, 1.2]
points = {points}
"""
spec_path = Path(args.out).with_suffix(".toml")
spec_path.parent.mkdir(parents=True, exist_ok=True)
spec_path.write_text(spec)
result = campaign.run(spec_path, args.out, progress=False)  # in process, all cores
table = result.table  # one row per run (pyarrow.Table); campaign.load(out) reads it back
print(campaign.summary(table))
fell = np.asarray(table.column("fell"))
names = np.asarray(table.column("controller"))
for name in ("LQR", "LQG", "MPC"):
    print(f"{name}: {fell[names == name].mean():.1%} of {np.sum(names == name)} runs fell")
print("figures:", ", ".join(sorted(p.name for p in result.files if p.suffix == ".svg")))
# --8<-- [end:campaign]
assert table.num_rows == 3 * seeds * points * points
assert (Path(args.out) / "fall_rate_map.svg").exists()

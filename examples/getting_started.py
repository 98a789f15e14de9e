"""Getting started: the paper's comparison, `riprs compare`, from Python.

Designs LQR, LQG and MPC with the paper's weights, runs each for 10 s on the nonlinear `paper`
plant with 2048-count encoders and 1 mrad noise while the arm steps 0 -> 1 rad at 1 s, prints
Tab. 1 next to the paper's experiment and writes the CSV files and figures into --out.

    python examples/getting_started.py --out compare-out

With RIPRS_EXAMPLES_SMALL=1 the runs last 2 s (the test suite's size).
"""

from __future__ import annotations

import argparse
import os

# --8<-- [start:imports]
import riprs
from riprs.compare import compare, format_monte_carlo

# --8<-- [end:imports]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="riprs-compare", help="output directory")
args = parser.parse_args()
small = os.environ.get("RIPRS_EXAMPLES_SMALL") == "1"

# --8<-- [start:config]
config = riprs.Spec()  # the paper's settings, as `riprs config` prints them
# --8<-- [end:config]
if small:
    config = config.updated({"reference": {"duration": 2.0}})
# --8<-- [start:compare]
result = compare(config, out=args.out, seed=0, progress=False)
print(result.table())
for name, run in result.runs.items():
    print(f"{name}: fell={run.fell}, {len(run.t)} samples, peak |u| = {abs(run.u).max():.2f} V")
print("files:", ", ".join(sorted(p.name for p in result.files)))
# --8<-- [end:compare]

# --8<-- [start:monte_carlo]
# 50 more runs per controller over noise seeds and +-10 % errors of every physical parameter
# (`riprs compare --monte-carlo 50`): metrics only, computed in parallel.
runs = 50
# --8<-- [end:monte_carlo]
if small:
    runs = 5
# --8<-- [start:monte_carlo_run]
mc = compare(config, seed=0, monte_carlo=runs, plots=False, progress=False).monte_carlo
print()
print(format_monte_carlo(mc))
# --8<-- [end:monte_carlo_run]

# Every controller balances the nominal plant: the check that keeps this example honest.
assert not any(run.fell for run in result.runs.values())
assert {f"{q}.svg" for q in ("arm_angle", "pendulum_angle", "control_voltage")} <= {
    p.name for p in result.files
}

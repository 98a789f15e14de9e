"""Performance: a quick timing of riprs against what a Python user would write instead, on the
machine at hand (medians of repeated calls). benches/baselines.py is the full comparison and
`cargo bench` times the Rust hot paths without Python.

    python examples/performance.py

With RIPRS_EXAMPLES_SMALL=1 each case is repeated fewer times (the test suite's size).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

# --8<-- [start:imports]
import numpy as np
import scipy.linalg

import riprs
from riprs import paper

# --8<-- [end:imports]

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", help="unused: this example writes no files")
parser.parse_args()
repeats = 20 if os.environ.get("RIPRS_EXAMPLES_SMALL") == "1" else 200


# --8<-- [start:timing]
def median_time(fn, repeats: int) -> float:
    """Median wall time of one call (s)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


plant = paper.discrete_model()
Q, R = paper.lqr_weights()
mpc = paper.mpc("active_set")
y, r = np.array([0.0, 0.01]), np.array([0.0, 0.0])
cases = {
    "DARE, paper plant": (
        lambda: riprs.dare(plant.A, plant.B, Q, R),
        lambda: scipy.linalg.solve_discrete_are(plant.A, plant.B, Q, R),
        "scipy.linalg.solve_discrete_are",
    ),
    "10 s closed-loop LQR (1000 steps)": (
        lambda: riprs.simulate(paper.plant(), riprs.Lqr.paper(), 10.0),
        None,
        "",
    ),
    "MPC step, active-set": (lambda: mpc.step(y, r), None, ""),
}
print(f"{'case':36} {'riprs':>10} {'baseline':>12}  ratio")
for name, (ours, theirs, label) in cases.items():
    t_ours = median_time(ours, repeats)
    line = f"{name:36} {t_ours * 1e6:8.1f} µs"
    if theirs is not None:
        t_theirs = median_time(theirs, repeats)
        line += f" {t_theirs * 1e6:10.1f} µs  {t_theirs / t_ours:5.0f}x  ({label})"
    print(line)
# --8<-- [end:timing]

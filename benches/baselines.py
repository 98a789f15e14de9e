"""riprs against what a Python user would write instead, timed in one run on one machine.

Rows (each a median over repeated calls; ratio = baseline / riprs, how many times faster riprs
is):

- DARE of the paper's 4-state plant: ``riprs.dare`` vs ``scipy.linalg.solve_discrete_are``.
- LQR design: ``riprs.dlqr`` vs python-control's ``dlqr``.
- The 5-state Kalman design of eq. (11): ``riprs.kalman`` vs scipy's DARE plus the MATLAB
  formulas for L and M in numpy.
- One MPC step on the paper's settings, per riprs QP backend, vs python ``clarabel`` on the same
  condensed QP and vs ``cvxpy`` with parameters (``benches/mpc_baseline.py``).
- A 10 s closed-loop LQR run: ``riprs.simulate`` vs a numpy RK4 loop and scipy ``solve_ivp``
  (``benches/sim_baseline.py``).

Usage: ``python benches/baselines.py [--csv FILE] [--quick]``; prints a table and writes it as
CSV (default ``target/baselines.csv``).
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import control
import numpy as np
import scipy.linalg as sl

import riprs

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import mpc_baseline
import sim_baseline


def median_seconds(fn: Callable[[], Any], min_time: float, max_calls: int = 100_000) -> float:
    """Median of per-call times over batches sized so each batch lasts ~1 ms."""
    fn()
    start = time.perf_counter()
    fn()
    once = max(time.perf_counter() - start, 1e-7)
    per_batch = max(1, min(int(1e-3 / once), max_calls))
    samples: list[float] = []
    deadline = time.perf_counter() + min_time
    while time.perf_counter() < deadline or len(samples) < 5:
        t0 = time.perf_counter()
        for _ in range(per_batch):
            fn()
        samples.append((time.perf_counter() - t0) / per_batch)
    return statistics.median(samples)


def design_rows(min_time: float) -> list[tuple[str, str, float, float]]:
    plant = riprs.paper.discrete_model()
    Q, R = riprs.paper.lqr_weights()
    aug = riprs.paper.augmented_model()
    Qn, Rn, Nn = riprs.paper.noise_model()
    G = np.eye(5)

    def kalman_scipy() -> tuple[np.ndarray, np.ndarray]:
        P = sl.solve_discrete_are(aug.A.T, aug.C.T, Qn, Rn, s=Nn)
        S_inv = np.linalg.inv(aug.C @ P @ aug.C.T + Rn)
        return (aug.A @ P @ aug.C.T + Nn) @ S_inv, P @ aug.C.T @ S_inv

    rows = []
    for label, baseline_name, ours, theirs in (
        (
            "DARE, paper 4-state plant",
            "scipy.linalg.solve_discrete_are",
            lambda: riprs.dare(plant.A, plant.B, Q, R),
            lambda: sl.solve_discrete_are(plant.A, plant.B, Q, R),
        ),
        (
            "dlqr, paper 4-state plant",
            "control.dlqr",
            lambda: riprs.dlqr(plant.A, plant.B, Q, R),
            lambda: control.dlqr(plant.A, plant.B, Q, R),
        ),
        (
            "Kalman L and M, 5-state eq. (11)",
            "scipy DARE + numpy formulas",
            lambda: riprs.kalman(aug.A, G, aug.C, Qn, Rn, Nn),
            kalman_scipy,
        ),
    ):
        rows.append(
            (label, baseline_name, median_seconds(ours, min_time), median_seconds(theirs, min_time))
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--csv", default="target/baselines.csv", help="where to write the table")
    parser.add_argument("--quick", action="store_true", help="shorter timing (noisier)")
    args = parser.parse_args()
    min_time = 0.2 if args.quick else 1.0

    rows = design_rows(min_time)
    rows += mpc_baseline.baseline_rows(min_time)
    rows += sim_baseline.baseline_rows(repeats=3 if args.quick else 7)

    machine = _machine()
    print(f"riprs {riprs.__version__} vs Python baselines — medians, one run ({machine})")
    print(f"{'case':<40}{'riprs':>12}  {'baseline':<36}{'baseline':>12}{'ratio':>9}")
    for label, baseline, ours, theirs in rows:
        print(
            f"{label:<40}{_fmt(ours):>12}  {baseline:<36}{_fmt(theirs):>12}{theirs / ours:>8.0f}x"
        )
    path = Path(args.csv)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["case", "riprs_seconds", "baseline", "baseline_seconds", "ratio"])
        for label, baseline, ours, theirs in rows:
            w.writerow([label, f"{ours:.6e}", baseline, f"{theirs:.6e}", f"{theirs / ours:.2f}"])
    print(f"wrote {path}")


def _machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            model = next(line.split(":", 1)[1].strip() for line in fh if "model name" in line)
    except (OSError, StopIteration):
        pass
    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}"


def _fmt(seconds: float) -> str:
    if seconds < 1e-3:
        return f"{seconds * 1e6:.2f} µs"
    return f"{seconds * 1e3:.2f} ms"


if __name__ == "__main__":
    main()

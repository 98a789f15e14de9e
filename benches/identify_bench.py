"""Time of ``riprs.identify`` on 60 s of 100 Hz logs (a 30 s chirp and a 30 s PRBS run of a
hidden rig with Coulomb friction, dead zone, 2048-count encoders and noise), and the number of
segment simulations it used.

    python benches/identify_bench.py [--repeat N]
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

import riprs

TS = 0.01
HIDDEN = riprs.FurutaParams(
    Rm=6.1, kt=0.051, km=0.051, mr=0.11, Lr=0.097, Jr=1.1e-4, mp=0.031, Lp=0.152, Jp=6.5e-5,
    Dr=9e-4, Dp=2.4e-5, Cr=2.5e-3, Cp=1.5e-5, Vd=0.35,
)  # fmt: skip


def log_file(path: Path, signal: str, seed: int) -> Path:
    plant = riprs.Plant(HIDDEN)
    rng = np.random.default_rng(seed)
    e = riprs.excitation(signal, dt=TS, duration=30.0, amplitude=2.5, seed=seed)
    q = 2 * math.pi / 2048
    x = np.array([0.0, 0.0, math.pi, 0.0])
    lines = ["t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status"]
    for k in range(len(e)):
        meas = np.round(x[[0, 2]] / q) * q + rng.normal(0.0, 5e-4, 2)
        u = float(np.clip(e[k] - meas[0], -10.0, 10.0))
        lines.append(f"{k * TS:.3f},{k},{meas[0]:.17g},{meas[1]:.17g},0,{u:.17g},0,0,0")
        x = plant.step(x, u, TS, 10)
    path.write_text("\n".join(lines) + "\n")
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as d:
        logs = [log_file(Path(d) / f"{s}.csv", s, seed) for s, seed in (("chirp", 1), ("prbs", 2))]
        times = []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = riprs.identify(logs)
            times.append(time.perf_counter() - t0)
    print(
        "identify 60 s of 100 Hz logs (2 logs, holdout 25 %): "
        f"median {statistics.median(times):.2f} s over {args.repeat} runs; "
        f"{result.iterations} iterations, {result.simulations} segment "
        f"simulations ({result.segments} segments of {result.segment:g} s after a 0.5 s stage), "
        f"held-out fit {np.round(result.fit_percent, 1).tolist()} %"
    )


if __name__ == "__main__":
    main()

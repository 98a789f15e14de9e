"""The table of docs/tuning.md "On the issue's rigs", measured: steady-state arm peak-to-peak
of LQR, LQG and MPC before (no compensation, the file's weights) and after (``riprs tune``,
its compensation 30 % off the rig's dead zone and arm friction, both ways).

Every run: the rig's nonlinear model with stiction (breakaway torque ``2 max(Cr, 0.002)``
N m, which neither the compensation nor the tuning is told), 2048-count encoders, 0.5 mrad
noise, the paper's 0 -> 1 rad arm step at 1 s, 10 s; over the last 3 s the arm's
peak-to-peak, the largest ``|alpha|`` and the arm's offset from the reference, the worst of
two noise seeds. "falls" is a fall in either seed. The rigs are the issue's five and
``riprs.random_rig(seed)`` for the seeds given, each with the sensor above (the issue's rigs'
own, ``riprs.named_rig``).

Usage: python benches/tune_table.py [--seeds 1-10] [--no-issue-rigs]
"""

from __future__ import annotations

import argparse
from typing import Dict, List, Tuple

import numpy as np

import riprs
from riprs.config import Spec
from riprs.tune import tune

TS, SEEDS = 0.01, (0, 1)
#: The issue's table's sensor, the named rigs' own, which the generated rigs are read by too.
SENSOR = riprs.named_rig("paper").to_config()["sensor"]
COUNTS, NOISE = SENSOR["encoder_counts"], SENSOR["noise_std"]
CONTROLLERS = ("LQR", "LQG", "MPC")


def issue_rigs() -> Dict[str, Spec]:
    """Each of the issue's rigs (``riprs.named_rig``), by its row label."""
    return {
        rig.label: Spec.from_toml(rig.to_toml())
        for rig in map(riprs.named_rig, riprs.named_rigs())
    }


def with_sensor(spec: Spec) -> Spec:
    """``spec`` read by the table's sensor, over a 10 s run."""
    return spec.updated({"sensor": SENSOR, "reference": {"duration": 10.0}})


def steady(plant: riprs.Plant, controller) -> Tuple[bool, float, float, float]:
    """(fell, arm peak-to-peak, max |alpha|, |offset|), the worst of the noise seeds."""
    fell, pp, alpha, offset = False, 0.0, 0.0, 0.0
    for seed in SEEDS:
        r = riprs.simulate(
            plant, controller, 10.0, reference=1.0, reference_time=1.0,
            encoder_counts=COUNTS, noise_std=NOISE, seed=seed,
        )
        t, x = np.asarray(r.t), np.asarray(r.x)
        w = t >= t[-1] - 3.0 + 1e-9
        fell |= bool(r.fell)
        pp = max(pp, float(np.ptp(x[w, 0])))
        alpha = max(alpha, float(np.max(np.abs(x[w, 2]))))
        offset = max(offset, abs(float(np.mean(x[w, 0])) - 1.0))
    return fell, pp, alpha, offset


def cell(m: Tuple[bool, float, float, float]) -> str:
    fell, pp, alpha, offset = m
    if fell:
        return "falls"
    bar = "" if pp <= 0.05 and alpha <= 0.02 and offset <= 0.02 else " ✗"
    return f"{pp:.3f}{bar}"


def measure(name: str, file: Spec) -> List[str]:
    """One table row: before, then after with the compensation at 0.7 and 1.3 of the rig's."""
    p = file.params
    truth = file.updated({"plant": {"arm_breakaway": 2.0 * max(p.Cr, 0.002)}}).build_plant()
    before = file.updated({"compensation": {"enabled": False}}).build_controllers(TS)
    row = [" / ".join(cell(steady(truth, before[c])) for c in CONTROLLERS)]
    tuned = tune(file, runs=0, progress=False)
    for factor in (0.7, 1.3):
        changes = {"compensation": {"dead_zone": factor * p.Vd, "arm_friction": factor * p.Cr}}
        cs = tuned.spec.updated(changes).build_controllers(TS)
        row.append(" / ".join(cell(steady(truth, cs[c])) for c in CONTROLLERS))
    w = tuned.weights
    pendulum = f"α×{w['pendulum']:g} " if w["pendulum"] != 1.0 else ""
    row.append(
        f"θ×{w['arm']:g} {pendulum}R×{w['input']:g} q {w['recovery']:g} "
        f"ki {w['integral_weight']:g} {'kept' if tuned.kept_file_weights else ''}".strip()
    )
    return [name, *row]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="1-10", help="generated rigs, e.g. 1-10 or 3,9")
    ap.add_argument("--no-issue-rigs", action="store_true")
    args = ap.parse_args()
    seeds: List[int] = []
    for part in args.seeds.split(","):
        lo, _, hi = part.partition("-")
        seeds.extend(range(int(lo), int(hi or lo) + 1))
    rigs = {
        name: with_sensor(spec)
        for name, spec in ({} if args.no_issue_rigs else issue_rigs()).items()
    }
    for s in seeds:
        rigs[f"generated {s}"] = with_sensor(Spec.from_toml(riprs.random_rig(s).to_toml()))
    print("| rig | before (LQR / LQG / MPC) | tuned, compensation ×0.7 | tuned, ×1.3 | weights |")
    print("|---|---|---|---|---|")
    for name, spec in rigs.items():
        print("| " + " | ".join(measure(name, spec)) + " |", flush=True)


if __name__ == "__main__":
    main()

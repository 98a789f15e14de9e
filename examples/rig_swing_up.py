"""Swing-up on the rig, without a rig: `rip-rt emulate --start down` (the pendulum hanging at
rest) and `rip-rt run --swing-up`, which checks that the rig is at rest, calibrates the encoder
zeros from that rest, swings the pendulum up, catches it with the LQR and balances; the log's
phase column tells the swing from the balance.

    pip install .   # or: cargo build --release -p rip-rt
    python examples/rig_swing_up.py --out swing-rig-out

rip-rt is $RIP_RT, else the `rip-rt` that pip installed, else cargo's release build (built
if missing): riprs._binaries.rip_rt_path. With
RIPRS_EXAMPLES_SMALL=1 it balances 1 s after the catch (the test suite's size), else 4 s.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
from pathlib import Path

import numpy as np

import riprs
from riprs._binaries import rip_rt_path

ROOT = Path(__file__).resolve().parents[1]
parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="riprs-rig-swing-up", help="output directory")
parser.add_argument(
    "--lockstep",
    action="store_true",
    help="run the emulator in lockstep with rip-rt (simulated time: the same log on a loaded"
    " machine; the test suite runs it so)",
)
args = parser.parse_args()
# Lockstep: no period waits for the wall clock; the emulator advances one period per command.
lockstep = ["--lockstep"] if args.lockstep else []
small = os.environ.get("RIPRS_EXAMPLES_SMALL") == "1"
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
rip_rt = rip_rt_path(build=True, workspace=ROOT)
duration = "1" if small else "4"


# --8<-- [start:run]
def swing_up(log_path: Path) -> subprocess.CompletedProcess:
    """A hanging emulated pendulum, swung up and balanced by `rip-rt run --swing-up`."""
    emulator = subprocess.Popen(
        [str(rip_rt), "emulate", "--start", "down", "--noise", "0.3", "--seed", "1", *lockstep],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        device = emulator.stdout.readline().strip().removeprefix("device: ")
        return subprocess.run(
            [str(rip_rt), "run", "--port", device, "--controller", "lqr", "--swing-up",
             "--duration", duration, "--log", str(log_path), "--rt-priority", "20", *lockstep],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    finally:
        emulator.send_signal(signal.SIGTERM)
        emulator.wait(timeout=10)


log_path = out / "swing_up.csv"
run = swing_up(log_path)
# --8<-- [end:run]
# As in rig_emulator.py: a run stopped by the timing rules on an overloaded machine is repeated.
for _ in range(2):
    if run.returncode not in (4, 10):
        break
    print(f"(rip-rt stopped with exit code {run.returncode} on a loaded machine; run again)")
    run = swing_up(log_path)
print(f"rip-rt run --swing-up exit code {run.returncode}; its report:")
print(run.stdout + run.stderr)
assert run.returncode == 0, run.stderr

# --8<-- [start:log]
log = riprs.load_log(log_path)
print("calibration:", log.meta.get("calibration"))
print("first catch at", log.meta.get("catch_s"), "s; catches:", log.meta.get("catches"))
swing = log.phase == "swing_up"
print(f"{swing.sum()} rows swinging up, {(log.phase == 'balance').sum()} balancing")
# --8<-- [end:log]
assert (log.phase == "balance").any()

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 4.5), constrained_layout=True)
upright = np.abs(np.remainder(log.alpha + np.pi, 2 * np.pi) - np.pi)
for phase, colour in (("swing_up", "tab:orange"), ("balance", "tab:blue")):
    rows = log.phase == phase
    ax1.plot(log.t[rows], upright[rows], ".", ms=2, color=colour, label=phase)
    ax2.plot(log.t[rows], log.u[rows], ".", ms=2, color=colour)
ax1.set_ylabel("|pendulum angle| [rad]\n(0 = upright)")
ax2.set_ylabel("voltage [V]")
ax2.set_xlabel("time [s]")
ax1.legend(markerscale=4)
fig.savefig(out / "swing_up.svg")
print("wrote", out / "swing_up.svg")

"""On the rig, without a rig: `rip-rt emulate` (the firmware's device logic on a simulated
pendulum behind a pseudo-terminal) and `rip-rt run` balancing it with the MPC for a few seconds,
then the log read back with riprs.load_log and overlaid on the simulated comparison.

    pip install .   # or: cargo build --release -p rip-rt
    python examples/rig_emulator.py --out rig-out

rip-rt is $RIP_RT, else the `rip-rt` that pip installed, else cargo's release build (built
if missing): riprs._binaries.rip_rt_path. With
RIPRS_EXAMPLES_SMALL=1 the run lasts 2 s (the test suite's size), else 5 s.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
from pathlib import Path

import riprs
from riprs._binaries import rip_rt_path
from riprs.compare import Trajectory, compare

ROOT = Path(__file__).resolve().parents[1]
parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--out", default="riprs-rig", help="output directory")
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
duration = "2" if small else "5"

# --8<-- [start:run]
def balance(log_path: Path) -> subprocess.CompletedProcess:
    """One emulated rig and one `rip-rt run` of the MPC on it."""
    emulator = subprocess.Popen(
        [str(rip_rt), "emulate", "--noise", "0.3", "--seed", "1", *lockstep],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        # The emulator prints the pseudo-terminal it opened: "device: /dev/pts/N".
        device = emulator.stdout.readline().strip().removeprefix("device: ")
        return subprocess.run(
            [str(rip_rt), "run", "--port", device, "--controller", "mpc",
             "--duration", duration, "--log", str(log_path), "--rt-priority", "20", *lockstep],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    finally:
        emulator.send_signal(signal.SIGTERM)
        emulator.wait(timeout=10)


log_path = out / "mpc.csv"
run = balance(log_path)
# --8<-- [end:run]
# The emulator runs in real time next to the loop: on a machine so loaded that one of them does
# not get the CPU for tens of milliseconds, the safety rules stop the run (4: the emulator's
# replies came too late, 5: the pendulum fell, 10: the loop itself was starved). Such a run is
# repeated, at most twice, and says so.
for _ in range(2):
    if run.returncode not in (4, 5, 10):
        break
    print(f"(rip-rt stopped with exit code {run.returncode} on a loaded machine; run again)")
    run = balance(log_path)
print(f"rip-rt run exit code {run.returncode}; its report:")
print(run.stdout + run.stderr)
assert run.returncode == 0, run.stderr

# --8<-- [start:log]
log = riprs.load_log(log_path)
print("stop:", log.stop_reason, "| rows:", len(log.t), "| controller:", log.meta["controller"])
print(f"|alpha| max {abs(log.alpha).max():.3f} rad, |u| max {abs(log.u).max():.2f} V")
# Overlay the hardware (here: emulated) run on the simulated comparison figures.
config = riprs.Spec().updated({"reference": {"duration": float(duration)}})
result = compare(config, out=out / "compare", progress=False,
                 overlays={"rip-rt mpc": Trajectory.from_log(log)})  # fmt: skip
print("figures:", ", ".join(sorted(p.name for p in result.files if p.suffix == ".svg")))
# --8<-- [end:log]
assert log.stop_reason == "finished" and abs(log.alpha).max() < 0.3
assert (out / "compare" / "arm_angle_with_logs.svg").exists()

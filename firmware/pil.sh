#!/usr/bin/env bash
# Processor-in-the-loop checks of the qemu build of the USART image in QEMU (firmware/README.md,
# "Onboard mode"): agreement of the image's moves with the host's, instruction counts per step,
# and balance in lockstep with the host's simulated plant; then the SysTick-driven onboard loop
# at 1 kHz and 100 Hz, its period on QEMU's clock, the device's own stop, and an overrun on a
# slowed core. Ends with one line per controller and check:
#   pil: <controller> steps=N max_du=X max_instr=Y balanced=yes|no
#   pil: stop steps=N max_du=X max_instr=Y max_arm=Z
#   pil: watchdog records=N first_ms=X period_us=Y end_s=Z applied_mv=0
#   pil: timer-<rate> periods=N mean_us=X min_us=Y max_us=Z max_step_instr=W overruns=0
#   pil: budget accepted=... refused=...
#   pil: cli-<controller> exit=0 rows=N max_step_cycles=C
#   pil: overrun step=0 step_us=X step_instr=Y state=overrun overruns=1 applied_mv=0 enabled=no
#
#   firmware/build.sh --no-default-features --features qemu
#   firmware/pil.sh [IMAGE] [STEPS]     (default: that build, 10000 steps per controller)
set -euo pipefail
cd "$(dirname "$0")/.."
image=${1:-firmware/target/thumbv7em-none-eabihf/release/rip-firmware}
steps=${2:-10000}
cargo build --release --quiet -p rip-rt --bins --example pil
exec target/release/examples/pil "$image" "$steps"

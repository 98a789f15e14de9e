#!/usr/bin/env bash
# Processor-in-the-loop checks of the USART image in QEMU (firmware/README.md, "Onboard mode"):
# agreement of the image's moves with the host's, instruction counts per step, and balance in
# lockstep with the host's simulated plant. Ends with one line per controller:
#   pil: <controller> steps=N max_du=X max_instr=Y balanced=yes|no
#
#   firmware/pil.sh [IMAGE] [STEPS]     (default: the USART build, 10000 steps per controller)
set -euo pipefail
cd "$(dirname "$0")/.."
image=${1:-firmware/target/thumbv7em-none-eabihf/release/rip-firmware}
steps=${2:-10000}
cargo build --release --quiet -p rip-rt --example pil
exec target/release/examples/pil "$image" "$steps"

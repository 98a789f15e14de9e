#!/usr/bin/env bash
# Builds the release image of the firmware and prints its flash and RAM use.
#
#   firmware/build.sh                                        # USB CDC build (default)
#   firmware/build.sh --no-default-features --features usart # USART1 build (QEMU)
#
# Two routes to a thumbv7em-none-eabihf compiler, chosen automatically:
# - rustup with the target installed (`rustup target add thumbv7em-none-eabihf`): plain
#   `cargo build --release`, linked with the toolchain's rust-lld;
# - otherwise a compiler whose sysroot carries the standard library's sources (Debian's
#   rustc-web + rust-web-src, or rustup's rust-src component): `core` is built from source
#   with -Zbuild-std (RUSTC_BOOTSTRAP=1 allows the unstable flag on a stable compiler) and the
#   image is linked with ld.lld. FIRMWARE_RUSTC / FIRMWARE_CARGO pick that compiler (default:
#   /usr/bin/rustc and /usr/bin/cargo when present, else the ones on PATH).
set -euo pipefail
cd "$(dirname "$0")"
target=thumbv7em-none-eabihf

if command -v rustup >/dev/null 2>&1 &&
    rustup target list --installed 2>/dev/null | grep -qx "$target"; then
    echo "firmware: rustup route ($(rustc --version))"
    cargo build --release --locked "$@"
else
    rustc_bin=${FIRMWARE_RUSTC:-$( [ -x /usr/bin/rustc ] && echo /usr/bin/rustc || command -v rustc)}
    cargo_bin=${FIRMWARE_CARGO:-$( [ -x /usr/bin/cargo ] && echo /usr/bin/cargo || command -v cargo)}
    sysroot=$("$rustc_bin" --print sysroot)
    if [ ! -d "$sysroot/lib/rustlib/src/rust/library/core" ]; then
        echo "firmware: no $target target and no library sources in $sysroot:" >&2
        echo "  rustup target add $target   (or: apt-get install rustc-web rust-web-src lld)" >&2
        exit 1
    fi
    command -v ld.lld >/dev/null || { echo "firmware: ld.lld not found (apt-get install lld)" >&2; exit 1; }
    echo "firmware: build-std route ($("$rustc_bin" --version))"
    RUSTC="$rustc_bin" RUSTC_BOOTSTRAP=1 "$cargo_bin" build --release --locked \
        -Zbuild-std=core -Zbuild-std-features=compiler-builtins-mem \
        --config "target.$target.linker='ld.lld'" "$@"
fi

elf=target/$target/release/rip-firmware
# Flash holds the code, the read-only data and the initial values of .data; RAM holds .data,
# .bss and .uninit (the stack takes the rest of RAM).
flash=0
ram=0
while read -r sec size; do
    case "$sec" in
        .vector_table | .text | .rodata) flash=$((flash + 16#$size)) ;;
        .data) flash=$((flash + 16#$size)); ram=$((ram + 16#$size)) ;;
        .bss | .uninit) ram=$((ram + 16#$size)) ;;
    esac
done < <(readelf -SW "$elf" | sed -n 's/^ *\[ *[0-9]*\] *\(\.[A-Za-z_.]*\) *[A-Z]* *[0-9a-f]* *[0-9a-f]* *\([0-9a-f]*\).*/\1 \2/p')
echo "firmware: $elf"
awk -v f="$flash" -v r="$ram" 'BEGIN {
    printf "firmware: flash %d bytes (%.1f %% of 1024 KiB), static RAM %d bytes (%.1f %% of 128 KiB)\n",
        f, 100 * f / 1048576, r, 100 * r / 131072 }'

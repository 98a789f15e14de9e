#!/usr/bin/env bash
# Makes docs/img/live.png, the screenshot of `riprs watch` in docs/live.md: a swing-up and
# balance (LQG) on the emulator, recorded live with `riprs watch --save`, then opened in Rerun's
# native viewer on a virtual display and captured with the viewer's own `--screenshot-to`.
#
# Run by hand, not in CI. Needs rip-rt and riprs with the live extra on PATH
# (`cargo build --release`, `pip install ".[live]"`) and, on Debian/Ubuntu:
#   apt-get install -y xvfb xauth mesa-vulkan-drivers libvulkan1 imagemagick pngquant
# (no GPU needed: the viewer draws with Mesa's software Vulkan, lavapipe).
#
#   scripts/live_screenshot.sh [OUT.png]      # default docs/img/live.png
set -euo pipefail

root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$root/docs/img/live.png}"
port="${LIVE_PORT:-9871}"
work="$(mktemp -d)"
pids=()
cleanup() {
    for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
    rm -rf "$work"
}
trap cleanup EXIT

for cmd in rip-rt riprs rerun xvfb-run convert; do
    command -v "$cmd" >/dev/null || { echo "live_screenshot: $cmd not found" >&2; exit 1; }
done

# 1. The recording: the viewer saves to a file, the emulator starts with the pendulum hanging,
#    and the run swings it up, catches it and balances for 6 s (the reference step included).
riprs watch --port "$port" --save "$work/live.rrd" --once --ready "$work/ready" &
watch_pid=$!
pids+=("$watch_pid")
for _ in $(seq 100); do [ -e "$work/ready" ] && break; sleep 0.1; done
rip-rt emulate --link "$work/rip" --start down --live "$port" >/dev/null &
emulate_pid=$!
pids+=("$emulate_pid")
for _ in $(seq 100); do [ -e "$work/rip" ] && break; sleep 0.1; done
rip-rt run --port "$work/rip" --controller lqg --swing-up --duration 6 --live "$port" --quiet &
run_pid=$!
pids+=("$run_pid")
# The viewer ends at the run's stop frame (--once), the last thing the run sends; the
# emulator's true state after it would only lengthen the recording.
wait "$watch_pid"
wait "$run_pid"
kill "$emulate_pid"

# 2. A view for the picture: riprs watch's layout, with the whole recording in the scopes and
#    the rig drawn as it was while balancing. Loaded after the recording, it replaces the
#    recording's own layout for this viewer only.
python3 - "$work/shot.rbl" <<'EOF'
import sys

import rerun as rr
import rerun.blueprint as rrb

from riprs.live import _blueprint

bp = _blueprint(rr)
# The rig as it was 13 s into the recording (balancing, after the reference step), seen from
# the side.
template = rrb.Spatial3DView(
    eye_controls=rrb.EyeControls3D(
        kind=rrb.Eye3DKind.Orbital,
        position=[0.22, -0.20, 0.16],
        look_target=[0.04, 0.0, 0.06],
        eye_up=[0.0, 0.0, 1.0],
    ),
    time_ranges=rrb.VisibleTimeRange(
        "time",
        start=rrb.TimeRangeBoundary.absolute(seconds=12.99),
        end=rrb.TimeRangeBoundary.absolute(seconds=13.0),
    ),
)
stack = [bp.root_container]
while stack:
    part = stack.pop()
    if isinstance(part, rrb.Spatial3DView):
        part.properties.update(template.properties)
    stack.extend(getattr(part, "contents", []) or [])
shot = rrb.Blueprint(
    bp.root_container,
    rrb.TimePanel(state="collapsed", timeline="time", play_state="following"),
    collapse_panels=True,
)
shot.save("riprs", sys.argv[1])
EOF

# 3. The screenshot: the viewer at 1600x1000 points (3200x2000 pixels in the picture) on a
#    larger virtual screen, so that the pointer, at the screen's centre, hovers nothing; with
#    RUST_LOG=error, no notices about the software renderer cover the views.
RUST_LOG=error timeout 300 xvfb-run -a -s "-screen 0 4400x2800x24" \
    rerun --renderer vulkan --window-size 1600x1000 --screenshot-to "$work/shot.png" \
    "$work/live.rrd" "$work/shot.rbl" >"$work/rerun.log" 2>&1 \
    || { tail -20 "$work/rerun.log" >&2; exit 1; }

# 4. Down to 1600x1000 pixels and a palette: the page's image stays small.
mkdir -p "$(dirname "$out")"
convert "$work/shot.png" -resize 1600x1000 -strip "$work/small.png"
if command -v pngquant >/dev/null; then
    pngquant --force --quality 70-95 --speed 1 --output "$out" "$work/small.png" \
        || cp "$work/small.png" "$out"
else
    cp "$work/small.png" "$out"
fi
echo "live_screenshot: wrote $out ($(stat -c %s "$out") bytes)"

"""Ctrl-C stops long native work: a subprocess starts a simulation that would run for minutes,
gets SIGINT, and must be gone within seconds (the bounds are wide on purpose: uninterrupted, the
work takes well over a minute on any machine, and the process must end less than 10 s after
the signal)."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest

GRACE = 10.0  # seconds allowed between SIGINT and the end of the process

# Each snippet prints "ready" just before the long native call; uninterrupted each takes far
# longer than a minute (thousands of 10 s Clarabel MPC runs, or an hour of simulated MPC).
WORK = {
    "simulate_batch": "riprs.simulate_batch(riprs.Plant.paper(), mpc, 2000, 10.0)",
    "simulate_metrics": "riprs.simulate_metrics(riprs.Plant.paper(), mpc, 100000, 10.0)",
    "simulate": "riprs.simulate(riprs.Plant.paper(), mpc, 3600.0)",
}

SCRIPT = """
import sys
import riprs
mpc = riprs.Mpc.paper(solver="clarabel")
print("ready", flush=True)
try:
    {work}
except KeyboardInterrupt:
    print("interrupted", flush=True)
    sys.exit(3)
print("finished", flush=True)
"""


def _wait_for(
    proc: subprocess.Popen[bytes], needle: bytes, stream: str | int, limit: float
) -> bytes:
    """Reads `stream` of `proc` (or the descriptor `stream`) until `needle` appears (or `limit`
    seconds pass)."""
    fd = stream if isinstance(stream, int) else getattr(proc, stream).fileno()
    seen = b""
    end = time.monotonic() + limit
    while needle not in seen and time.monotonic() < end:
        ready, _, _ = select.select([fd], [], [], 0.5)
        if ready:
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            seen += chunk
    assert needle in seen, seen
    return seen


def _drain(fd: int) -> bytes:
    """What is left to read on a terminal whose other end has closed."""
    out = b""
    while select.select([fd], [], [], 0.5)[0]:
        try:
            chunk = os.read(fd, 4096)
        except OSError:  # EIO: the last writer is gone
            break
        if not chunk:
            break
        out += chunk
    return out


def _interrupt(proc: subprocess.Popen[bytes]) -> tuple[bytes, bytes]:
    # Let the native work get going first.
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    try:
        return proc.communicate(timeout=GRACE)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail(f"still running {GRACE} s after SIGINT")


@pytest.mark.parametrize("name", list(WORK))
def test_sigint_stops_native_simulation(name) -> None:
    code = SCRIPT.format(work=WORK[name])
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    _wait_for(proc, b"ready", "stdout", 60.0)
    out, err = _interrupt(proc)
    assert proc.returncode == 3, (out, err)
    assert b"interrupted" in out and b"finished" not in out


def test_sigint_ends_riprs_compare_with_one_line_and_130(tmp_path: Path) -> None:
    # Documented-legal but long: an hour of simulated time for each of the three controllers.
    config = tmp_path / "long.toml"
    config.write_text("[reference]\nduration = 3600.0\n")
    out_dir = tmp_path / "out"
    args = ["compare", "--config", str(config), "--out", str(out_dir), "--no-plots"]
    # Standard error on a terminal, as at a shell: the progress bar is drawn only there.
    terminal, stderr = pty.openpty()
    # 80 columns (a new pseudo-terminal has 0, where the bar would draw nothing).
    fcntl.ioctl(stderr, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "riprs.cli", *args], stdout=subprocess.PIPE, stderr=stderr
        )
        os.close(stderr)
        # The progress bar appears once the simulations start.
        seen = _wait_for(proc, b"simulating", terminal, 120.0)
        _interrupt(proc)
        err = _drain(terminal)
    finally:
        os.close(terminal)
    assert proc.returncode == 130
    assert b"Traceback" not in err
    last = (seen + err).replace(b"\r", b"\n").strip().splitlines()[-1]
    assert last == b"riprs: interrupted"
    assert not out_dir.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.toml"]


def test_the_cli_module_runs_as_a_script() -> None:
    # `python -m riprs.cli` is what the test above runs; make sure it is the real CLI.
    done = subprocess.run(
        [sys.executable, "-m", "riprs.cli", "--version"], capture_output=True, text=True
    )
    assert done.returncode == 0 and done.stdout.startswith("riprs ")

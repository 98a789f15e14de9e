"""The ``rip-rt`` that ``pip install`` puts on the PATH is the cargo binary's program.

The console script runs ``rip_rt::cli::run`` inside the extension. These tests hold it to the
binary built by cargo from the same tree (the reference): the same output and exit codes for
every subcommand's ``--help``, ``--version`` and usage errors; and, on a balancing run against
the emulator, the binary's signal behaviour (SIGINT, SIGTERM: 0 V and the driver disabled as
the device's last command, exit 128 + the signal, no Python traceback). The end-to-end tests of
``crates/rip-rt/tests`` cover every other signal on the binary.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import sysconfig
import textwrap
import time
from pathlib import Path

import pytest

import riprs
from riprs._binaries import cargo_target_dir

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sysconfig.get_path("scripts")) / "rip-rt"

pytestmark = pytest.mark.skipif(
    not SCRIPT.is_file(), reason=f"riprs is not installed with its scripts ({SCRIPT} missing)"
)


@pytest.fixture(scope="module")
def binary() -> Path:
    target = cargo_target_dir(ROOT)
    if target is None:
        pytest.skip("not a cargo checkout: no rip-rt binary to compare with")
    exe = target / "release" / "rip-rt"
    if not exe.is_file():
        subprocess.run(
            ["cargo", "build", "--release", "-p", "rip-rt"], cwd=ROOT, check=True, timeout=1800
        )
    return exe


def _run(exe: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=60)


def test_version_is_the_packages() -> None:
    done = _run(SCRIPT, "--version")
    assert done.returncode == 0, done.stderr
    assert done.stdout == f"rip-rt {riprs.__version__}\n"


@pytest.mark.parametrize(
    "args",
    [
        ["--version"],
        ["--help"],
        ["run", "--help"],
        ["excite", "--help"],
        ["emulate", "--help"],
        ["config", "--help"],
        [],  # no subcommand: usage error
        ["run", "--port", "/dev/null"],  # missing --controller
        ["run", "--port", "/dev/null", "--controller", "pid"],  # bad value
        ["emulate", "--noise", "-1"],
        ["config", "/nonexistent/rig.toml"],
    ],
    ids=lambda a: " ".join(a) or "none",
)
def test_every_subcommand_answers_as_the_binary_does(binary: Path, args: list[str]) -> None:
    ours, ref = _run(SCRIPT, *args), _run(binary, *args)
    assert (ours.returncode, ours.stdout, ours.stderr) == (ref.returncode, ref.stdout, ref.stderr)


def test_config_prints_the_whole_resolved_file(binary: Path, tmp_path: Path) -> None:
    # Standard output ends without a pending partial line: it is flushed before the exit.
    rig = tmp_path / "rig.toml"
    rig.write_text('[plant]\npreset = "qube_servo2"\n[mpc]\nprediction_horizon = 30\n')
    ours, ref = _run(SCRIPT, "config", str(rig)), _run(binary, "config", str(rig))
    assert ours.returncode == ref.returncode == 0, ours.stderr
    assert ours.stdout == ref.stdout and "prediction_horizon = 30" in ours.stdout


def test_the_loop_runs_without_the_gil() -> None:
    # While the native call runs the emulator for 1 s on a thread, the interpreter's main
    # thread keeps running Python: the GIL is released for the whole call.
    code = textwrap.dedent(
        """
        import threading, time
        from riprs._riprs import rip_rt_main
        out = {}
        work = lambda: out.setdefault("code", rip_rt_main(["rip-rt", "emulate", "--duration", "1"]))
        t = threading.Thread(target=work)
        start = time.monotonic()
        t.start()
        ticks = 0
        while t.is_alive():
            ticks += 1
            time.sleep(0.002)
        print(out["code"], ticks, time.monotonic() - start)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    exit_code, ticks, elapsed = done.stdout.split()[-3:]
    assert int(exit_code) == 0
    assert float(elapsed) >= 1.0
    # 1 s at one tick per 2 ms sleep: hundreds; a held GIL would allow none.
    assert int(ticks) > 100, done.stdout


def _record(path: Path) -> list[tuple[int, int]]:
    rows = []
    for line in path.read_text().splitlines()[1:]:
        fields = line.split(",")
        if len(fields) >= 4 and fields[3].strip():
            rows.append((int(fields[2]), int(fields[3])))
    return rows


def _settled_record(path: Path) -> list[tuple[int, int]]:
    # The last frames of the run may still be in the emulator's input.
    text = path.read_text()
    for _ in range(40):
        time.sleep(0.05)
        again = path.read_text()
        if again == text:
            break
        text = again
    return _record(path)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: s.name)
def test_a_signal_stops_the_motor_with_the_binarys_exit_code(
    binary: Path, tmp_path: Path, sig: signal.Signals
) -> None:
    record = tmp_path / "record.csv"
    emulator = subprocess.Popen(
        # In lockstep: the signal's path through the script is the subject, not timing.
        [str(binary), "emulate", "--noise", "0.3", "--record", str(record), "--lockstep"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert emulator.stdout is not None
        device = emulator.stdout.readline().strip().removeprefix("device: ")
        # As from a shell: Python's own SIGINT handler would be installed in the script's
        # interpreter (a job started with SIGINT ignored is another case, the binary's too).
        run = subprocess.Popen(
            [str(SCRIPT), "run", "--port", device, "--controller", "lqr", "--lockstep"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONFAULTHANDLER": ""},
        )
        # Half a second of balancing (50 enabled commands) before the signal.
        balanced = False
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and run.poll() is None:
            time.sleep(0.02)
            enabled = [mv for mv, f in _record(record) if f == 1] if record.exists() else []
            if len(enabled) >= 50 and any(mv != 0 for mv in enabled):
                balanced = True
                break
        assert balanced, "never balanced"
        run.send_signal(sig)
        _, err = run.communicate(timeout=20)
        commands = _settled_record(record)
    finally:
        emulator.send_signal(signal.SIGTERM)
        emulator.wait(timeout=10)
    assert run.returncode == 128 + sig, err
    assert f"stopped by {sig.name}" in err, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    # The device's last command: 0 mV with the driver disabled (flags 0).
    assert commands[-1] == (0, 0), commands[-5:]

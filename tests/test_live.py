"""The live view as a person uses it: an emulator and a run publishing their telemetry, and
``riprs watch`` in a second process saving what it received; then a log and its simulation
drawn in the same panels. Lockstep runs: what is received and drawn is the subject, not the
loop's timing (benches/live_bench.py measures that)."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from riprs import live
from riprs._riprs import live_frame_layout
from riprs.cli import main as riprs_main
from riprs.log import load_log

ROOT = Path(__file__).resolve().parents[1]

# The panels of a run: what the live view draws from the stream and the replay from a log.
RUN_PANELS = {
    "/scopes/arm/measured",
    "/scopes/pendulum/measured",
    "/scopes/voltage/measured",
    "/scopes/timing/run",
    "/rig/measured",
    "/events",
}
TRUE_PANELS = {"/scopes/arm/true", "/scopes/pendulum/true", "/scopes/voltage/true", "/rig/true"}


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_for(path: Path, what: str, proc: subprocess.Popen[str], timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert proc.poll() is None, f"{what} ended early: {proc.communicate()}"
        assert time.monotonic() < deadline, f"no {what} within {timeout} s"
        time.sleep(0.05)


def _watched(
    rip_rt: Path, d: Path, emulate: list[str], command: list[str], config: str = ""
) -> dict[str, Path]:
    """``riprs watch --save`` on a free port, then a lockstep emulator (``emulate`` args and
    ``--live``) and a rip-rt ``command`` on it with ``--log``, ``{device}`` and ``{config}``
    (the file ``config``, its ``{port}`` filled in) filled in; the viewer ends with the
    command's stop frame."""
    port = _free_port()
    (d / "rig.toml").write_text(config.format(port=port))
    files = {k: d / n for k, n in [("rrd", "run.rrd"), ("stats", "stats.json"), ("log", "run.csv")]}
    ready = d / "ready"
    watcher = subprocess.Popen(
        [sys.executable, "-m", "riprs.cli", "watch", "--port", str(port), "--save",
         str(files["rrd"]), "--once", "--idle", "60", "--stats", str(files["stats"]),
         "--ready", str(ready), "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    emulator = None
    try:
        _wait_for(ready, "viewer", watcher)
        emulator = subprocess.Popen(
            [str(rip_rt), "emulate", "--lockstep", "--live", str(port), *emulate],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert emulator.stdout is not None
        device = emulator.stdout.readline().strip().removeprefix("device: ")
        args = [a.format(port=port, device=device, config=d / "rig.toml") for a in command]
        done = subprocess.run(
            [str(rip_rt), *args, "--lockstep", "--log", str(files["log"]), "--quiet"],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        _, err = watcher.communicate(timeout=120)
        assert watcher.returncode == 0, err
    finally:
        for p in (watcher, emulator):
            if p is not None and p.poll() is None:
                p.terminate()
                p.communicate(timeout=10)
    return files


@pytest.fixture(scope="module")
def watched_run(rip_rt: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A lockstep LQG run of 3 s on the emulator, the run's stream switched on by its file's
    ``[loop] live_port`` and the emulator's by ``--live``, watched by ``riprs watch --save``."""
    command = ["run", "--port", "{device}", "--controller", "lqg", "--duration", "3"]
    return _watched(
        rip_rt,
        tmp_path_factory.mktemp("live"),
        [],
        [*command, "--config", "{config}"],
        "[loop]\nlive_port = {port}\n",
    )


@pytest.fixture(scope="module")
def watched_excitation(rip_rt: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A lockstep chirp of 3 s on the emulator hanging down, streamed with ``--live``."""
    command = ["excite", "--port", "{device}", "--signal", "chirp", "--duration", "3"]
    return _watched(
        rip_rt,
        tmp_path_factory.mktemp("live-excite"),
        ["--start", "down"],
        [*command, "--live", "{port}"],
    )


def test_the_viewer_receives_and_records_every_period_of_a_run(
    watched_run: dict[str, Path],
) -> None:
    rows = len(load_log(watched_run["log"]).t)
    stats = json.loads(watched_run["stats"].read_text())
    assert rows == 300, rows
    # The bar: at least 99 % of the run's periods reach the viewer.
    assert stats["frames"]["period"] >= 0.99 * rows, stats
    assert stats["frames"]["stop"] == 1 and stats["exit_codes"] == [0], stats
    assert stats["frames"]["truth"] > 0 and stats["bad"] == 0, stats
    counts = live.recorded_counts(watched_run["rrd"])
    assert RUN_PANELS | TRUE_PANELS <= set(counts), counts
    assert counts["/scopes/arm/measured"] == stats["frames"]["period"], counts
    assert counts["/rig/true"] == stats["frames"]["truth"], counts


def test_an_excitation_is_watched_whole(watched_excitation: dict[str, Path]) -> None:
    log = load_log(watched_excitation["log"])
    stats = json.loads(watched_excitation["stats"].read_text())
    # Every logged period, its stages (sign check, chirp) among them, reaches the viewer.
    assert stats["frames"]["period"] >= 0.99 * len(log.t) > 0, stats
    assert stats["exit_codes"] == [0], stats
    counts = live.recorded_counts(watched_excitation["rrd"])
    assert counts["/scopes/voltage/measured"] == stats["frames"]["period"], counts


def test_a_log_and_its_simulation_show_the_live_views_panels(
    watched_run: dict[str, Path], tmp_path: Path
) -> None:
    replay = tmp_path / "replay.rrd"
    assert riprs_main(["watch", "--log", str(watched_run["log"]), "--save", str(replay)]) == 0
    counts = live.recorded_counts(replay)
    assert RUN_PANELS <= set(counts), counts
    assert counts["/scopes/arm/measured"] == 300, counts
    both = tmp_path / "both.rrd"
    args = ["watch", "--log", str(watched_run["log"]), "--compare", "--save", str(both)]
    assert riprs_main(args) == 0
    counts = live.recorded_counts(both)
    assert RUN_PANELS <= set(counts), counts
    assert {"/scopes/arm/simulated", "/scopes/pendulum/simulated", "/rig/simulated"} <= set(
        counts
    ), counts
    # The simulation spans the log's time axis.
    assert abs(counts["/scopes/arm/simulated"] - 300) <= 2, counts


def test_a_simulation_draws_its_own_panels(tmp_path: Path) -> None:
    out = tmp_path / "sim.rrd"
    args = ["watch", "--simulate", "lqr", "--duration", "1", "--save", str(out)]
    assert riprs_main(args) == 0
    counts = live.recorded_counts(out)
    assert counts["/scopes/arm/simulated"] == 100, counts
    assert "/rig/simulated" in counts, counts


@pytest.mark.parametrize(
    ("args", "named"),
    [
        (["--port", "0"], "--port"),
        (["--port", "http"], "--port"),
        (["--idle", "-1", "--save", "x.rrd"], "idle"),
        (["--compare"], "--compare"),
        (["--log", "a.csv", "--once"], "--once"),
        (["--log", "a.csv", "--simulate", "lqr"], "--simulate"),
    ],
)
def test_bad_input_is_an_error_naming_the_argument(
    args: list[str], named: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    args = [str(tmp_path / a) if a.endswith((".rrd", ".csv")) else a for a in args]
    try:
        code = riprs_main(["watch", *args])
    except SystemExit as e:
        code = int(e.code or 0)
    err = capsys.readouterr().err
    assert code != 0 and named in err, err
    assert "Traceback" not in err, err


@pytest.mark.parametrize(
    "args",
    [
        ["run", "--port", "/dev/null", "--controller", "lqr", "--live", "0"],
        ["excite", "--port", "/dev/null", "--signal", "chirp", "--log", "x.csv", "--live", "x"],
        ["emulate", "--live", "70000"],
    ],
    ids=["run", "excite", "emulate"],
)
def test_a_bad_live_port_is_refused_naming_live(rip_rt: Path, args: list[str]) -> None:
    done = subprocess.run([str(rip_rt), *args], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "--live" in done.stderr, done.stderr


def test_the_documented_frame_layout_is_the_one_rip_rt_sends() -> None:
    fields, fmt, version = live_frame_layout()
    doc = (ROOT / "docs" / "live.md").read_text()
    table = re.findall(r"^\| `(\w+)` \| `(\w+)` \| (\d+) \|", doc, flags=re.M)
    assert [(n, c, int(k)) for n, c, k in table] == [(n, c, k) for n, c, k, _ in fields]
    assert f"version {version}" in doc and f"`{fmt}`" in doc
    assert live.decode_frame(b"RIPL") is None

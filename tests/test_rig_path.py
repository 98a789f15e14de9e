"""What a new user tripped over on the way to the rig, each held by a test.

- ``riprs compare --start down`` draws the simulated pendulum angle wrapped, as the rig's log
  holds it (rip-rt wraps to (-pi, pi]; the reference here is ``numpy.angle``).
- ``riprs compare --log run.csv`` starts the simulations as the logged run started (its
  ``phase`` column), and refuses a ``--start`` that contradicts it.
- Progress bars go to standard error, only when it is a terminal: ``riprs compare > out.txt
  2>&1`` holds no carriage return and "Tab. 1" starts its own line.
- The bring-up checklist's reading of a pendulum encoder 0.02 rad off (firmware/README.md) is
  what ``rip-rt run`` prints against an emulated rig with that offset.
"""

from __future__ import annotations

import io
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import riprs
from riprs import compare as compare_module
from riprs.cli import main
from riprs.compare import Trajectory, compare, start_of_logs, wrap_angle

ROOT = Path(__file__).resolve().parents[1]

# One controller and a short run keep these fast; the swing-up needs its allowance on top.
SHORT = """
controllers = ["LQR"]
[reference]
duration = 3.0
step_time = 0.5
[monte_carlo]
runs = 0
"""

HEADER = "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status,phase\n"


def _log(path: Path, phases: list[str], alpha: list[float]) -> Path:
    rows = [
        f"{0.01 * k:.4f},{k},0.0,{a:.6f},0.0,0.0,5.0,80.0,1,{p}\n"
        for k, (p, a) in enumerate(zip(phases, alpha, strict=True))
    ]
    path.write_text("# controller: lqr\n" + HEADER + "".join(rows) + "# stop: finished\n")
    return path


@pytest.fixture()
def swing_log(tmp_path: Path) -> Path:
    return _log(
        tmp_path / "swing.csv",
        ["swing_up", "swing_up", "swing_up", "balance", "balance"],
        [3.14159, -2.9, 1.2, 0.1, 0.05],
    )


@pytest.fixture()
def balance_log(tmp_path: Path) -> Path:
    return _log(tmp_path / "up.csv", ["balance"] * 4, [0.05, 0.04, 0.03, 0.02])


def _config(tmp_path: Path) -> Path:
    path = tmp_path / "short.toml"
    path.write_text(SHORT)
    return path


def test_wrap_angle_is_rip_rts_wrapping() -> None:
    a = np.linspace(-25.0, 25.0, 20001)
    np.testing.assert_allclose(wrap_angle(a), np.angle(np.exp(1j * a)), atol=1e-12)
    # (-pi, pi]: pi stays, -pi becomes pi, as rip-rt's wrap_angle does.
    assert wrap_angle(np.pi) == np.pi and wrap_angle(-np.pi) == np.pi


def test_start_down_draws_the_simulated_pendulum_wrapped(tmp_path: Path) -> None:
    result = compare(_config(tmp_path), start="down", plots=False, progress=False)
    raw = result.runs["LQR"].y[:, 1]
    drawn = result.trajectories["LQR"].pendulum
    # The simulated swing-up climbs past pi (hanging is pi from upright, then turns).
    assert np.abs(raw).max() > np.pi
    assert np.all(drawn > -np.pi) and np.all(drawn <= np.pi)
    np.testing.assert_allclose(drawn, np.angle(np.exp(1j * raw)), atol=1e-9)


def test_figures_draw_the_simulation_and_the_log_alike(tmp_path: Path, swing_log: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from riprs.plots import plot_trajectories

    result = compare(_config(tmp_path), start="down", plots=False, progress=False)
    log = Trajectory.from_log(riprs.load_log(swing_log))
    ax = plot_trajectories({**result.trajectories, "rip-rt swing": log}, "pendulum")
    for line in ax.get_lines():
        y = np.asarray(line.get_ydata(), dtype=float)
        assert np.all(y[np.isfinite(y)] <= np.pi + 1e-12), line.get_label()
        assert np.all(y[np.isfinite(y)] > -np.pi - 1e-12), line.get_label()


def test_the_start_follows_the_logs_phase_column(swing_log: Path, balance_log: Path) -> None:
    swing, up = riprs.load_log(swing_log), riprs.load_log(balance_log)
    assert start_of_logs({"swing.csv": swing}) == "down"
    assert start_of_logs({"up.csv": up}) == "up"
    assert start_of_logs({}) == "up"
    assert start_of_logs({}, "down") == "down"
    assert start_of_logs({"swing.csv": swing}, "down") == "down"
    with pytest.raises(riprs.ConfigError, match=r"--start up, but the log swing\.csv swings up"):
        start_of_logs({"swing.csv": swing}, "up")
    with pytest.raises(riprs.ConfigError, match=r"--start down, but the log up\.csv has no"):
        start_of_logs({"up.csv": up}, "down")
    with pytest.raises(riprs.ConfigError, match="the logs started differently"):
        start_of_logs({"swing.csv": swing, "up.csv": up})


def test_cli_overlays_a_swing_up_log_on_a_swing_up_simulation(
    tmp_path: Path, swing_log: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = _config(tmp_path)
    code = main(["compare", "--config", str(cfg), "--log", str(swing_log), "--no-plots",
                 "--quiet", "--out", str(tmp_path / "out")])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0
    # The same simulations as an explicit --start down (the time to upright is its column),
    # and the logged run's own row after them.
    code = main(["compare", "--config", str(cfg), "--start", "down", "--no-plots", "--quiet",
                 "--out", str(tmp_path / "down")])  # fmt: skip
    explicit = capsys.readouterr().out
    assert code == 0

    def rows(text: str) -> list[list[str]]:
        return [ln.split() for ln in text.split("\nwrote")[0].splitlines()]

    assert [r for r in rows(printed) if "(logged)" not in r] == rows(explicit)
    assert any(r[:2] == ["rip-rt", "swing"] and r[-1] == "(logged)" for r in rows(printed))
    assert "upright" in printed
    code = main(["compare", "--config", str(cfg), "--log", str(swing_log), "--start", "up",
                 "--no-plots", "--quiet", "--out", str(tmp_path / "bad")])  # fmt: skip
    assert code == 1
    assert "--start up, but the log" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
    # The rig page's last step says so.
    rig = (ROOT / "docs" / "rig.md").read_text()
    step = rig[rig.index("9. **Compare**") : rig.index("## Without a rig")]
    assert "--log run.csv" in step and "`phase`" in step and "--start down" in step


def test_progress_is_not_written_into_a_file(tmp_path: Path) -> None:
    # Standard output and error into one file, as `riprs compare > out.txt 2>&1` does.
    out_txt = tmp_path / "out.txt"
    with out_txt.open("w") as fh:
        done = subprocess.run(
            [sys.executable, "-c", "import sys; from riprs.cli import main; sys.exit(main())",
             "compare", "--config", str(_config(tmp_path)), "--no-plots",
             "--out", str(tmp_path / "out")],
            stdout=fh, stderr=subprocess.STDOUT, timeout=300, cwd=tmp_path,
            env={**os.environ, "MPLBACKEND": "Agg"},
        )  # fmt: skip
    text = out_txt.read_text()
    assert done.returncode == 0, text
    assert "\r" not in text and "simulating" not in text, text
    assert any(line.startswith("Tab. 1") for line in text.splitlines()), text


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_is_drawn_on_standard_error_of_a_terminal(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    items = list(compare_module._progress([1, 2, 3], "simulating", True))
    assert items == [1, 2, 3]
    assert "simulating" in terminal.getvalue()
    assert capsys.readouterr().out == ""
    # Asked not to, or on a file: nothing, and the iterable itself.
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    seq = [1, 2]
    assert compare_module._progress(seq, "simulating", True) is seq
    monkeypatch.setattr(sys, "stderr", terminal)
    assert compare_module._progress(seq, "simulating", False) is seq


def test_the_checklists_encoder_offset_reading(tmp_path: Path, rip_rt: Path) -> None:
    # A pendulum encoder whose zero is 0.02 rad from hanging: the refusal reads 3.120 in
    # magnitude instead of 3.142, as firmware/README.md's bring-up checklist says.
    rig = tmp_path / "offset.toml"
    rig.write_text("[sensor]\nencoder_offsets = [0.0, 0.02]\n")
    emulator = subprocess.Popen(
        [str(rip_rt), "emulate", "--config", str(rig), "--start", "down", "--lockstep"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert emulator.stdout is not None
        device = emulator.stdout.readline().strip().removeprefix("device: ")
        done = subprocess.run(
            [str(rip_rt), "run", "--port", device, "--controller", "lqr", "--duration", "1",
             "--lockstep"],
            capture_output=True, text=True, timeout=60,
        )  # fmt: skip
    finally:
        emulator.send_signal(signal.SIGTERM)
        emulator.wait(timeout=10)
    assert done.returncode == 6, done.stderr
    refusal = r"refusing to balance: pendulum at (-?\d+\.\d{3}) rad from upright"
    reading = re.search(refusal, done.stderr)
    assert reading is not None, done.stderr
    # The hanging pendulum sits at pi - 0.02 from upright; (pi - 0.02) / (2 pi / 2048) is
    # 1017.5 counts, so a resting pendulum reads either neighbouring count: one count of
    # quantisation plus the printout's rounding.
    one_count = 2 * np.pi / 2048
    assert abs(abs(float(reading[1])) - (np.pi - 0.02)) <= one_count + 5e-4, done.stderr
    checklist = (ROOT / "firmware" / "README.md").read_text()
    assert "-3.120 or 3.120, a 0.02 rad offset" in checklist.replace("−", "-")
    assert "--swing-up" in checklist and "calibration.max_pendulum_offset" in checklist


def _rig_swing_log(path: Path) -> tuple[Path, float, float]:
    """A swing-up's log as ``rip-rt run --swing-up`` writes it: the sign check's rows from
    t = 0, no rows while the rig comes to rest (6.7 s), then the swing from t = 7.3 s and the
    balance after its catch. Returns the path, the swing's start and the catch's time."""
    rows = []
    k = 0

    def row(t: float, theta: float, alpha: float, ref: float, u: float, phase: str) -> None:
        nonlocal k
        rows.append(f"{t:.4f},{k},{theta:.6f},{alpha:.6f},{ref:.3f},{u:.4f},5.0,80.0,1,{phase}\n")
        k += 1

    for i in range(30):
        row(0.01 * i, 0.01 * np.sin(i), np.pi, 0.0, 2.0 if i < 15 else -2.0, "sign_check")
    t_swing, t_catch = 7.3, 9.1
    t = t_swing
    while t < t_catch - 1e-9:
        row(t, 0.4 * np.sin(3 * (t - t_swing)), np.pi - (t - t_swing), 0.0, 5.0, "swing_up")
        t += 0.01
    while t < t_catch + 4.0:
        ref = 1.0 if t >= t_catch + 1.0 else 0.0
        row(t, ref + 0.02 * np.sin(7 * t), 0.01 * np.cos(5 * t), ref, 0.3 * np.sin(t), "balance")
        t += 0.01
    path.write_text("# controller: lqr\n" + HEADER + "".join(rows) + "# stop: finished\n")
    return path, t_swing, t_catch


def test_a_logged_swing_up_starts_where_its_simulation_does(tmp_path: Path) -> None:
    path, t_swing, t_catch = _rig_swing_log(tmp_path / "run.csv")
    log = riprs.load_log(path)
    tr = Trajectory.from_log(log)
    # The swing's first row is t = 0, as a simulation started hanging; the sign check and the
    # wait for rest are not drawn.
    assert tr.t[0] == 0.0
    assert np.all(np.diff(tr.t) > 0) and np.all(np.diff(tr.t) < 0.011)
    swing_rows = log.phase == "swing_up"
    first = int(np.flatnonzero(swing_rows)[0])
    np.testing.assert_allclose(tr.t, log.t[first:] - t_swing, atol=1e-9)
    np.testing.assert_allclose(tr.arm, log.theta[first:])
    assert tr.catch_time == pytest.approx(t_catch - t_swing, abs=1e-6)
    # A run started upright is taken as it is.
    up = Trajectory.from_log(riprs.load_log(_log(tmp_path / "up.csv", ["balance"] * 3, [0.1] * 3)))
    assert up.t[0] == 0.0 and up.catch_time is None


def test_gaps_are_drawn_as_gaps() -> None:
    import matplotlib

    matplotlib.use("Agg")
    from riprs.plots import plot_trajectories, with_gaps

    t = np.concatenate([np.arange(0, 0.3, 0.01), 7.3 + np.arange(0, 1, 0.01)])
    y = np.concatenate([np.zeros(30), np.full(100, 10.0)])
    t2, y2 = with_gaps(t, y)
    # One break, inside the gap, and every sample kept.
    nan = np.flatnonzero(np.isnan(y2))
    assert nan.size == 1 and 0.29 < t2[nan[0]] < 7.3
    np.testing.assert_array_equal(np.delete(t2, nan), t)
    np.testing.assert_array_equal(np.delete(y2, nan), y)
    # Evenly spaced samples are left as they are.
    even, same = with_gaps(t[:30], y[:30])
    np.testing.assert_array_equal(even, t[:30])
    np.testing.assert_array_equal(same, y[:30])
    tr = Trajectory(t=t, arm=y, pendulum=y, voltage=y, reference=0 * y)
    ax = plot_trajectories({"rip-rt run": tr}, "voltage")
    drawn = np.asarray(ax.get_lines()[0].get_ydata(), dtype=float)
    assert np.isnan(drawn).sum() == 1


def test_the_overlay_marks_both_catches_and_scores_the_logged_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from riprs.plots import plot_trajectories

    path, t_swing, t_catch = _rig_swing_log(tmp_path / "run.csv")
    cfg = tmp_path / "rig.toml"
    cfg.write_text(
        SHORT.replace("step_time = 0.5", "step_time = 1.0") + '[plant]\npreset = "qube_servo2"\n'
    )
    code = main(["compare", "--config", str(cfg), "--log", str(path), "--no-plots", "--quiet",
                 "--out", str(tmp_path / "out")])  # fmt: skip
    printed = capsys.readouterr().out
    assert code == 0, printed
    # The step time is the spec's, and the paper's experimental column is not printed for a
    # rig it does not describe.
    assert "the step 1 s after the catch" in printed
    assert "paper's experimental values are of its own rig" in printed
    assert "   paper" not in printed
    # The logged run's own indices, over the same window as the simulation's (from its catch,
    # reference.duration long), against numpy's.
    line = next(ln for ln in printed.splitlines() if ln.startswith("rip-rt run"))
    log = riprs.load_log(path)
    window = (log.t >= t_catch - 1e-9) & (log.t < t_catch + 3.0 - 1e-9)
    expected = [
        np.sqrt(np.mean((log.theta[window] - log.theta_ref[window]) ** 2)),
        np.sqrt(np.mean(wrap_angle(log.alpha[window]) ** 2)),
        np.sqrt(np.mean(log.u[window] ** 2)),
    ]
    figures = [float(v) for v in line.split()[2:5]]
    np.testing.assert_allclose(figures, expected, atol=6e-5)
    assert float(line.split()[5]) == pytest.approx(t_catch - t_swing, abs=0.006)
    assert "(logged)" in line
    # Both catches are marked on the figures.
    result = compare(cfg, start="down", plots=False, progress=False)
    traj = Trajectory.from_log(log)
    ax = plot_trajectories({**result.trajectories, "rip-rt run": traj}, "arm")
    marks = [t.get_text() for t in ax.texts]
    assert any(m.startswith("LQR catch") for m in marks), marks
    assert f"rip-rt run catch {t_catch - t_swing:.2f} s" in marks, marks


def test_the_paper_rig_keeps_the_papers_column(capsys: pytest.CaptureFixture[str]) -> None:
    from riprs.compare import describes_paper_rig, format_table

    paper_rig = riprs.Spec()
    assert describes_paper_rig(paper_rig)
    other = paper_rig.updated({"plant": {"preset": "qube_servo2"}})
    assert not describes_paper_rig(other)
    assert not describes_paper_rig(paper_rig.updated({"plant": {"Dr": 1e-3}}))
    summary = {"LQR": (0.1, 0.01, 0.5)}
    assert "paper" in format_table(summary, config=paper_rig).splitlines()[2]
    assert "0.1000" in format_table(summary, config=other)

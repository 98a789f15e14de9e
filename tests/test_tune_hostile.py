"""``riprs tune`` (and ``riprs identify``'s output) on hostile input.

A rig no controller can balance, outputs that cannot be written or would overwrite the input,
arguments out of range, a rig whose identification is untrusted: each is refused up front
with an error naming the argument or the reason, nothing is written, no traceback reaches the
command line, and nothing runs for long on a bad argument.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path

import pytest

import riprs
from riprs.cli import main
from riprs.tune import preflight, tune

# `riprs tune` without its swing-up search (tests/test_swing_tuning.py has it).
TUNE = ["tune", "--no-swing-up"]

# `riprs.tune` is the function; the module is reached by its name.
tune_module = importlib.import_module("riprs.tune")

#: The paper's rig as a file: its own weights work, so a tuning of it takes well under a second.
PAPER = "# The paper's rig.\n" + riprs.Spec().to_toml()

#: Rigs no controller can balance, each as the issue found it.
WEAK_MOTOR = '[plant]\npreset = "qube_servo2"\nkt = 0.004\nkm = 0.004\nRm = 30.0\n'
TILTED_START = '[plant]\npreset = "qube_servo2"\ninitial_state = [0.0, 0.0, 1.2, 0.0]\n'
NOISY_SENSOR = '[plant]\npreset = "qube_servo2"\n[sensor]\nnoise_std = [1.0, 1.0]\n'


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() if p.is_file() else b"<dir>"
        for p in sorted(root.rglob("*"))
    }


@pytest.fixture
def no_search(monkeypatch):
    """Fails the test if the tuning's search starts: the refusal must come before it."""

    def search(*_args, **_kwargs):
        raise AssertionError("the search ran")

    monkeypatch.setattr(tune_module, "tune_weights", search)


# -- a rig no controller can balance ------------------------------------------------------------


@pytest.mark.parametrize("text", [WEAK_MOTOR, TILTED_START], ids=["weak_motor", "tilted_start"])
def test_a_rig_beyond_the_voltage_bound_is_refused_before_the_search(
    tmp_path, capsys, no_search, text
) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(text)
    before = _files(tmp_path)
    code = main([*TUNE, str(rig), "--out", str(tmp_path / "tuned.toml"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1, err
    assert "no controller can balance this rig" in err and "would need" in err, err
    assert "Traceback" not in err
    assert _files(tmp_path) == before


def test_the_python_api_refuses_it_too(no_search) -> None:
    with pytest.raises(riprs.ConfigError, match="no controller can balance this rig"):
        tune(riprs.Spec.from_toml(WEAK_MOTOR), runs=0, progress=False, swing_up=False)


@pytest.mark.slow
def test_a_rig_every_controller_falls_on_exits_non_zero_saying_so(tmp_path, capsys) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(NOISY_SENSOR)
    before = _files(tmp_path)
    code = main([*TUNE, str(rig), "--out", str(tmp_path / "tuned.toml"), "--runs", "2"])
    out, err = capsys.readouterr()
    assert code == 1, err
    for name in ("LQR", "LQG", "MPC"):
        assert any(line.startswith(name) and "falls" in line for line in out.splitlines()), out
    assert "riprs: error:" in err and "fall" in err, err
    assert "miss it by least" not in out
    assert _files(tmp_path) == before


class _Bar:
    """A progress bar that records how it was moved (tqdm's attributes and methods)."""

    def __init__(self, total: int, stop_after: int | None = None) -> None:
        self.total = total
        self.n = 0
        self.seen: list[tuple[int, int]] = []
        self.stop_after = stop_after

    def update(self, n: int = 1) -> None:
        self.n += n
        self.refresh()

    def refresh(self) -> None:
        self.seen.append((self.n, self.total))
        if self.stop_after is not None and len(self.seen) >= self.stop_after:
            raise KeyboardInterrupt

    def close(self) -> None:
        pass


def _fake_bars(monkeypatch, **kwargs) -> list[_Bar]:
    bars: list[_Bar] = []

    def bar(enabled: bool = True, total: int = 0, **_ignored) -> _Bar:
        bars.append(_Bar(total, **kwargs))
        return bars[-1]

    monkeypatch.setattr(tune_module._progress, "bar", bar)
    return bars


def test_the_progress_bar_moves_with_the_search_and_ctrl_c_ends_it(monkeypatch) -> None:
    # A KeyboardInterrupt from the bar is what a Ctrl-C between its updates amounts to; the
    # noisy rig's search, every candidate of which falls, would run for most of a minute.
    bars = _fake_bars(monkeypatch, stop_after=6)
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        tune(riprs.Spec.from_toml(NOISY_SENSOR), runs=3, swing_up=False)
    assert time.monotonic() - start < 15.0
    (bar,) = bars
    done = [n for n, _ in bar.seen]
    assert len(set(done)) == len(done) == 6 and done == sorted(done), bar.seen
    assert all(total > 200 + 3 and n < total for n, total in bar.seen), bar.seen


def test_the_bar_ends_full(monkeypatch) -> None:
    bars = _fake_bars(monkeypatch)
    tune(riprs.Spec(), runs=2)
    (bar,) = bars
    assert bar.n == bar.total, bar.seen


# -- outputs ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("in_the_way", "out", "named"),
    [("dir", "dir", ""), ("tuned.tune.toml", "tuned.toml", "tuned.tune.toml")],
    ids=["the output", "its record"],
)
def test_a_directory_in_the_way_is_refused_before_the_search(
    tmp_path, capsys, no_search, in_the_way, out, named
) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    (tmp_path / in_the_way).mkdir()
    before = _files(tmp_path)
    code = main([*TUNE, str(rig), "--out", str(tmp_path / out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.startswith("riprs: error: --out: "), err
    assert named in err and "is a directory" in err, err
    assert _files(tmp_path) == before


@pytest.mark.parametrize("out", ["rig.toml", "./rig.toml", "link.toml"])
def test_the_input_is_not_overwritten_unless_forced(tmp_path, capsys, no_search, out) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    (tmp_path / "link.toml").symlink_to(rig)
    before = _files(tmp_path)
    code = main([*TUNE, str(rig), "--out", str(tmp_path / out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.startswith("riprs: error: --out: "), err
    assert "--force" in err and "rig.toml" in err, err
    assert _files(tmp_path) == before


def test_the_record_does_not_overwrite_the_input_either(tmp_path, capsys, no_search) -> None:
    rig = tmp_path / "tuned.tune.toml"
    rig.write_text(PAPER)
    before = _files(tmp_path)
    code = main([*TUNE, str(rig), "--out", str(tmp_path / "tuned.toml"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and "--force" in err, err
    assert _files(tmp_path) == before


def test_force_overwrites_the_input(tmp_path, capsys) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    assert main([*TUNE, str(rig), "--out", str(rig), "--runs", "0", "--quiet", "--force"]) == 0
    assert "Tuned by riprs tune" in rig.read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml", "rig.tune.toml"]


def test_write_refuses_a_directory_and_leaves_nothing(tmp_path) -> None:
    res = tune(riprs.Spec(), runs=0, progress=False, swing_up=False)
    (tmp_path / "dir").mkdir()
    with pytest.raises(riprs.RiprsError, match=r"^out: .* is a directory"):
        res.write(tmp_path / "dir")
    assert _files(tmp_path) == {"dir": b"<dir>"}


def test_write_refuses_to_overwrite_its_input_unless_asked(tmp_path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    res = tune(rig, runs=0, progress=False, swing_up=False)
    with pytest.raises(riprs.RiprsError, match="overwrite=True"):
        res.write(rig)
    assert rig.read_text() == PAPER
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]
    res.write(rig, overwrite=True)
    assert rig.read_text() != PAPER


@pytest.mark.parametrize("existing", [True, False], ids=["over an old pair", "a new pair"])
def test_a_write_that_fails_on_the_second_file_leaves_the_files_as_they_were(
    tmp_path, monkeypatch, existing
) -> None:
    # The disk fills as the second file moves into place: an old pair is put back byte for
    # byte, a new one leaves nothing.
    res = tune(riprs.Spec(), runs=0, progress=False, swing_up=False)
    out = tmp_path / "tuned.toml"
    if existing:
        out.write_text("old tuned file")
        (tmp_path / "tuned.tune.toml").write_text("old record")
    before = _files(tmp_path)
    real = tune_module._outputs.os.replace
    calls = []

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(28, "No space left on device", str(dst))
        real(src, dst)

    monkeypatch.setattr(tune_module._outputs.os, "replace", replace)
    with pytest.raises(OSError):
        res.write(out)
    monkeypatch.undo()
    assert _files(tmp_path) == before


@pytest.mark.parametrize("where", ["dir", "side"])
def test_identify_checks_its_outputs_before_the_fit(tmp_path, capsys, monkeypatch, where) -> None:
    identify_module = importlib.import_module("riprs.identify")

    def fit(*_args, **_kwargs):
        raise AssertionError("the identification ran")

    monkeypatch.setattr(identify_module, "identify", fit)
    if where == "dir":
        out = tmp_path / "rig"
        out.mkdir()
    else:
        out = tmp_path / "rig.toml"
        (tmp_path / "rig.identification.toml").mkdir()
    before = _files(tmp_path)
    code = main(["identify", str(tmp_path / "missing.csv"), "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err
    assert code == 1 and err.startswith("riprs: error: --out: "), err
    assert "is a directory" in err
    assert _files(tmp_path) == before


def test_identify_does_not_overwrite_a_log(tmp_path, capsys, monkeypatch) -> None:
    identify_module = importlib.import_module("riprs.identify")
    monkeypatch.setattr(identify_module, "identify", lambda *_a, **_k: pytest.fail("ran"))
    log = tmp_path / "excite.csv"
    log.write_text("t,theta\n")
    before = _files(tmp_path)
    assert main(["identify", str(log), "--out", str(log), "--no-plots"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("riprs: error: --out: ") and "input file" in err, err
    assert _files(tmp_path) == before


# -- arguments ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--seed", "-1"], "--seed"),
        (["--seed", str(10**23)], "--seed"),
        (["--spread", "1"], "--spread"),
        (["--spread", "nan"], "--spread"),
        (["--spread", "-0.1"], "--spread"),
        (["--runs", "-3"], "--runs"),
        (["--runs", str(10**9)], "--runs"),
    ],
)
def test_cli_arguments_out_of_range_are_refused_up_front(
    tmp_path, capsys, no_search, args, flag
) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    before = _files(tmp_path)
    code = main([*TUNE, str(rig), "--out", str(tmp_path / "tuned.toml"), "--quiet", *args])
    err = capsys.readouterr().err
    assert code == 1, err
    assert err.startswith(f"riprs: error: {flag}: "), err
    assert "Traceback" not in err
    assert _files(tmp_path) == before


def test_a_seed_that_is_no_integer_is_a_usage_error(tmp_path, capsys, no_search) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    with pytest.raises(SystemExit) as exc:
        main([*TUNE, str(rig), "--out", str(tmp_path / "tuned.toml"), "--seed", "1e23"])
    assert exc.value.code == 2
    assert "--seed" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"Ts": 1e-5}, "Ts"),
        ({"Ts": 0.5}, "Ts"),
        ({"Ts": float("nan")}, "Ts"),
        ({"seed": -1}, "seed"),
        ({"seed": 10**23}, "seed"),
        ({"seed": 1e23}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"seed": True}, "seed"),
        ({"seed": "3"}, "seed"),
        ({"runs": -3}, "runs"),
        ({"runs": 2.5}, "runs"),
        ({"runs": 10**9}, "runs"),
        ({"spread": 1.0}, "spread"),
        ({"spread": float("nan")}, "spread"),
    ],
)
def test_python_arguments_out_of_range_are_refused_up_front(no_search, kwargs, name) -> None:
    with pytest.raises(ValueError, match=f"^{name}: "):
        tune(riprs.Spec(), progress=False, **kwargs)


def test_numpy_integers_are_integers() -> None:
    import numpy as np

    res = tune(
        riprs.Spec(), runs=np.int64(1), seed=np.uint64(2**64 - 1), progress=False, swing_up=False
    )
    assert res.runs == 1 and all(c.balanced_fraction == 1.0 for c in res.controllers.values())


# -- an untrusted identification ---------------------------------------------------------------

UNTRUSTED = (
    "[identification]\ntrusted = false\n"
    'problems = ["the dead zone is not identifiable from these logs"]\n'
)


def test_an_untrusted_identification_is_warned_of_and_recorded(tmp_path, capsys) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    (tmp_path / "rig.identification.toml").write_text(UNTRUSTED)
    out = tmp_path / "tuned.toml"
    assert main([*TUNE, str(rig), "--out", str(out), "--runs", "0", "--quiet"]) == 0
    printed, err = capsys.readouterr()
    assert printed.startswith("WARNING: ") and "not trusted" in printed, printed
    assert "riprs: warning:" in err and "not trusted" in err, err
    assert "dead zone is not identifiable" in err
    import tomllib

    record = tomllib.loads((tmp_path / "tuned.tune.toml").read_text())
    assert record["identification"]["trusted"] is False, record
    assert "dead zone is not identifiable" in record["identification"]["reason"], record
    # The pre-flight of the tuned file sees it, though nothing lies beside the tuned file.
    found = {f.check: f for f in preflight(out, "LQR")}["identification"]
    assert found.verdict == "refuse", found
    assert "dead zone is not identifiable" in found.message, found


def test_a_trusted_rig_records_no_mark(tmp_path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(PAPER)
    res = tune(rig, runs=0, progress=False, swing_up=False)
    assert res.untrusted is None
    side = res.write(tmp_path / "tuned.toml")
    assert "untrusted" not in side.read_text()
    found = {f.check: f for f in preflight(tmp_path / "tuned.toml", "LQR")}["identification"]
    assert found.verdict == "pass", found


def test_ctrl_c_ends_riprs_tune_within_seconds(tmp_path) -> None:
    import os
    import select
    import signal
    import subprocess
    import sys

    rig = tmp_path / "rig.toml"
    rig.write_text(NOISY_SENSOR)
    # The warning of an untrusted identification is printed just before the search begins.
    (tmp_path / "rig.identification.toml").write_text(UNTRUSTED)
    before = _files(tmp_path)
    proc = subprocess.Popen(
        [sys.executable, "-m", "riprs.cli", *TUNE, str(rig), "--out", str(tmp_path / "t.toml")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        seen, end = b"", time.monotonic() + 60.0
        while b"riprs: warning:" not in seen and time.monotonic() < end:
            if select.select([proc.stderr], [], [], 0.5)[0]:
                seen += os.read(proc.stderr.fileno(), 4096)
        assert b"riprs: warning:" in seen, seen
        time.sleep(1.0)
        assert proc.poll() is None, "the search (about half a minute) ended early"
        proc.send_signal(signal.SIGINT)
        start = time.monotonic()
        _, err = proc.communicate(timeout=30)
        assert time.monotonic() - start < 10.0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert b"riprs: interrupted" in err and b"Traceback" not in err, err
    assert _files(tmp_path) == before

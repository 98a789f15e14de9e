"""`riprs compare`'s output directory: problems found before any simulation, results staged and
moved into place, so a failure (a full disk, an error, Ctrl-C) never leaves a half-written
result or touches earlier ones."""

from __future__ import annotations

import errno
import os
from collections import namedtuple
from pathlib import Path

import pytest

import riprs.compare as compare_module
from riprs.cli import main
from riprs.compare import OutputPathError, compare
from riprs.config import Spec

SHORT = "[reference]\nduration = 0.5\n"


@pytest.fixture
def config(tmp_path: Path) -> Path:
    path = tmp_path / "config.toml"
    path.write_text(SHORT)
    return path


@pytest.fixture
def no_simulation(monkeypatch):
    """Fails the test if a simulation starts: the output checks must come first."""

    def refuse(*_args, **_kwargs):
        raise AssertionError("a simulation ran before the output path was checked")

    monkeypatch.setattr(compare_module, "simulate", refuse)
    monkeypatch.setattr(compare_module, "build_controllers", refuse)


def _tree(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() if p.is_file() else b"<dir>"
        for p in sorted(root.rglob("*"))
    }


def test_an_empty_out_is_refused_and_nothing_is_written(
    tmp_path, config, monkeypatch, capsys, no_simulation
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["compare", "--config", str(config), "--out", "", "--quiet"]) == 1
    assert "out" in capsys.readouterr().err
    assert list(work.iterdir()) == []


@pytest.mark.parametrize("where", ["file", "file/sub"])
def test_a_file_in_the_way_is_refused(tmp_path, config, capsys, no_simulation, where) -> None:
    (tmp_path / "file").write_text("keep me")
    code = main(["compare", "--config", str(config), "--out", str(tmp_path / where), "--quiet"])
    assert code == 1
    assert "not a directory" in capsys.readouterr().err
    assert (tmp_path / "file").read_text() == "keep me"


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_an_unwritable_place_is_refused(tmp_path, no_simulation) -> None:
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    with pytest.raises(OutputPathError, match="not writable"):
        compare(Spec(), out=locked / "out", progress=False)


def test_too_little_free_space_is_refused(tmp_path, monkeypatch, no_simulation) -> None:
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(compare_module.shutil, "disk_usage", lambda _p: usage(10**6, 10**6, 4096))
    with pytest.raises(OutputPathError, match="free"):
        compare(Spec(), out=tmp_path / "out", progress=False)
    assert list(tmp_path.iterdir()) == []


def test_a_failed_write_leaves_the_earlier_results(tmp_path, config, monkeypatch) -> None:
    out = tmp_path / "out"
    assert main(["compare", "--config", str(config), "--out", str(out), "--quiet"]) == 0
    before = _tree(out)
    assert "summary.csv" in before and "arm_angle.png" in before

    def disk_full(trajectories, path: Path) -> Path:
        with path.open("w") as fh:
            fh.write("time,lqr_arm\n0.0,")
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(compare_module, "_write_trajectories", disk_full)
    code = main(["compare", "--config", str(config), "--out", str(out), "--seed", "9", "--quiet"])
    assert code == 1
    assert _tree(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["config.toml", "out"]


def test_an_interrupted_run_leaves_nothing(tmp_path, config, monkeypatch, capsys) -> None:
    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(compare_module, "simulate", interrupted)
    out = tmp_path / "new" / "deeper" / "out"
    assert main(["compare", "--config", str(config), "--out", str(out), "--quiet"]) == 130
    assert capsys.readouterr().err.strip() == "riprs: interrupted"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["config.toml"]


def test_results_replace_earlier_ones_and_the_report_names_the_directory(
    tmp_path, config, monkeypatch, capsys
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["compare", "--config", str(config), "--out", "res", "--no-plots"]) == 0
    first = (tmp_path / "res" / "summary.csv").read_text()
    assert capsys.readouterr().out.strip().endswith(f"wrote 2 files to {tmp_path / 'res'}")
    assert (tmp_path / "res").stat().st_mode & 0o077, "the result directory is not private"
    code = main(["compare", "--config", str(config), "--out", "res", "--seed", "4", "--no-plots"])
    assert code == 0
    assert (tmp_path / "res" / "summary.csv").read_text() != first
    assert sorted(p.name for p in (tmp_path / "res").iterdir()) == [
        "summary.csv",
        "trajectories.csv",
    ]


def test_log_overlays_are_written_with_the_rest(tmp_path, config, capsys) -> None:
    rows = "\n".join(
        f"{k * 0.01:.2f},{k},{0.001 * k:.4f},0.01,1.0,0.5,30,80,0" for k in range(50)
    )
    log = tmp_path / "run.csv"
    log.write_text(
        "# rip-rt: 0.1.0\nt,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status\n"
        + rows
        + "\n"
    )
    out = tmp_path / "out"
    assert main(["compare", "--config", str(config), "--out", str(out), "--log", str(log)]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert "arm_angle_with_logs.png" in names and "control_voltage_with_logs.svg" in names
    assert capsys.readouterr().out.strip().endswith(f"wrote {len(names)} files to {out}")

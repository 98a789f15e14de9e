"""One lookup of rip-rt (riprs._binaries) for the CLI, the examples, the tests and the docs:
$RIP_RT, then the installed console script, then cargo's release build wherever cargo puts it
(``CARGO_TARGET_DIR`` included, as ``cargo metadata`` reports it)."""

from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path

import pytest

from riprs import _binaries

ROOT = Path(__file__).resolve().parents[1]

needs_cargo = pytest.mark.skipif(shutil.which("cargo") is None, reason="cargo is not installed")


def _executable(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("#!/bin/sh\necho fake rip-rt\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return path


@pytest.fixture()
def nothing_installed(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """No $RIP_RT, no console script beside the interpreter or on PATH."""
    monkeypatch.delenv("RIP_RT", raising=False)
    empty = tmp_path / "empty-bin"
    empty.mkdir()
    monkeypatch.setattr(_binaries.sysconfig, "get_path", lambda name: str(empty))
    cargo = shutil.which("cargo")
    # Keep cargo reachable, and nothing else that could be a rip-rt.
    monkeypatch.setenv("PATH", os.pathsep.join([str(empty), str(Path(cargo).parent)] if cargo
                                               else [str(empty)]))  # fmt: skip
    if cargo and shutil.which("rip-rt"):
        pytest.skip("a rip-rt sits next to cargo; the fallback cannot be isolated here")


def test_rip_rt_env_wins(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    exe = _executable(tmp_path / "my-rip-rt")
    monkeypatch.setenv("RIP_RT", str(exe))
    assert _binaries.rip_rt_path() == exe


def test_a_missing_rip_rt_env_is_named(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("RIP_RT", str(tmp_path / "nope"))
    with pytest.raises(FileNotFoundError, match="RIP_RT="):
        _binaries.rip_rt_path()


def test_the_installed_script_comes_next(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.delenv("RIP_RT", raising=False)
    scripts = tmp_path / "venv-bin"
    exe = _executable(scripts / "rip-rt")
    monkeypatch.setattr(_binaries.sysconfig, "get_path", lambda name: str(scripts))
    assert _binaries.rip_rt_path(workspace=ROOT) == exe


@needs_cargo
def test_cargo_target_dir_is_followed(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, nothing_installed: None
) -> None:
    target = tmp_path / "elsewhere"
    monkeypatch.setenv("CARGO_TARGET_DIR", str(target))
    assert _binaries.cargo_target_dir(ROOT) == target
    assert _binaries.find_rip_rt(workspace=ROOT) is None
    exe = _executable(target / "release" / "rip-rt")
    assert _binaries.rip_rt_path(workspace=ROOT) == exe
    # Without the variable, cargo's own default under the workspace.
    monkeypatch.delenv("CARGO_TARGET_DIR")
    default = _binaries.cargo_target_dir(ROOT)
    assert default is not None and default.resolve() != target.resolve()


def test_nothing_found_says_how_to_get_it(tmp_path: Path, nothing_installed: None) -> None:
    how = r"install riprs with pip.*cargo build --release -p rip-rt"
    with pytest.raises(FileNotFoundError, match=how):
        _binaries.rip_rt_path(workspace=tmp_path)  # not a cargo workspace

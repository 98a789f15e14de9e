"""Where the ``rip-rt`` program is: one rule for the CLI, the examples, the tests and the docs.

In order:

1. ``$RIP_RT``, when set (it must name an existing file);
2. the ``rip-rt`` console script that ``pip install`` put beside this interpreter (the
   environment's scripts directory), then any ``rip-rt`` on ``PATH``;
3. in a source checkout, the binary cargo built: ``release/rip-rt`` under the target directory
   that ``cargo metadata`` reports (so ``CARGO_TARGET_DIR`` and ``build.target-dir`` are
   followed), built with ``cargo build --release -p rip-rt`` first if asked to.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sysconfig
from pathlib import Path

__all__ = ["cargo_target_dir", "find_rip_rt", "rip_rt_path"]

NAME = "rip-rt"

# A checkout has the workspace manifest two levels above the package (python/riprs/).
_CHECKOUT = Path(__file__).resolve().parents[2]


def _workspace() -> Path | None:
    manifest = _CHECKOUT / "Cargo.toml"
    return _CHECKOUT if manifest.is_file() and (_CHECKOUT / "crates" / NAME).is_dir() else None


def cargo_target_dir(workspace: Path | None = None) -> Path | None:
    """The target directory cargo uses for the checkout, or None outside one (or without cargo).

    Parameters
    ----------
    workspace : pathlib.Path, optional
        The workspace root; default: the checkout this package was imported from.

    Returns
    -------
    pathlib.Path or None
        ``cargo metadata``'s ``target_directory``.
    """
    root = workspace if workspace is not None else _workspace()
    if root is None or shutil.which("cargo") is None:
        return None
    try:
        proc = subprocess.run(
            ["cargo", "metadata", "--format-version", "1", "--no-deps", "--offline"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        return Path(json.loads(proc.stdout)["target_directory"])
    except (OSError, subprocess.SubprocessError, ValueError, KeyError):
        return None


def _on_path() -> Path | None:
    scripts = sysconfig.get_path("scripts")
    beside = Path(scripts) / NAME if scripts else None
    if beside is not None and beside.is_file() and os.access(beside, os.X_OK):
        return beside
    found = shutil.which(NAME)
    return Path(found) if found else None


def find_rip_rt(build: bool = False, workspace: Path | None = None) -> Path | None:
    """The ``rip-rt`` to run (module docstring), or None if there is none.

    Parameters
    ----------
    build : bool, default False
        In a checkout without an installed ``rip-rt``, run ``cargo build --release -p rip-rt``
        when the binary is missing.
    workspace : pathlib.Path, optional
        The cargo workspace to fall back to; default: the checkout this package was imported
        from, if it was (an installed package is not in one: the tests pass their own).

    Returns
    -------
    pathlib.Path or None
        The executable.

    Raises
    ------
    FileNotFoundError
        ``$RIP_RT`` is set but names no file.
    subprocess.CalledProcessError
        The build was asked for and failed.
    """
    env = os.environ.get("RIP_RT")
    if env:
        path = Path(env)
        if not path.is_file():
            raise FileNotFoundError(f"RIP_RT={env!r} is not a file")
        return path
    installed = _on_path()
    if installed is not None:
        return installed
    root = workspace if workspace is not None else _workspace()
    target = cargo_target_dir(root)
    if root is None or target is None:
        return None
    exe = target / "release" / NAME
    if not exe.is_file() and build:
        subprocess.run(
            ["cargo", "build", "--release", "-p", NAME], cwd=root, check=True, timeout=1800
        )
    return exe if exe.is_file() else None


def rip_rt_path(build: bool = False, workspace: Path | None = None) -> Path:
    """The ``rip-rt`` to run, like :func:`find_rip_rt`, or a clear error if there is none.

    Parameters
    ----------
    build : bool, default False
        Build it with cargo in a checkout where it is missing.
    workspace : pathlib.Path, optional
        The cargo workspace to fall back to (:func:`find_rip_rt`).

    Returns
    -------
    pathlib.Path
        The executable.

    Raises
    ------
    FileNotFoundError
        No ``rip-rt`` was found; the message says how to get one.
    """
    exe = find_rip_rt(build=build, workspace=workspace)
    if exe is None:
        raise FileNotFoundError(
            "rip-rt not found: install riprs with pip (it provides the rip-rt command), "
            "build it with `cargo build --release -p rip-rt`, or set RIP_RT to its path"
        )
    return exe

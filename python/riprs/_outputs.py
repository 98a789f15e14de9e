"""Files written together (a rig or tuned file and the file beside it that only makes sense
with it): checked before the work that produces them, and written both or neither.

``riprs tune`` and ``riprs identify`` spend seconds to minutes computing what they write, so
:func:`check` finds a directory in the way, a parent that cannot take the files, or the input
itself among the outputs before that work begins; :func:`write` stages every file in its
destination's directory and moves them into place only when all are staged, putting back what
was there if a later move fails, so no half-written file or stray temporary file is left.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import List, Sequence, Tuple, Union

from riprs._riprs import RiprsError

PathLike = Union[str, "os.PathLike[str]"]


class OutputError(RiprsError):
    """An output file cannot be written where it was asked for; the message begins with the
    argument that named it (``key``)."""

    def __init__(self, message: str, *, key: str) -> None:
        super().__init__(f"{key}: {message}")
        self.key = key


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check(
    outputs: Sequence[PathLike],
    *,
    key: str,
    inputs: Sequence[PathLike] = (),
    overwrite: bool = False,
    force: str | None = None,
) -> List[Path]:
    """Check that ``outputs`` can be written, before the work that produces them.

    Parameters
    ----------
    outputs : sequence of path-like
        The files to write (the first is the one the caller named).
    key : str
        The argument that named them, which every message begins with.
    inputs : sequence of path-like
        Files the work reads: an output that is one of them (by any path, a link included)
        is refused unless ``overwrite``.
    overwrite : bool
        Allow an output to replace an input.
    force : str, optional
        How the caller asks to overwrite (``"--force"``, ``"overwrite=True"``), named in the
        message; without it an input is never overwritten.

    Returns
    -------
    list of pathlib.Path
        The outputs as paths.

    Raises
    ------
    OutputError
        An empty path, a directory in the way, a parent that is no directory or not
        writable, or an input among the outputs.
    """
    paths = []
    for out in outputs:
        text = os.fspath(out)
        if not text.strip():
            raise OutputError("the output file is an empty path", key=key)
        path = Path(text).expanduser()
        if path.is_dir():
            raise OutputError(f"{path} is a directory; name a file to write", key=key)
        base = path.absolute().parent
        while not base.exists():
            base = base.parent
        if not base.is_dir():
            raise OutputError(f"{base} is not a directory", key=key)
        if not os.access(base, os.W_OK | os.X_OK):
            raise OutputError(f"{base} is not writable", key=key)
        for source in inputs:
            if not overwrite and _same(path, Path(os.fspath(source))):
                how = f"; pass {force} to replace it" if force else ""
                raise OutputError(
                    f"{path} is the input file {os.fspath(source)}, which would be "
                    f"overwritten{how}",
                    key=key,
                )
        paths.append(path)
    return paths


def _mode(path: Path) -> int:
    """The permissions a file written at ``path`` gets: those of the file it replaces, or
    the usual ones for a new file (temporary files are private)."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def write(files: Sequence[Tuple[Path, str]]) -> None:
    """Write every ``(path, text)`` of ``files``, or none of them.

    Each text is staged in a temporary file beside its destination, then all are moved into
    place; if a move fails, the destinations already moved are put back as they were (or
    removed, where there was nothing). Temporary files never outlive the call, whatever ends
    it (an error, Ctrl-C).
    """
    staged: List[Tuple[Path, Path]] = []
    kept: List[Tuple[Path, Path | None]] = []
    created: List[Path] = []
    moved: List[Path] = []
    try:
        for path, text in files:
            missing = [p for p in [path.parent, *path.parent.parents] if not p.exists()]
            for p in reversed(missing):
                p.mkdir()
                created.append(p)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            staged.append((Path(tmp), path))
            with os.fdopen(fd, "w") as fh:
                fh.write(text)
            os.chmod(tmp, _mode(path))
        # What each destination held, to put back if a later move fails.
        for _tmp, path in staged:
            if path.exists():
                fd, backup = tempfile.mkstemp(
                    prefix=f".{path.name}.", suffix=".old", dir=path.parent
                )
                os.close(fd)
                shutil.copy2(path, backup)
                kept.append((path, Path(backup)))
            else:
                kept.append((path, None))
        for tmp, path in staged:
            os.replace(tmp, path)
            moved.append(path)
    except BaseException:
        for path, backup in reversed(kept):
            if path not in moved:
                continue
            try:
                if backup is not None:
                    os.replace(backup, path)
                else:
                    path.unlink()
            except OSError:
                pass
        for p in reversed(created):
            shutil.rmtree(p, ignore_errors=True)
        raise
    finally:
        for tmp, _path in staged:
            tmp.unlink(missing_ok=True)
        for _path, backup in kept:
            if backup is not None:
                backup.unlink(missing_ok=True)

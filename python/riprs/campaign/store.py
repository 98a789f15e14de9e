"""Results on disk: Parquet chunks written atomically, the manifest, resume."""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import platform
import re
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Union

import numpy as np

from riprs import __version__
from riprs.campaign.spec import Campaign, CampaignError

__all__ = ["load"]

PathLike = Union[str, "os.PathLike[str]"]



_EXTRA = "pip install 'riprs[campaign]'"
_CHUNK_FILE = re.compile(r"^part-(\d{10})-(\d{10})\.parquet$")
# 2: "sessions" (engine, versions and start of each call that wrote runs) in place of
# "engines"; "versions" are those of the first session.
_MANIFEST_FORMAT = 2


# -- results on disk ----------------------------------------------------------------------------


def _require_arrow() -> Any:
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise CampaignError(
            f"riprs campaign writes Parquet with pyarrow, which is not installed: {_EXTRA}"
        ) from None
    return pyarrow


def _to_table(columns: Mapping[str, Any]) -> Any:
    pa = _require_arrow()
    arrays = {}
    for name, values in columns.items():
        if name == "controller":
            arrays[name] = pa.array(list(values), type=pa.string())
        elif name in ("fall_time", "settle_time"):
            # Missing (no fall, never settled) is null, so that equal results compare equal.
            values = np.asarray(values, dtype=np.float64)
            arrays[name] = pa.array(values, mask=np.isnan(values))
        else:
            arrays[name] = pa.array(np.asarray(values))
    return pa.table(arrays)


def _chunk_path(runs_dir: Path, start: int, stop: int) -> Path:
    return runs_dir / f"part-{start:010d}-{stop:010d}.parquet"


def _write_chunk(runs_dir: Path, start: int, stop: int, columns: Mapping[str, Any]) -> Path:
    """Write one chunk atomically: a reader sees the whole file or none."""
    import pyarrow.parquet as pq

    path = _chunk_path(runs_dir, start, stop)
    tmp = runs_dir / f".{path.name}.{os.getpid()}.tmp"
    try:
        pq.write_table(_to_table(columns), tmp)
        os.replace(tmp, path)
    except BaseException:
        # Ctrl-C or a full disk mid-write: the chunk is not on disk and will be run again.
        tmp.unlink(missing_ok=True)
        raise
    return path


def _read_chunk(runs_dir: Path, start: int, stop: int) -> dict[str, np.ndarray]:
    """The columns of one chunk file that :class:`~riprs.campaign.plots.Aggregates` sums."""
    import pyarrow.parquet as pq

    from riprs.campaign.plots import Aggregates

    wanted = ["run", "fell", "diverged", *(m for m in Aggregates.METRICS if m != "fall_rate")]
    table = pq.read_table(_chunk_path(runs_dir, start, stop), columns=wanted)
    return {n: np.asarray(table.column(n).to_numpy(zero_copy_only=False)) for n in wanted}


def _done_ranges(runs_dir: Path, total: int) -> list[tuple[int, int]]:
    """The run ranges of the chunk files in ``runs_dir``, sorted."""
    ranges = []
    for p in sorted(runs_dir.iterdir()) if runs_dir.is_dir() else []:
        m = _CHUNK_FILE.match(p.name)
        if m is None:
            continue
        start, stop = int(m.group(1)), int(m.group(2))
        if not 0 <= start < stop <= total:
            raise CampaignError(f"{p}: runs {start}..{stop} are outside this campaign's 0..{total}")
        ranges.append((start, stop))
    ranges.sort()
    for (a0, a1), (b0, _) in itertools.pairwise(ranges):
        if b0 < a1:
            raise CampaignError(f"{runs_dir}: chunks {a0}..{a1} and {b0}.. overlap")
    return ranges


def _pending(
    done: Sequence[tuple[int, int]], total: int, size: int
) -> Iterator[tuple[int, int]]:
    """The runs not on disk, cut into chunks of at most ``size`` runs, generated as they are
    taken: a campaign of millions of chunks never lists them all."""
    cursor = 0
    for start, stop in [*done, (total, total)]:
        for a in range(cursor, start, size):
            yield (a, min(a + size, start))
        cursor = max(cursor, stop)


def _versions(engine: str) -> dict[str, str]:
    versions = {
        "riprs": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "pyarrow": _require_arrow().__version__,
    }
    if engine != "in-process":
        import dask
        import distributed

        versions["dask"] = dask.__version__
        versions["distributed"] = distributed.__version__
    return versions


def _check_out(campaign: Campaign, out: Path) -> dict[str, Any] | None:
    """The manifest ``out`` holds for this campaign (None for a new directory); refuses a
    directory that holds another spec's results, results of another riprs version (a run's
    numbers are riprs's: two versions are never mixed in one table) or anything else.
    Changes nothing."""
    manifest_path = out / "manifest.json"
    if manifest_path.exists():
        try:
            previous: dict[str, Any] = json.loads(manifest_path.read_text())
            old_hash = previous["spec_hash"]
        except (ValueError, KeyError, TypeError) as exc:
            raise CampaignError(f"{manifest_path}: unreadable manifest ({exc})") from None
        if old_hash != campaign.spec_hash:
            raise CampaignError(
                f"{out} holds results of another spec (hash {old_hash[:12]}, this spec "
                f"{campaign.spec_hash[:12]}); choose another --out or remove {out}"
            )
        versions = previous.get("versions")
        old = versions.get("riprs") if isinstance(versions, dict) else None
        if old != __version__:
            raise CampaignError(
                f"{out} holds results of riprs {old or '(version not recorded)'} and this is "
                f"riprs {__version__}; runs of two versions are not mixed: finish it with riprs "
                f"{old or 'that version'}, or start anew with another --out (or remove {out})"
            )
        return previous
    if out.exists() and (not out.is_dir() or any(p.name != ".lock" for p in out.iterdir())):
        raise CampaignError(f"{out} exists, is not an empty directory and holds no manifest")
    return None


def _write_manifest(
    campaign: Campaign,
    out: Path,
    engine: str,
    spec_text: str | None,
    previous: dict[str, Any] | None,
) -> None:
    """Create ``out`` and (re)write its manifest and spec copy, each atomically."""
    (out / "runs").mkdir(parents=True, exist_ok=True)
    # Left by a process killed mid-write (SIGKILL, power loss); its chunk is run again.
    for stale in (out / "runs").glob(".part-*.tmp"):
        stale.unlink(missing_ok=True)
    previous = previous or {}
    session = {
        "engine": engine,
        "versions": _versions(engine),
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    # Format 1 kept only the engines of earlier calls.
    earlier = previous.get("sessions", [{"engine": e} for e in previous.get("engines", [])])
    manifest = {
        "format": _MANIFEST_FORMAT,
        "spec_hash": campaign.spec_hash,
        "runs": campaign.runs,
        "controllers": campaign.controllers,
        "seeds": campaign.seeds,
        "axes": [
            {"name": a.name, "values": a.values.tolist(), "relative": a.relative}
            for a in campaign.axes
        ],
        "engine": engine,
        "versions": previous.get("versions", session["versions"]),
        "sessions": [*earlier, session],
        "created": previous.get("created", session["started"]),
        "updated": session["started"],
        "spec": campaign.data,
    }
    tmp = out / ".manifest.json.tmp"
    tmp.write_text(json.dumps(manifest, indent=2, default=str) + "\n")
    os.replace(tmp, out / "manifest.json")
    if spec_text is not None:
        tmp = out / ".spec.toml.tmp"
        tmp.write_text(spec_text)
        os.replace(tmp, out / "spec.toml")


@contextlib.contextmanager
def _exclusive(out: Path) -> Iterator[None]:
    """Hold ``out``'s lock: one campaign process writes a directory at a time."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no lock
        yield
        return
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "a") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise CampaignError(f"another riprs campaign is writing to {out}") from None
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def load(out: PathLike) -> Any:
    """The results of a campaign directory as one ``pyarrow.Table`` sorted by ``run``."""
    import pyarrow.parquet as pq

    pa = _require_arrow()
    runs_dir = Path(out) / "runs"
    files = [p for p in sorted(runs_dir.glob("part-*.parquet")) if _CHUNK_FILE.match(p.name)]
    if not files:
        raise CampaignError(f"{runs_dir} holds no results")
    table = pa.concat_tables([pq.read_table(p) for p in files])
    return table.sort_by("run")

"""Reading the CSV logs written by ``rip-rt run --log FILE.csv``.

The format is documented in ``docs/rip-rt.md``: comment lines ``# key: value`` (a header
before the column row and a footer with the stop reason and timing figures), one column row,
then one row per control period.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Dict, List, Union

import numpy as np

from riprs._riprs import RiprsError

# Bits of the ``status`` column above the device's own eight status bits.
FLAG_NO_REPLY = 1 << 8
FLAG_FALLBACK = 1 << 9
FLAG_CLAMPED = 1 << 10  # the command is at the voltage limit
FLAG_DEADLINE_MISS = 1 << 11

_REQUIRED = ("t", "seq", "theta", "alpha", "theta_ref", "u", "compute_us", "jitter_us", "status")


class LogError(RiprsError):
    """A file is not a readable ``rip-rt`` log; the message names the file, line and column."""


@dataclasses.dataclass(frozen=True)
class RtLog:
    """A ``rip-rt`` run: one entry per control period, numpy float64 unless noted.

    Attributes
    ----------
    t : seconds since balancing started.
    seq : sequence number of the sample request (int64).
    theta, alpha : measured arm and pendulum angle (rad; pendulum 0 = upright).
    theta_ref : arm reference (rad).
    u : commanded voltage (V).
    xhat : controller state estimate, shape (n, n_states); n_states is 0 when the controller
        logs none. Rows without a measurement hold NaN.
    compute_us : decode → command encoded time (µs).
    jitter_us : wake-up lateness relative to the period's deadline (µs).
    status : device status bits | ``FLAG_*`` bits (int64).
    meta : the ``# key: value`` comment lines (header and footer).
    """

    t: np.ndarray
    seq: np.ndarray
    theta: np.ndarray
    alpha: np.ndarray
    theta_ref: np.ndarray
    u: np.ndarray
    xhat: np.ndarray
    compute_us: np.ndarray
    jitter_us: np.ndarray
    status: np.ndarray
    meta: Dict[str, str]

    @property
    def y(self) -> np.ndarray:
        """Measured outputs ``[theta, alpha]``, shape (n, 2)."""
        return np.column_stack([self.theta, self.alpha])

    @property
    def stop_reason(self) -> str | None:
        """Why the run stopped (``finished``, ``signal``, ``watchdog``, ...), if recorded."""
        return self.meta.get("stop")


def load_log(path: Union[str, os.PathLike[str]]) -> RtLog:
    """Read a ``rip-rt`` CSV log.

    Raises
    ------
    OSError
        If the file cannot be read.
    LogError
        If it is not a ``rip-rt`` log (not text, missing columns, or a row that does not
        parse); the message names the file, the line and the column. A ``ValueError``.
    """
    try:
        return _parse(path)
    except UnicodeDecodeError as exc:
        raise LogError(f"{os.fspath(path)}: not a rip-rt log (not UTF-8 text: {exc})") from None


def _parse(path: Union[str, os.PathLike[str]]) -> RtLog:
    meta: Dict[str, str] = {}
    columns: List[str] | None = None
    rows: List[List[float]] = []
    with open(path, encoding="utf-8") as fh:
        for lineno, raw in enumerate(fh, start=1):
            line = raw.rstrip("\r\n")
            if not line:
                continue
            if line.startswith("#"):
                key, sep, value = line[1:].strip().partition(":")
                if sep:
                    meta[key.strip()] = value.strip()
                continue
            fields = line.split(",")
            if columns is None:
                columns = fields
                missing = [c for c in _REQUIRED if c not in columns]
                if missing:
                    raise LogError(
                        f"{path}: line {lineno}: not a rip-rt log, missing columns {missing}"
                    )
                continue
            if len(fields) != len(columns):
                raise LogError(
                    f"{path}: line {lineno}: {len(fields)} fields, expected {len(columns)}"
                )
            row = []
            for name, value in zip(columns, fields, strict=True):
                try:
                    row.append(float(value) if value else float("nan"))
                except ValueError:
                    raise LogError(
                        f"{path}: line {lineno}: column {name!r}: not a number: {value!r}"
                    ) from None
            rows.append(row)
    if columns is None:
        raise LogError(f"{path}: not a rip-rt log (no column row)")
    data = np.array(rows, dtype=np.float64).reshape(len(rows), len(columns))
    index = {name: i for i, name in enumerate(columns)}
    xhat_cols = sorted(
        (c for c in columns if c.startswith("xhat_")), key=lambda c: int(c.split("_")[1])
    )

    def col(name: str) -> np.ndarray:
        return data[:, index[name]].copy()

    xhat = (
        np.column_stack([col(c) for c in xhat_cols])
        if xhat_cols
        else np.zeros((len(rows), 0))
    )
    return RtLog(
        t=col("t"),
        seq=col("seq").astype(np.int64),
        theta=col("theta"),
        alpha=col("alpha"),
        theta_ref=col("theta_ref"),
        u=col("u"),
        xhat=xhat,
        compute_us=col("compute_us"),
        jitter_us=col("jitter_us"),
        status=col("status").astype(np.int64),
        meta=meta,
    )


__all__ = [
    "FLAG_CLAMPED",
    "FLAG_DEADLINE_MISS",
    "FLAG_FALLBACK",
    "FLAG_NO_REPLY",
    "RtLog",
    "load_log",
]

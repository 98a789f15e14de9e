"""Reading the CSV logs written by ``rip-rt run --log FILE.csv``.

The format is documented in ``docs/rip-rt.md``: comment lines ``# key: value`` (a header
before the column row and a footer with the stop reason and timing figures), one column row,
then one row per control period.
"""

from __future__ import annotations

import dataclasses
import io
import os
import warnings
from typing import Any, Dict, List, Union

import numpy as np

from riprs._riprs import RiprsError

# Bits of the ``status`` column above the device's own eight status bits.
FLAG_NO_REPLY = 1 << 8
FLAG_FALLBACK = 1 << 9
FLAG_CLAMPED = 1 << 10  # the command is at the voltage limit
FLAG_DEADLINE_MISS = 1 << 11

_REQUIRED = ("t", "seq", "theta", "alpha", "theta_ref", "u", "compute_us", "jitter_us", "status")

#: The values of the ``phase`` column: the controller's phase after the period's step in
#: ``rip-rt run``; the experiment's stage in ``rip-rt excite``. A ``rip-rt run --swing-up`` log
#: starts with ``sign_check`` rows too (the pulse before the swing, :data:`EXCITE_PHASES`).
RUN_PHASES = ("swing_up", "balance", "stopped")
#: The stages of ``rip-rt excite``: the sign check, then the signal (free swing: kick, coast).
EXCITE_PHASES = ("sign_check", "chirp", "prbs", "steps", "kick", "coast")
PHASES = RUN_PHASES + EXCITE_PHASES
# Logs written before the column existed are of balancing runs only.
_DEFAULT_PHASE = "balance"
_PHASE_DTYPE = f"U{max(len(p) for p in PHASES)}"


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
    phase : the controller's phase after the period's step, one of :data:`PHASES` (numpy
        strings): ``sign_check`` during a swing-up's sign check, ``swing_up`` until its catch,
        then ``balance``. Logs written before this column existed read as ``balance``
        throughout. An excitation log
        (``rip-rt excite``) holds its stages, :data:`EXCITE_PHASES`.
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
    phase: np.ndarray
    meta: Dict[str, str]

    @property
    def y(self) -> np.ndarray:
        """Measured outputs ``[theta, alpha]``, shape (n, 2)."""
        return np.column_stack([self.theta, self.alpha])

    @property
    def catch_index(self) -> int | None:
        """Index of the first row in the ``balance`` phase after ``swing_up`` rows (a swing-up's
        catch), or ``None``."""
        swinging = self.phase == "swing_up"
        after = np.flatnonzero(~swinging[1:] & swinging[:-1] & (self.phase[1:] == "balance"))
        return int(after[0]) + 1 if after.size else None

    @property
    def stop_reason(self) -> str | None:
        """Why the run stopped (``finished``, ``signal``, ``watchdog``, ...), if recorded."""
        return self.meta.get("stop")


def load_log(path: Union[str, os.PathLike[str]]) -> RtLog:
    """Read a ``rip-rt`` CSV log.

    The file is read in blocks of about 1 MB, each parsed by numpy's C parser straight into
    preallocated typed columns (``seq`` and ``status`` int64, ``phase`` text, the rest float64;
    an empty cell is NaN), so memory stays close to that of the result: a 2-million-row log of
    an LQG run (214 MB of arrays) peaks about 12 MB above its arrays.
    A UTF-8 byte-order mark is accepted; columns not listed in :class:`RtLog` are ignored.

    Raises
    ------
    OSError
        If the file cannot be read.
    LogError
        If it is not a ``rip-rt`` log: not UTF-8 text, missing, repeated or misnamed columns
        (estimate columns are ``xhat_0``, ``xhat_1``, ...), a row with the wrong number of
        fields, a cell that is not a number (``seq`` and ``status``: not an integer in the
        int64 range), or a ``phase`` not in :data:`PHASES`. The message names the file, the line
        and the column. A ``ValueError``.
    """
    return _Reader(os.fspath(path)).read()


_BOM = b"\xef\xbb\xbf"
_INT_COLUMNS = ("seq", "status")
# Bytes per parsing block: bounds the temporary text and parsed table (a few MB).
_BLOCK_BYTES = 1 << 20
# A rip-rt row is a few hundred bytes.
_MAX_ROW_BYTES = 1 << 14


class _Reader:
    def __init__(self, path: str) -> None:
        self.path = path
        self.meta: Dict[str, str] = {}

    def fail(self, lineno: int | None, message: str) -> LogError:
        where = f"{self.path}: line {lineno}" if lineno is not None else self.path
        return LogError(f"{where}: {message}")

    def comment(self, raw: bytes, lineno: int) -> None:
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise self.fail(lineno, f"not a rip-rt log (not UTF-8 text: {exc})") from None
        key, sep, value = line[1:].strip().partition(":")
        if sep:
            self.meta[key.strip()] = value.strip()

    def header(self, raw: bytes, lineno: int) -> List[str]:
        try:
            names = [c.strip() for c in raw.decode("utf-8").rstrip("\r\n").split(",")]
        except UnicodeDecodeError as exc:
            raise self.fail(lineno, f"not a rip-rt log (not UTF-8 text: {exc})") from None
        missing = [c for c in _REQUIRED if c not in names]
        if missing:
            raise self.fail(lineno, f"not a rip-rt log, missing columns {missing}")
        seen = set()
        for name in names:
            if name in seen:
                raise self.fail(lineno, f"column {name!r} appears twice")
            seen.add(name)
        estimates = [c for c in names if c.startswith("xhat_")]
        for name in estimates:
            suffix = name[len("xhat_") :]
            if not (suffix.isascii() and suffix.isdigit()) or int(suffix) >= len(estimates):
                raise self.fail(
                    lineno,
                    f"column {name!r}: state-estimate columns are named xhat_0 to "
                    f"xhat_{len(estimates) - 1} (one per estimated state)",
                )
        return names

    def read(self) -> RtLog:
        with open(self.path, "rb") as fh:
            # A first pass counts lines, so every column is allocated once at (nearly) its
            # final size and filled in place: no list of rows, no growing and copying.
            capacity = sum(chunk.count(b"\n") for chunk in iter(lambda: fh.read(1 << 22), b""))
            fh.seek(0)
            return self._parse(fh, capacity + 1)

    def _parse(self, fh: Any, capacity: int) -> RtLog:
        names: List[str] | None = None
        lineno = 0
        while names is None:
            raw = fh.readline()
            if not raw:
                raise self.fail(None, "not a rip-rt log (no column row)")
            lineno += 1
            if lineno == 1:
                raw = raw.removeprefix(_BOM)
            if raw.startswith(b"#"):
                self.comment(raw, lineno)
            elif raw.strip():
                names = self.header(raw, lineno)
        out = self._allocate(names, capacity)
        dtype = np.dtype(
            [
                (f"c{j}", _column_dtype(name))
                for j, name in enumerate(names)
            ]
        )
        rows = 0
        carry = b""
        while True:
            chunk = fh.read(_BLOCK_BYTES)
            if not chunk and not carry:
                break
            buffer = carry + chunk
            if chunk:
                cut = buffer.rfind(b"\n") + 1
                if cut == 0:
                    if len(buffer) > _MAX_ROW_BYTES:
                        raise self.fail(lineno + 1, f"row longer than {_MAX_ROW_BYTES} bytes")
                    carry = buffer
                    continue
                block, carry = buffer[:cut], buffer[cut:]
            else:
                block, carry = buffer + b"\n", b""
            rows += self._block(names, dtype, block, lineno + 1, out, rows)
            lineno += block.count(b"\n")
        for array in out.values():
            array.resize((rows, *array.shape[1:]), refcheck=False)
        return RtLog(
            t=out["t"],
            seq=out["seq"],
            theta=out["theta"],
            alpha=out["alpha"],
            theta_ref=out["theta_ref"],
            u=out["u"],
            xhat=out["xhat"],
            compute_us=out["compute_us"],
            jitter_us=out["jitter_us"],
            status=out["status"],
            phase=out["phase"],
            meta=self.meta,
        )

    @staticmethod
    def _allocate(names: List[str], capacity: int) -> Dict[str, np.ndarray]:
        out = {
            name: np.empty(capacity, dtype=np.int64 if name in _INT_COLUMNS else np.float64)
            for name in _REQUIRED
        }
        n_est = sum(1 for c in names if c.startswith("xhat_"))
        out["xhat"] = np.empty((capacity, n_est), dtype=np.float64)
        out["phase"] = np.empty(capacity, dtype=_PHASE_DTYPE)
        if "phase" not in names:
            out["phase"][:] = _DEFAULT_PHASE
        return out

    def _block(
        self,
        names: List[str],
        dtype: np.dtype[Any],
        block: bytes,
        first_line: int,
        out: Dict[str, np.ndarray],
        start: int,
    ) -> int:
        """Parses the whole lines in ``block`` (the first is line ``first_line``) into
        ``out[start:]`` with numpy's C parser; returns the number of rows. On any problem the
        rows are read again one by one to name the exact line and column."""
        if b"\r" in block:
            block = block.replace(b"\r\n", b"\n")
        if block.startswith((b"#", b"\n")) or b"\n#" in block or b"\n\n" in block:
            # Comment or empty lines (the footer): set them aside, keep the line numbers.
            data, numbers = [], []
            for i, line in enumerate(block.split(b"\n")[:-1]):
                if line.startswith(b"#"):
                    self.comment(line, first_line + i)
                elif line:
                    data.append(line)
                    numbers.append(first_line + i)
            if not data:
                return 0
            text = b"\n".join(data) + b"\n"
        else:
            text = block
            numbers = None
        # An empty cell is NaN: spell it out for the parser (twice for runs of empty cells).
        # Each search is a fast scan; the copies are made only where empty cells occur.
        if b",," in text:
            text = text.replace(b",,", b",nan,").replace(b",,", b",nan,")
        if b",\n" in text:
            text = text.replace(b",\n", b",nan\n")
        if b"\n," in text:
            text = text.replace(b"\n,", b"\nnan,")
        if text.startswith(b","):
            text = b"nan" + text
        try:
            with warnings.catch_warnings():
                # numpy 1.23-1.26 read "1.0", "nan" or "1e30" into an integer column through a
                # float, with a DeprecationWarning; numpy 2 refuses them. Refused on every
                # version: such a cell is not an integer of the log format.
                warnings.filterwarnings("error", r"loadtxt\(\)", DeprecationWarning)
                table = np.loadtxt(
                    io.BytesIO(text), delimiter=",", dtype=dtype, comments=None, ndmin=1
                )
        except (ValueError, OverflowError, DeprecationWarning):
            lines = block.split(b"\n")[:-1] if numbers is None else data
            where = range(first_line, first_line + len(lines)) if numbers is None else numbers
            self._diagnose(names, lines, list(where))
            raise self.fail(first_line, "unreadable rows") from None
        end = start + len(table)
        for j, name in enumerate(names):
            if name == "phase":
                values = table[f"c{j}"]
                bad = np.flatnonzero(~np.isin(values, PHASES))
                if bad.size:
                    row = int(bad[0])
                    lineno = first_line + row if numbers is None else numbers[row]
                    raise self.fail(
                        lineno,
                        f"column 'phase': {str(values[row])!r} is not one of {list(PHASES)}",
                    )
                out["phase"][start:end] = values
            elif name.startswith("xhat_"):
                out["xhat"][start:end, int(name[len("xhat_") :])] = table[f"c{j}"]
            elif name in _REQUIRED:
                out[name][start:end] = table[f"c{j}"]
        return len(table)

    def _diagnose(self, names: List[str], data: List[bytes], data_lines: List[int]) -> None:
        """Raises the error of the first bad row of a block."""
        for raw, lineno in zip(data, data_lines, strict=True):
            fields = raw.rstrip(b"\r\n").split(b",")
            if len(fields) != len(names):
                raise self.fail(lineno, f"{len(fields)} fields, expected {len(names)}")
            for name, value in zip(names, fields, strict=True):
                shown = value.decode("utf-8", "replace")
                if name in _INT_COLUMNS:
                    if not _is_int64(value):
                        raise self.fail(
                            lineno,
                            f"column {name!r}: not an integer in the int64 range: {shown!r}",
                        )
                elif name == "phase":
                    if shown not in PHASES:
                        raise self.fail(
                            lineno, f"column 'phase': {shown!r} is not one of {list(PHASES)}"
                        )
                elif _wanted(name):
                    try:
                        float(value) if value.strip() else None
                    except ValueError:
                        raise self.fail(
                            lineno, f"column {name!r}: not a number: {shown!r}"
                        ) from None


def _wanted(name: str) -> bool:
    """Columns that are read; others are skipped (but still counted per row)."""
    return name in _REQUIRED or name == "phase" or name.startswith("xhat_")


def _column_dtype(name: str) -> str:
    if name in _INT_COLUMNS:
        return "i8"
    if name == "phase":
        # Longer than any phase, so that a wrong value is seen whole, not cut to a valid one.
        return "U16"
    return "f8" if _wanted(name) else "S1"


def _is_int64(value: bytes) -> bool:
    try:
        return -(2**63) <= int(value) < 2**63
    except ValueError:
        return False


__all__ = [
    "EXCITE_PHASES",
    "FLAG_CLAMPED",
    "FLAG_DEADLINE_MISS",
    "FLAG_FALLBACK",
    "FLAG_NO_REPLY",
    "PHASES",
    "RUN_PHASES",
    "RtLog",
    "load_log",
]

"""Checks of ``rip-rt excite`` logs before identification: size, units, signs, wild samples and
gaps, each named by its log and column (:func:`riprs.identify.identify` runs them)."""

from __future__ import annotations

import math
import os
from typing import List

import numpy as np

from riprs._riprs import RiprsError
from riprs.log import FLAG_CLAMPED, RtLog


class IdentifyError(RiprsError):
    """Logs that cannot be identified from; the message names the log and what is wrong."""


#: Fraction of clamped samples above which a log is reported as saturated.
SATURATION_WARNING = 0.02

#: Fewest samples a log must have for the fit (after the held-out part).
MIN_TRAINING_SAMPLES = 200

#: Longest run of missing samples (replies lost or late on the link) filled in by
#: interpolation: 0.1 s at 100 Hz, a fraction of the pendulum's period.
MAX_GAP = 10


#: Bytes of a log read to estimate its row count before it is read whole.
_PROBE_BYTES = 1 << 16
#: A sample this far (rad) from the median of its neighbours, and 50 times the column's
#: typical step, is a wild sample (a corrupted reading), not motion.
WILD_ANGLE = 1.0
#: A voltage beyond this (V) is no motor command.
WILD_VOLTAGE = 100.0
#: t-statistic below which the voltage and the arm's acceleration are judged of opposite sign.
SIGN_T = -3.0


def _estimated_rows(name: str, path: str) -> int:
    """Rows of the log at ``path`` estimated from its size and its first data lines, so that a
    log too large for one identification is refused before it is read whole."""
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        head = fh.read(_PROBE_BYTES)
    lines = head.split(b"\n")
    if len(head) < _PROBE_BYTES:
        return sum(1 for ln in lines if ln.strip() and not ln.startswith(b"#")) - 1
    data = [ln for ln in lines[:-1] if ln.strip() and not ln.startswith(b"#")][1:]
    if not data:
        return 0
    per_row = sum(len(ln) + 1 for ln in data) / len(data)
    return int(size / per_row)


def _wild(values: np.ndarray, limit: float) -> np.ndarray:
    """Indices of samples far from the median of their 5-sample neighbourhood: more than
    ``limit`` and 50 typical steps."""
    n = len(values)
    if n < 5:
        return np.zeros(0, dtype=np.int64)
    padded = np.concatenate([values[:2], values, values[-2:]])
    windows = np.lib.stride_tricks.sliding_window_view(padded, 5)
    with np.errstate(invalid="ignore", over="ignore"):
        dev = np.abs(values - np.median(windows, axis=1))
        step = float(np.median(np.abs(np.diff(values))))
    return np.flatnonzero(dev > max(limit, 50.0 * step))


def _check_units(name: str, log: RtLog) -> None:
    """Wild samples, angles in degrees, time in milliseconds, and the sign relation between the
    voltage and the arm's acceleration; each error names the log and the column."""
    for column in ("theta", "alpha"):
        values = getattr(log, column)
        bad = _wild(np.unwrap(values) if column == "alpha" else values, WILD_ANGLE)
        if 0 < bad.size <= max(3, len(values) // 1000):
            raise IdentifyError(
                f"{name}: column {column!r} has a wild sample at row {bad[0]} "
                f"({values[bad[0]]:.6g} rad, its neighbours about "
                f"{np.median(values[max(bad[0] - 2, 0) : bad[0] + 3]):.6g}): a corrupted reading; "
                "remove the row or repeat the run"
            )
    bad_u = np.flatnonzero(np.abs(log.u) > WILD_VOLTAGE)
    if bad_u.size:
        raise IdentifyError(
            f"{name}: column 'u' is {log.u[bad_u[0]]:.6g} V at row {bad_u[0]}: no motor command "
            f"exceeds {WILD_VOLTAGE:g} V; a corrupted reading"
        )
    if np.max(np.abs(log.theta)) > 2 * math.pi:
        raise IdentifyError(
            f"{name}: column 'theta' reaches {np.max(np.abs(log.theta)):.4g}: the arm angle looks "
            "like degrees (an arm stays within one turn; the log must be in rad)"
        )
    if np.median(np.abs(log.alpha)) > 2 * math.pi:
        raise IdentifyError(
            f"{name}: column 'alpha' is {np.median(np.abs(log.alpha)):.4g} in the median: the "
            "pendulum angle looks like degrees (hanging is pi rad; the log must be in rad)"
        )
    if len(log.t) > 1:
        dt = float(np.median(np.diff(log.t)))
        period = log.meta.get("period_ms")
        try:
            expected = float(period) / 1000.0 if period is not None else None
        except ValueError:
            expected = None
        if expected is not None and expected > 0:
            if abs(dt / expected - 1000.0) < 50.0:
                raise IdentifyError(
                    f"{name}: column 't' steps by {dt:g} but the header says period_ms: {period}: "
                    "the time column is in milliseconds; it must be in seconds"
                )
            if abs(dt / expected - 1.0) > 0.1:
                raise IdentifyError(
                    f"{name}: column 't' steps by {dt:g} s but the header says period_ms: "
                    f"{period}; the time column and the header disagree"
                )
        elif dt >= 0.5:
            raise IdentifyError(
                f"{name}: column 't' steps by {dt:g}: a sample time of half a second or more "
                "cannot identify a pendulum; the time column looks like milliseconds (it must "
                "be in seconds)"
            )
    _check_sign(name, log)


def _check_sign(name: str, log: RtLog) -> None:
    """The sign relation between voltage and arm acceleration (rip-rt excite's sign check): a
    positive voltage accelerates the arm towards positive theta. A least-squares fit of the
    arm's rate change per sample on ``[u, rate, 1]``; a clearly negative voltage coefficient is
    a negated voltage column or a reversed arm encoder."""
    if len(log.t) < 50 or np.ptp(log.u) < 0.5:
        return
    ts = float(np.median(np.diff(log.t)))
    if not ts > 0:
        return
    rate = np.diff(log.theta) / ts
    accel = np.diff(rate)
    regressors = np.column_stack([log.u[1:-1], rate[:-1], np.ones(len(accel))])
    coef, *_ = np.linalg.lstsq(regressors, accel, rcond=None)
    resid = accel - regressors @ coef
    dof = max(len(accel) - 3, 1)
    try:
        cov = np.linalg.inv(regressors.T @ regressors) * float(resid @ resid) / dof
    except np.linalg.LinAlgError:
        return
    t_stat = coef[0] / math.sqrt(max(cov[0, 0], 1e-300))
    if t_stat < SIGN_T:
        raise IdentifyError(
            f"{name}: columns 'u' and 'theta' have opposite signs: a positive voltage "
            f"decelerates the arm (t = {t_stat:.1f}); the voltage is negated or the arm encoder "
            "is reversed (swap the motor leads or the encoder's A/B, or set the sign in the "
            "calibration, and repeat the run)"
        )


def _check(name: str, log: RtLog, holdout: float) -> List[str]:
    """Refuses what cannot be fitted; returns warnings for what can."""
    notes = []
    n = len(log.t)
    if n == 0:
        raise IdentifyError(
            f"{name}: no samples: the log has a header but no rows (a run stopped before its "
            "first sample); record it again"
        )
    for column in ("t", "theta", "alpha", "u"):
        bad = np.flatnonzero(~np.isfinite(getattr(log, column)))
        if bad.size:
            raise IdentifyError(
                f"{name}: column {column!r} is not a number in {bad.size} rows (first at row "
                f"{bad[0]}); identification needs every sample"
            )
    _check_units(name, log)
    train = int((1.0 - holdout) * n)
    if train < MIN_TRAINING_SAMPLES:
        raise IdentifyError(
            f"{name}: too short: {n} samples, {train} left for the fit after the held-out part "
            f"({holdout:g}); at least {MIN_TRAINING_SAMPLES} are needed"
        )
    dt = np.diff(log.t)
    ts = float(np.median(dt))
    steps = dt / ts if ts > 0 else dt
    if not ts > 0 or np.any(np.abs(steps - np.round(steps)) > 0.25) or steps.min() < 0.5:
        raise IdentifyError(
            f"{name}: the samples are not evenly spaced (median step {ts:g} s, steps from "
            f"{dt.min():g} to {dt.max():g} s)"
        )
    if np.round(steps).max() > MAX_GAP + 1:
        raise IdentifyError(
            f"{name}: {int(np.round(steps).max()) - 1} samples in a row are missing (at "
            f"t = {log.t[int(np.argmax(steps))]:g} s); at most {MAX_GAP} are filled in"
        )
    hanging = np.abs(np.angle(np.exp(1j * log.alpha))) > math.pi / 2
    if np.mean(hanging) < 0.5:
        raise IdentifyError(
            f"{name}: the pendulum is upright in {100 * np.mean(~hanging):.0f} % of the samples: "
            "this is a balancing run, not an excitation run. Its closed loop keeps the motion "
            "too small and the open-loop simulation of an upright pendulum diverges; record "
            "excitation runs with the pendulum hanging (rip-rt excite)"
        )
    if np.ptp(log.u) < 1e-3 and np.ptp(log.theta) < 1e-3 and np.ptp(np.unwrap(log.alpha)) < 1e-3:
        raise IdentifyError(
            f"{name}: no excitation: the voltage is constant and neither angle moves, so "
            "nothing is identifiable from it"
        )
    if np.ptp(log.u) < 1e-3:
        notes.append(
            f"{name}: the voltage is constant ({log.u[0]:g} V): the motor parameters (kt, Dr, "
            "Vd) are determined by the other logs only"
        )
    clamped = np.mean((log.status & FLAG_CLAMPED) != 0) if len(log.status) else 0.0
    if clamped > SATURATION_WARNING:
        notes.append(
            f"{name}: the voltage is saturated in {100 * clamped:.0f} % of the samples: the "
            "motor received less than the logged command there, which biases kt, Dr and Vd; "
            "lower the excitation amplitude"
        )
    return notes

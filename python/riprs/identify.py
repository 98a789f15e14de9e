"""Identification of a rig from ``rip-rt excite`` logs: an output-error fit of the nonlinear
Furuta model (``rip_core::identify``), its report, figures and the ``[plant]`` file.

The model, the identifiable parameters and the criterion are documented in
``rip_core::identify``: the pendulum's mass and length (``mp``, ``Lp``), ``mr``, ``Rm``, ``km``
and ``g`` are taken from the start set and fix the scale; ``Lr``, ``Jr``, ``Jp``, ``kt``,
``Dr``, ``Dp``, Coulomb friction ``Cr``, ``Cp`` and the dead zone ``Vd`` are estimated.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from pathlib import Path
from typing import Dict, List, Sequence, Tuple, Union

import numpy as np

from riprs._riprs import FurutaParams, Plant, RiprsError, identify_logs, load_config
from riprs.log import FLAG_CLAMPED, RtLog, load_log

PathLike = Union[str, "os.PathLike[str]"]
LogLike = Union[PathLike, RtLog]

#: Fraction of clamped samples above which a log is reported as saturated.
SATURATION_WARNING = 0.02
#: Fewest samples a log must have for the fit (after the held-out part).
MIN_TRAINING_SAMPLES = 200
#: The order of ``[plant]`` keys written to an identified file.
PLANT_KEYS = ("mr", "Lr", "Jr", "mp", "Lp", "Jp", "Dr", "Dp", "Rm", "kt", "km", "Cr", "Cp", "Vd")


class IdentifyError(RiprsError):
    """Logs that cannot be identified from; the message names the log and what is wrong."""


class IdentifyWarning(UserWarning):
    """Logs that can be fitted but do not determine everything (saturation, parameters not
    identifiable); the message names the log or the parameters."""


@dataclasses.dataclass(frozen=True)
class IdentifyResult:
    """The outcome of :func:`identify`.

    Attributes
    ----------
    params : FurutaParams
        Identified parameters (the start set's fixed ones unchanged).
    start : FurutaParams
        The start set.
    preset : str
        Preset the start set is based on (written as ``preset`` in the ``[plant]`` file).
    std_errors : dict
        Standard error of each estimated parameter (same units; ``inf`` when not identifiable).
        Output-error residuals are coloured, so these are lower bounds.
    fit_percent : ndarray, shape (n_logs, 2)
        Held-out fit (%) of ``[theta, alpha]`` per log, MATLAB ``compare``'s
        ``100 (1 - |y - yhat| / |y - mean(y)|)``; NaN without a held-out part.
    training_fit_percent : ndarray, shape (n_logs, 2)
        The same over the fitted segments.
    not_identifiable : tuple of str
        Parameters the logs do not determine (relative standard error above 50 %, or in a null
        direction of the information matrix).
    at_bounds : tuple of str
        Parameters that ended on a bound (e.g. a dead zone or friction of about zero).
    condition_number, rank : float, int
        Of the parameters' information matrix (Jacobian at the optimum).
    cost, rms_residual : float
        Final sum of squared normalised residuals and its root mean square.
    iterations, simulations, segments : int
        Levenberg-Marquardt iterations, segment simulations run, training segments.
    converged : bool
        Whether the fit met its tolerance before the iteration limit.
    Ad, Bd : ndarray
        Upright linearisation of the identified plant, zero-order hold at the logs' ``Ts``.
    Ts : float
        Sample time of the logs (s).
    holdout, segment : float
        The held-out fraction and segment length used.
    names : tuple of str
        A name for each log (the file stem, or ``log i``).
    warnings : tuple of str
        Every warning issued.
    """

    params: FurutaParams
    start: FurutaParams
    preset: str
    std_errors: Dict[str, float]
    fit_percent: np.ndarray
    training_fit_percent: np.ndarray
    not_identifiable: Tuple[str, ...]
    at_bounds: Tuple[str, ...]
    condition_number: float
    rank: int
    cost: float
    rms_residual: float
    iterations: int
    converged: bool
    simulations: int
    segments: int
    Ad: np.ndarray
    Bd: np.ndarray
    Ts: float
    holdout: float
    segment: float
    names: Tuple[str, ...]
    warnings: Tuple[str, ...]

    def report(self) -> str:
        """A plain-text report: parameters with standard errors, fits, diagnostics."""
        start = self.start.to_dict()
        lines = ["Identified parameters (start value -> estimate +- standard error):"]
        for name, se in self.std_errors.items():
            value = getattr(self.params, name)
            note = ""
            if name in self.not_identifiable:
                note = "  NOT IDENTIFIABLE from these logs"
            elif name in self.at_bounds:
                note = "  at its bound"
            lines.append(
                f"  {name:3s} {start[name]:12.5g} -> {value:12.5g} +- {se:9.2g}"
                + (f" ({100 * se / value:.1f} %)" if value > 0 and math.isfinite(se) else "")
                + note
            )
        fixed = [n for n in ("mp", "Lp", "mr", "Rm", "km", "g") if n not in self.std_errors]
        lines.append(
            "  not estimated (start set; see the warnings if one changed): "
            + ", ".join(f"{n} = {getattr(self.params, n):.5g}" for n in fixed)
        )
        lines.append("")
        lines.append("Fit (%) per log, theta / alpha: held-out | training")
        for name, fit, train in zip(
            self.names, self.fit_percent, self.training_fit_percent, strict=True
        ):
            lines.append(
                f"  {name}: {fit[0]:6.1f} / {fit[1]:6.1f} | {train[0]:6.1f} / {train[1]:6.1f}"
            )
        lines.append("")
        lines.append(
            f"{self.iterations} iterations ({'converged' if self.converged else 'NOT converged'}),"
            f" {self.simulations} segment simulations, {self.segments} segments of "
            f"{self.segment:g} s; information matrix rank {self.rank}/{len(self.std_errors)}, "
            f"condition number {self.condition_number:.3g}"
        )
        lines.append(f"A_d, B_d of the upright linearisation at Ts = {self.Ts:g} s:")
        for i in range(4):
            row = " ".join(f"{v:11.6f}" for v in self.Ad[i])
            lines.append(f"  {row} | {self.Bd[i, 0]:11.6f}")
        for w in self.warnings:
            lines.append(f"warning: {w}")
        return "\n".join(lines)

    def to_toml(self, source: str = "") -> str:
        """The ``[plant]`` file of the identified rig (read by ``riprs compare --config``,
        ``rip-rt run --config`` and ``rip-rt emulate --config``)."""
        p = self.params.to_dict()
        head = [f"# Identified by riprs identify{' from ' + source if source else ''}."]
        head.append(
            "# Held-out fit (theta/alpha %): "
            + "; ".join(
                f"{n} {f[0]:.1f}/{f[1]:.1f}"
                for n, f in zip(self.names, self.fit_percent, strict=True)
            )
        )
        if self.not_identifiable:
            head.append("# Not identifiable from the logs: " + ", ".join(self.not_identifiable))
        body = ["[plant]", f'preset = "{self.preset}"']
        body += [f"{k} = {p[k]!r}" for k in PLANT_KEYS]
        return "\n".join(head + body) + "\n"

    def simulate(self, log: RtLog) -> np.ndarray:
        """The identified model's angles for ``log``, shape (n, 2): simulated in pieces of
        :attr:`segment` seconds, each from the state measured at its start (rates by central
        differences). For figures; the fit itself estimates each piece's initial state."""
        ts, u, y = _arrays(log)
        plant = Plant(self.params)
        n = len(u)
        step = max(1, round(self.segment / ts))
        out = np.empty((n, 2))
        for k0 in range(0, n, step):
            k1 = min(n, k0 + step)
            a, b = max(k0 - 1, 0), min(k0 + 1, n - 1)
            rate = (y[b] - y[a]) / ((b - a) * ts)
            x0 = [y[k0, 0], rate[0], y[k0, 1], rate[1]]
            traj = plant.integrate(x0, u[k0 : k1 - 1], ts, 4)
            out[k0:k1] = traj[:, [0, 2]]
        return out


#: Longest run of missing samples (replies lost or late on the link) filled in by
#: interpolation: 0.1 s at 100 Hz, a fraction of the pendulum's period.
MAX_GAP = 10


def _arrays(log: RtLog) -> Tuple[float, np.ndarray, np.ndarray]:
    """``(Ts, u, y)`` on the regular grid, ``alpha`` made continuous. Samples missing from the
    log (at most ``MAX_GAP`` in a row: replies lost on the link) are filled in, the angles
    linearly and the voltage held, as the device held it."""
    ts = float(np.median(np.diff(log.t))) if len(log.t) > 1 else float("nan")
    k = np.round((log.t - log.t[0]) / ts).astype(np.int64)
    y = np.column_stack([log.theta, np.unwrap(log.alpha)])
    grid = np.arange(k[-1] + 1)
    if len(grid) != len(k):
        held = np.searchsorted(k, grid, side="right") - 1
        y = np.column_stack([np.interp(grid, k, y[:, j]) for j in range(2)])
        return ts, np.ascontiguousarray(log.u[held], dtype=np.float64), y
    return ts, np.ascontiguousarray(log.u, dtype=np.float64), np.ascontiguousarray(y)


def _start(start: Union[str, FurutaParams, PathLike]) -> Tuple[FurutaParams, str]:
    if isinstance(start, FurutaParams):
        return start, "qube_servo2"
    if start == "paper":
        return FurutaParams.paper(), "paper"
    if start == "qube_servo2":
        return FurutaParams.qube_servo2(), "qube_servo2"
    path = os.fspath(start)
    if not os.path.exists(path):
        raise IdentifyError(f"start: {start!r} is neither paper, qube_servo2 nor an existing file")
    spec = load_config(path)
    return spec.params, spec.plant.preset


def _check(name: str, log: RtLog, holdout: float) -> List[str]:
    """Refuses what cannot be fitted; returns warnings for what can."""
    notes = []
    n = len(log.t)
    for column in ("t", "theta", "alpha", "u"):
        bad = np.flatnonzero(~np.isfinite(getattr(log, column)))
        if bad.size:
            raise IdentifyError(
                f"{name}: column {column!r} is not a number in {bad.size} rows (first at row "
                f"{bad[0]}); identification needs every sample"
            )
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


def identify(
    logs: Sequence[LogLike],
    start: Union[str, FurutaParams, PathLike] = "qube_servo2",
    *,
    holdout: float = 0.25,
    segment: float = 2.0,
    max_iter: int = 60,
    substeps: int = 4,
) -> IdentifyResult:
    """Fit the nonlinear Furuta model to excitation logs (output error).

    Parameters
    ----------
    logs : sequence of path or RtLog
        ``rip-rt excite`` (or ``rip-rt run``) CSV logs, all with the same sample time, pendulum
        hanging down.
    start : {"paper", "qube_servo2"}, FurutaParams or path
        Start set: fixes ``mp``, ``Lp``, ``mr``, ``Rm``, ``km`` and ``g`` (weigh and measure
        the pendulum and put them in a ``[plant]`` file) and gives the initial guess.
    holdout : float
        Fraction of each log, at its end, kept out of the fit for validation (0 to 0.9).
    segment : float
        Length (s) of the simulated segments of the criterion.
    max_iter : int
        Levenberg-Marquardt iteration limit (at most 500).
    substeps : int
        Least RK4 steps per sample.

    Returns
    -------
    IdentifyResult

    Raises
    ------
    IdentifyError
        A log that cannot be identified from: not a number, too short, unevenly sampled, a
        balancing run, no excitation; the message names the log.
    LogError
        A file that is not a ``rip-rt`` log (wrong columns, unreadable rows).
    KeyboardInterrupt
        Ctrl-C; the fit stops within a segment simulation.

    Warns
    -----
    IdentifyWarning
        Saturated voltage, a log without voltage changes, parameters not identifiable from the
        logs, or a fit that did not converge.
    """
    params0, preset = _start(start)
    loaded: List[RtLog] = []
    names: List[str] = []
    for i, item in enumerate(logs):
        if isinstance(item, RtLog):
            loaded.append(item)
            names.append(f"log {i}")
        else:
            loaded.append(load_log(item))
            names.append(Path(os.fspath(item)).stem)
    if not loaded:
        raise IdentifyError("logs: at least one log is needed")
    if not (isinstance(holdout, (int, float)) and 0.0 <= holdout <= 0.9):
        raise IdentifyError(f"holdout: must be in [0, 0.9], got {holdout!r}")
    notes: List[str] = []
    data = []
    for name, log in zip(names, loaded, strict=True):
        notes += _check(name, log, holdout)
        data.append(_arrays(log))
    ts0 = data[0][0]
    for name, (ts, _, _) in zip(names, data, strict=True):
        if abs(ts - ts0) > 1e-6 * ts0:
            raise IdentifyError(f"{name}: sample time {ts:g} s differs from {names[0]}'s {ts0:g} s")
    raw = identify_logs(
        [(ts0, u, y) for _, u, y in data],
        params0,
        segment=segment,
        holdout=holdout,
        max_iter=max_iter,
        substeps=substeps,
    )
    if raw["not_identifiable"]:
        notes.append(
            "not identifiable from these logs: "
            + ", ".join(raw["not_identifiable"])
            + " (relative standard error above 50 %); add excitation that moves them "
            "(chirp or PRBS for the motor and arm, free swing for the pendulum)"
        )
    for name, what in (("mp", "Jp"), ("Lp", "Jp"), ("mr", "Jr")):
        before, after = getattr(params0, name), getattr(raw["params"], name)
        if after != before:
            notes.append(
                f"{name} changed from {before:.4g} to {after:.4g}: the start set's value leaves "
                f"no room for a positive {what}, so that link is taken as a uniform rod (the "
                "dynamics are the same; check the start set's masses and lengths)"
            )
    if not raw["converged"]:
        notes.append(f"the fit did not converge in {raw['iterations']} iterations")
    for note in notes:
        warnings.warn(note, IdentifyWarning, stacklevel=2)
    return IdentifyResult(
        params=raw["params"],
        start=params0,
        preset=preset,
        std_errors=dict(zip(raw["free"], raw["std_errors"], strict=True)),
        fit_percent=np.array(raw["fit_percent"]),
        training_fit_percent=np.array(raw["training_fit_percent"]),
        not_identifiable=tuple(raw["not_identifiable"]),
        at_bounds=tuple(raw["at_bounds"]),
        condition_number=raw["condition_number"],
        rank=raw["rank"],
        cost=raw["cost"],
        rms_residual=raw["rms_residual"],
        iterations=raw["iterations"],
        converged=raw["converged"],
        simulations=raw["simulations"],
        segments=raw["segments"],
        Ad=raw["Ad"],
        Bd=raw["Bd"],
        Ts=ts0,
        holdout=holdout,
        segment=segment,
        names=tuple(names),
        warnings=tuple(notes),
    )


def plot_fit(result: IdentifyResult, log: RtLog, name: str, path: PathLike) -> Path:
    """Measured vs simulated angles of one log (held-out part shaded), saved to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ts, _, y = _arrays(log)
    sim = result.simulate(log)
    t = np.arange(len(y)) * ts
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(9, 5.5))
    cut = int((1.0 - result.holdout) * len(y)) * ts
    i = result.names.index(name) if name in result.names else None
    for j, (ax, label) in enumerate(zip(axes, ("arm θ (rad)", "pendulum α (rad)"), strict=True)):
        ax.plot(t, y[:, j], lw=1.0, label="measured")
        ax.plot(t, sim[:, j], lw=1.0, ls="--", label="identified model")
        if result.holdout > 0:
            ax.axvspan(cut, t[-1], color="0.9", zorder=0, label="held out")
        ax.set_ylabel(label)
        if i is not None:
            ax.set_title(f"fit {result.fit_percent[i, j]:.1f} % (held out)", fontsize=9)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("t (s)")
    fig.suptitle(f"{name}: measured vs simulated")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


__all__ = ["IdentifyError", "IdentifyResult", "IdentifyWarning", "identify", "plot_fit"]

"""Identification of a rig from ``rip-rt excite`` logs: an output-error fit of the nonlinear
Furuta model (``rip_core::identify``), its report, figures and the ``[plant]`` file.

The model, the identifiable parameters and the criterion are documented in
``rip_core::identify``: the pendulum's mass and length (``mp``, ``Lp``), ``mr``, ``Rm`` and ``g``
are taken from the start set (or the lab file, :func:`read_lab`) and fix the scale; ``km`` is
held equal to ``kt`` unless the lab file gives it (the logs determine only ``Dr + kt km / Rm``);
``Lr``, ``Jr``, ``Jp``, ``kt``, ``Dr``, ``Dp``, Coulomb friction ``Cr``, ``Cp`` and the dead
zone ``Vd`` are estimated. A held value that was not measured (a preset's) carries a prior of
``PRIOR_RSE`` (30 %), named in the report and included in the standard errors. Every result
carries the core's verdict (:attr:`IdentifyResult.problems`): ``riprs identify`` writes no rig
file for a result that has any.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from pathlib import Path
from typing import Dict, List, Sequence, Tuple, Union

import numpy as np
import tomllib

from riprs._log_checks import MAX_GAP as MAX_GAP
from riprs._log_checks import MIN_TRAINING_SAMPLES as MIN_TRAINING_SAMPLES
from riprs._log_checks import SATURATION_WARNING as SATURATION_WARNING
from riprs._log_checks import IdentifyError, _check, _estimated_rows
from riprs._riprs import HEADER_SETTINGS as _HEADER_SETTINGS
from riprs._riprs import (
    IDENTIFY_MAX_SAMPLES,
    ConfigError,
    FurutaParams,
    Plant,
    Spec,
    header_rig_settings,
    identify_logs,
    lab_start,
    load_config,
    read_lab_file,
)
from riprs._riprs import IDENTIFY_MIN_HELDOUT_MOTION as MIN_HELDOUT_MOTION
from riprs._riprs import IDENTIFY_PRIOR_RSE as PRIOR_RSE
from riprs._riprs import LAB_KEYS as _LAB_KEYS
from riprs._riprs import PARAMETERS as _PARAMETERS
from riprs.log import RtLog, load_log

PathLike = Union[str, "os.PathLike[str]"]
LogLike = Union[PathLike, RtLog]

#: The start sets by preset name: a held value of the start that differs from its preset's is
#: the start file's own, measured (``rip_core::identify::IdentifyOptions::preset``).
_PRESETS = {"paper": FurutaParams.paper, "qube_servo2": FurutaParams.qube_servo2}

#: The order of ``[plant]`` keys written to an identified file.
PLANT_KEYS = tuple(_PARAMETERS)


class UntrustedIdentification(IdentifyError):
    """A fit that ran but cannot be trusted (``rip_core::identify``'s verdict): poor held-out
    fit, an ill-conditioned information matrix, parameters at bounds or implausible for the
    logs. The message lists every reason with the measurement or excitation that would fix it;
    :attr:`result` holds the rejected :class:`IdentifyResult`."""

    def __init__(self, message: str, result: IdentifyResult) -> None:
        super().__init__(message)
        self.result = result


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
        From the sandwich covariance of ``rip_core::identify`` (coloured, unequal residuals
        allowed for): 95 % intervals held the truth in 97 % of 50 re-identifications. The
        priors of :attr:`held` are included (``Dr`` depends on ``Rm`` when ``km = kt``).
    held : dict
        The start set's values held at a preset's, not measured: name -> prior relative
        standard deviation (``PRIOR_RSE``).
    km_tied : bool
        Whether ``km`` was held equal to ``kt`` (not measured).
    not_done : tuple of str
        Checks that were not done, neither passed nor failed: a log whose held-out part moves
        too little to score a fit; each names the recording that would let it be done.
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
        Levenberg-Marquardt iterations, segment simulations run (every start), training
        segments.
    starts : int
        Fits run by the multi-start (1 when the fit from the start set is trusted).
    linear_rse : dict
        Relative standard error of each entry of the continuous upright ``[A B]`` that is not
        a structural zero (``"A[1][3]"``, ...) and of its ``"unstable eigenvalue"``, by the
        delta method from :attr:`covariance`; the verdict requires at most 1 % and 0.5 %.
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
    problems : tuple of str
        The verdict: every reason not to trust the result (empty when trusted), each naming
        the log or parameter and what to measure or add. See :attr:`trusted`.
    covariance : ndarray, shape (9, 9)
        Covariance of the natural logarithm of the estimated values, in the order of
        ``std_errors`` (``Jr``, ``Jp``: of the joint-axis inertias ``J0``, ``Jalpha``); infinite
        rows for parameters the logs do not determine. The logs' alone, given the held values
        (without the priors of :attr:`held`, along which the dynamics do not change).
    held_out_motion : ndarray, shape (n_logs, 2)
        RMS deviation (rad) of ``[theta, alpha]`` over each log's held-out part; below
        ``MIN_HELDOUT_MOTION`` the fit is not scored (NaN, "not measurable").
    plant_covariance : ndarray, shape (9, 9)
        Covariance of the estimated parameters themselves (``[plant]`` names, SI units, in the
        order of ``std_errors``; ``Jr``, ``Jp`` the centroidal inertias), written as
        ``[plant_covariance]`` in the identification file; infinite rows for parameters the
        logs do not determine.
    settings : dict
        The ``[loop]``, ``[device]``, ``[sensor]`` and ``[safety]`` settings the logs' headers
        record (the rig as it was excited), written into the rig file.
    lab : dict
        The lab file's measurements used (name -> value), empty without one.
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
    problems: Tuple[str, ...] = ()
    covariance: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    held_out_motion: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2)))
    lab: Dict[str, float] = dataclasses.field(default_factory=dict)
    values: Tuple[float, ...] = ()
    starts: int = 1
    linear_rse: Dict[str, float] = dataclasses.field(default_factory=dict)
    plant_covariance: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    settings: Dict[str, Dict[str, object]] = dataclasses.field(default_factory=dict)
    held: Dict[str, float] = dataclasses.field(default_factory=dict)
    km_tied: bool = False
    not_done: Tuple[str, ...] = ()

    @property
    def trusted(self) -> bool:
        """Whether no check of the verdict failed (no :attr:`problems`); a check not done
        (:attr:`not_done`) is not a pass, and the report says so."""
        return not self.problems

    def held_text(self) -> str:
        """What the fit held without the logs determining it: the preset's values with their
        prior, the cable's stiffness ``Kc`` (never estimated) and ``km = kt``."""
        parts = [
            f"{n} = {getattr(self.start, n):.4g} (the {self.preset} preset's, not measured: "
            f"prior +-{100 * r:.0f} %)"
            for n, r in self.held.items()
        ]
        if parts:
            parts[-1] += " (their priors are in the standard errors)"
        parts.append(f"Kc = {self.start.Kc:.4g} N m/rad (the cable's stiffness, never estimated)")
        if self.km_tied:
            parts.append(
                "km = kt (one constant of a DC motor in SI units; the logs determine only "
                "Dr + kt km / Rm; give km in the lab file to hold it instead)"
            )
        return "; ".join(parts)

    def verdict(self) -> List[str]:
        """The verdict as lines: the checks failed (:attr:`problems`), not done
        (:attr:`not_done`) or passed, and what was held (:meth:`held_text`)."""
        lines = []
        if self.problems:
            lines.append("NOT TRUSTED: the model cannot be used as it is:")
            lines += [f"  - {p}" for p in self.problems]
        else:
            checks = ["conditioning", "bounds", "plausibility"]
            scored = [
                n for n, f in zip(self.names, self.fit_percent, strict=True) if np.isfinite(f).any()
            ]
            if scored:
                held_out = "held-out fit" + (
                    f" of {', '.join(scored)}" if len(scored) < len(self.names) else ""
                )
                checks.insert(0, held_out)
            lines.append(
                "verdict: "
                + ("every check passed" if not self.not_done else "checks passed")
                + f" ({', '.join(checks)})"
            )
        if self.not_done:
            lines.append("NOT DONE (neither passed nor failed):")
            lines += [f"  - {p}" for p in self.not_done]
        lines.append(f"held, not determined by the logs: {self.held_text()}")
        return lines

    def report(self) -> str:
        """A plain-text report: parameters with standard errors, fits, diagnostics."""
        start = self.start.to_dict()
        lines = ["Identified parameters (start value -> estimate +- standard error):"]
        for i, (name, se) in enumerate(self.std_errors.items()):
            value = getattr(self.params, name)
            # Jr's and Jp's errors are those of the joint-axis inertias the logs determine.
            fitted = self.values[i] if i < len(self.values) else value
            note = ""
            if name in self.not_identifiable:
                note = "  NOT IDENTIFIABLE from these logs"
            elif name in self.at_bounds:
                note = "  at its bound"
            lines.append(
                f"  {name:3s} {start[name]:12.5g} -> {value:12.5g} +- {se:9.2g}"
                + (f" ({100 * se / fitted:.1f} %)" if fitted > 0 and math.isfinite(se) else "")
                + note
            )
        fixed = [n for n in self.params.to_dict() if n not in self.std_errors]
        lines.append(
            "  not estimated (start set or lab file; held values below the verdict): "
            + ", ".join(f"{n} = {getattr(self.params, n):.5g}" for n in fixed)
        )
        lines.append("")
        lines.append("Fit (%) per log, theta / alpha: held-out | training")
        for name, fit, train in zip(
            self.names, self.fit_percent, self.training_fit_percent, strict=True
        ):
            lines.append(
                f"  {name}: {_fit_text(fit[0])} / {_fit_text(fit[1])} | {train[0]:6.1f} / "
                f"{train[1]:6.1f}"
            )
        if np.isnan(self.fit_percent).any() and self.holdout > 0:
            lines.append(
                "  (not measurable: the held-out part does not move, e.g. a pendulum at rest; "
                "it is not scored)"
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
        if self.problems:
            lines.append("")
        lines += self.verdict()
        return "\n".join(lines)

    def to_toml(self, source: str = "") -> str:
        """The ``[plant]`` file of the identified rig (read by ``riprs compare --config``,
        ``rip-rt run --config`` and ``rip-rt emulate --config``).

        Raises
        ------
        IdentifyError
            A file that their check would refuse (it is checked here, so never written).
        """
        p = self.params.to_dict()
        head = [f"# Identified by riprs identify{' from ' + source if source else ''}."]
        if self.problems:
            head.append("# UNTRUSTED: written by riprs identify --force despite:")
            head += [f"#   - {p}" for p in self.problems]
        head.append(
            "# Held-out fit (theta/alpha %): "
            + "; ".join(
                f"{n} {_fit_text(f[0]).strip()}/{_fit_text(f[1]).strip()}"
                for n, f in zip(self.names, self.fit_percent, strict=True)
            )
        )
        if self.lab:
            head.append(
                "# Lab measurements: " + ", ".join(f"{k} = {v!r}" for k, v in self.lab.items())
            )
        if self.held or self.km_tied:
            head.append(
                "# Held: "
                + ", ".join(
                    [f"{n} (the preset's, prior +-{100 * r:.0f} %)" for n, r in self.held.items()]
                    + (["km = kt"] if self.km_tied else [])
                )
            )
        for note in self.not_done:
            head.append(f"# Not done: {note.split(':')[0]}: held-out fit (nothing to score)")
        head.append(
            "# Verdict, lab values, fit report and parameter covariance: the .identification.toml "
            "file beside this one."
        )
        if self.not_identifiable:
            head.append("# Not identifiable from the logs: " + ", ".join(self.not_identifiable))
        body = ["[plant]", f'preset = "{self.preset}"']
        body += [f"{k} = {p[k]!r}" for k in PLANT_KEYS]
        for section in ("sensor", "loop", "device", "safety"):
            if section in self.settings:
                body += ["", f"[{section}]"]
                body += [f"{k} = {_toml_value(v)}" for k, v in self.settings[section].items()]
        text = "\n".join(head + body) + "\n"
        # The rig file's own check (riprs config's and rip-rt run's): a file it refuses is
        # not written.
        try:
            Spec.from_toml(text)
        except ConfigError as exc:
            raise IdentifyError(f"the identified rig file would be refused: {exc}") from None
        return text

    def identification_toml(self, source: str = "") -> str:
        """The identification file written beside the rig file (:func:`identification_path`):
        the verdict, the lab's measurements, the fit report and the parameters' covariance.

        ``[plant_covariance]`` holds the covariance of the estimated ``[plant]`` parameters, in
        the one format ``riprs.envs`` reads (docs/gym.md): ``parameters`` (their ``[plant]``
        names) and ``matrix`` (SI units, first order from the fit's covariance of the
        logarithms, :attr:`IdentifyResult.covariance`). Parameters the logs do not determine are
        left out (listed in ``not_determined``); those held on a bound have zero variance. A
        draw ``[plant] + N(0, matrix)`` is a rig consistent with the logs."""
        cov = np.array(self.plant_covariance) if len(self.plant_covariance) else np.zeros((0, 0))
        free = list(self.std_errors)
        keep = [i for i in range(len(cov)) if np.isfinite(cov[i]).all()]
        lines_cov = [
            "[plant_covariance]",
            "parameters = [" + ", ".join(_toml_str(free[i]) for i in keep) + "]",
            f"matrix = {_toml_matrix(cov[np.ix_(keep, keep)]) if keep else '[]'}",
            "not_determined = ["
            + ", ".join(_toml_str(free[i]) for i in range(len(cov)) if i not in keep)
            + "]",
        ]
        lines = [
            f"# Identification of the rig by riprs identify{' from ' + source if source else ''}.",
            "[identification]",
            f"trusted = {'true' if self.trusted else 'false'}",
            "logs = [" + ", ".join(_toml_str(n) for n in self.names) + "]",
            "problems = [" + ", ".join(_toml_str(p) for p in self.problems) + "]",
            "not_done = [" + ", ".join(_toml_str(p) for p in self.not_done) + "]",
            "warnings = [" + ", ".join(_toml_str(w) for w in self.warnings) + "]",
            "# Start set's values held at a preset's (not measured): name = prior relative sd.",
            "held = {" + ", ".join(f"{n} = {r!r}" for n, r in self.held.items()) + "}",
            f"km_tied = {'true' if self.km_tied else 'false'}",
            "",
            "[lab]",
        ]
        lines += [f"{k} = {v!r}" for k, v in self.lab.items()]
        lines += [
            "",
            "[fit]",
            "# Held-out and training fit (%) per log, [theta, alpha]; nan: not measurable.",
            f"held_out_percent = {_toml_matrix(self.fit_percent)}",
            f"training_percent = {_toml_matrix(self.training_fit_percent)}",
            f"held_out_motion_rad = {_toml_matrix(self.held_out_motion)}",
            f"condition_number = {_toml_float(self.condition_number)}",
            f"rank = {self.rank}",
            f"rms_residual = {_toml_float(self.rms_residual)}",
            f"iterations = {self.iterations}",
            f"converged = {'true' if self.converged else 'false'}",
            "",
            *lines_cov,
        ]
        return "\n".join(lines) + "\n"

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


def identification_path(rig: PathLike) -> Path:
    """The identification file beside a rig file: ``rig.toml`` -> ``rig.identification.toml``."""
    path = Path(rig)
    return path.with_name(f"{path.stem}.identification.toml")


def read_plant_covariance(rig: PathLike) -> Tuple[List[str], np.ndarray] | None:
    """The ``[plant_covariance]`` of a rig: ``(names, matrix)``, the covariance (SI units) of
    the ``[plant]`` parameters ``names`` that identification determined.

    Read from the rig file's own ``[plant_covariance]`` table, else from the identification
    file ``riprs identify`` wrote beside it (:func:`identification_path`). The one reader of
    the format: ``riprs tune``, ``riprs campaign`` and ``riprs.envs`` draw rigs from it.

    Returns
    -------
    tuple of (list of str, ndarray) or None
        None when neither file holds the table, or when it names no parameter (an
        identification that determined nothing).

    Raises
    ------
    IdentifyError
        A table without ``parameters`` and a square ``matrix`` of their size, naming the file.
    """
    path = Path(os.fspath(rig))
    with path.open("rb") as f:
        table = tomllib.load(f).get("plant_covariance")
    beside = identification_path(path)
    if table is None and beside.is_file():
        path = beside
        with beside.open("rb") as f:
            table = tomllib.load(f).get("plant_covariance")
    if table is None:
        return None
    try:
        names = [str(n) for n in table["parameters"]]
        matrix = np.array([[float(v) for v in row] for row in table["matrix"]], dtype=float)
    except (KeyError, TypeError, ValueError) as exc:
        raise IdentifyError(
            f"{path}: plant_covariance: needs parameters = [names] and matrix = [[...]]: {exc}"
        ) from None
    if not names:
        return None
    if matrix.shape != (len(names), len(names)):
        raise IdentifyError(
            f"{path}: plant_covariance: matrix must be {len(names)} x {len(names)} (one row and "
            f"column per parameter), got shape {matrix.shape}"
        )
    return names, matrix


def _toml_float(value: float) -> str:
    v = float(value)
    return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)


def _toml_matrix(m: np.ndarray) -> str:
    return "[" + ", ".join("[" + ", ".join(map(_toml_float, row)) + "]" for row in m) + "]"


def _toml_value(value: object) -> str:
    if isinstance(value, str):
        return _toml_str(value)
    if isinstance(value, list):
        return "[" + ", ".join(map(_toml_value, value)) + "]"
    return repr(value)


def _toml_str(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", " ") + '"'


def _fit_title(result: IdentifyResult, log: int, output: int) -> str:
    """A figure's title for one output's held-out fit; an output that was not scored says so
    and why, not "nan %"."""
    fit = result.fit_percent[log, output]
    if math.isfinite(fit):
        return f"fit {fit:.1f} % (held out)"
    if result.holdout <= 0:
        return "held-out fit: not done (nothing held out)"
    motion = result.held_out_motion[log, output] if len(result.held_out_motion) else math.nan
    return (
        f"held-out fit: not scored (moves {motion:.3g} rad RMS, below {MIN_HELDOUT_MOTION:g} rad)"
    )


def _fit_text(value: float) -> str:
    """A held-out fit for reports: ``not measurable`` for NaN (no motion held out)."""
    return f"{value:6.1f}" if math.isfinite(value) else "not measurable"


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


#: Keys of a lab file's ``[lab]`` table and what each is (``rip_core::identify::lab``, the one
#: definition, which ``rip-rt excite --lab`` reads too): what a scale, a ruler and a multimeter
#: give, and the encoders' counts per revolution. Each is optional (docs/rig.md says what each
#: one buys).
LAB_KEYS: Dict[str, str] = dict(_LAB_KEYS)


def read_lab(path: PathLike) -> Dict[str, float]:
    """Read a lab file: a TOML ``[lab]`` table of measured values (:data:`LAB_KEYS`).

    Raises
    ------
    IdentifyError
        An unknown key, a value that is not a positive finite number (counts: an integer of at
        least 16), or a file that is not TOML; the message names the file and the key.
    """
    try:
        return dict(read_lab_file(os.fspath(path)))
    except ConfigError as exc:
        raise IdentifyError(str(exc)) from None


def _apply_lab(start: FurutaParams, lab: Dict[str, float]) -> FurutaParams:
    """The start set with the lab's measurements in place (``rip_core``'s rule)."""
    try:
        return lab_start(start, [(k, float(v)) for k, v in lab.items()])
    except ConfigError as exc:
        raise IdentifyError(str(exc)) from None


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


#: The ``rip-rt excite`` log header's loop, sensor, device and safety settings and the rig file
#: key each is written to (``rip_core::identify::header``, the one definition): the rig file
#: then holds what ``rip-rt run`` needs. Each value is checked by the rig file's own check.
HEADER_SETTINGS: Dict[str, str] = dict(_HEADER_SETTINGS)


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


def _header_settings(
    names: Sequence[str], logs: Sequence[RtLog], sources: Sequence[str] | None = None
) -> Tuple[Dict[str, Dict[str, object]], Dict[str, float]]:
    """The rig file's ``[loop]``, ``[device]``, ``[sensor]`` and ``[safety]`` settings and the
    lab values recorded in the logs' headers (``rip-rt excite``); the logs must agree, else an
    error names the two logs and the key. A value the rig file would refuse is an error naming
    the log (``sources``: its file) and the header key."""
    found: Dict[str, Tuple[str, str, str]] = {}
    sources = list(sources) if sources is not None else list(names)
    for name, source, log in zip(names, sources, logs, strict=True):
        for key, value in log.meta.items():
            if HEADER_SETTINGS.get(key, "").startswith("safety."):
                # Limits may differ from run to run (a gentler chirp): the rig file keeps the
                # tightest, checked below.
                if key in found and _number(found[key][1]) <= _number(value):
                    continue
                found[key] = (name, value, source)
            elif key in HEADER_SETTINGS or key.startswith("lab."):
                if key in found and found[key][1] != value:
                    raise IdentifyError(
                        f"{name}: header {key}: {value}, but {found[key][0]} says "
                        f"{found[key][1]}: the logs were recorded with different settings"
                    )
                found.setdefault(key, (name, value, source))
    try:
        sections = header_rig_settings(
            [(source, key, text) for key, (_, text, source) in found.items()]
        )
    except ConfigError as exc:
        raise IdentifyError(str(exc)) from None
    lab: Dict[str, float] = {}
    for key, (_, text, source) in found.items():
        if key.startswith("lab."):
            try:
                value = float(text)
            except ValueError:
                raise IdentifyError(f"{source}: header {key}: not a number: {text!r}") from None
            lab[key[4:]] = int(value) if key.endswith("_counts") and value.is_integer() else value
            # The lab file's rule (rip_core::identify::lab), naming the log that recorded it.
            try:
                lab_start(FurutaParams.qube_servo2(), [(key[4:], value)])
            except ConfigError as exc:
                raise IdentifyError(f"{source}: header {exc}") from None
    return dict(sections), lab


def identify(
    logs: Sequence[LogLike],
    start: Union[str, FurutaParams, PathLike] = "qube_servo2",
    *,
    holdout: float = 0.25,
    segment: float = 2.0,
    max_iter: int = 60,
    substeps: int = 4,
    lab: Union[PathLike, Dict[str, float], None] = None,
    strict: bool = False,
) -> IdentifyResult:
    """Fit the nonlinear Furuta model to excitation logs (output error).

    Parameters
    ----------
    logs : sequence of path or RtLog
        ``rip-rt excite`` (or ``rip-rt run``) CSV logs, all with the same sample time, pendulum
        hanging down.
    start : {"paper", "qube_servo2"}, FurutaParams or path
        Start set: fixes ``mp``, ``Lp``, ``mr``, ``Rm`` and ``g`` (weigh and measure the
        pendulum and put them in a ``[plant]`` file or the lab file) and gives the initial
        guess. Those of them still at the preset's values are held with a prior of
        ``PRIOR_RSE`` (:attr:`IdentifyResult.held`); ``km`` is held equal to ``kt`` unless the
        lab file gives it.
    holdout : float
        Fraction of each log, at its end, kept out of the fit for validation (0 to 0.9).
    segment : float
        Length (s) of the simulated segments of the criterion.
    max_iter : int
        Levenberg-Marquardt iteration limit (at most 500).
    substeps : int
        Least RK4 steps per sample.
    lab : path or dict, optional
        A lab file (TOML, :func:`read_lab`) or its values: what was weighed and measured on the
        rig. Its values replace the start set's and are held fixed (``Lr`` too, which is
        otherwise estimated), and are carried into :attr:`IdentifyResult.lab` and the rig file.
        Without it, the lab values ``rip-rt excite --lab`` recorded in the logs' headers.
    strict : bool
        Raise :class:`UntrustedIdentification` when the verdict finds problems, instead of
        returning them in :attr:`IdentifyResult.problems`. (A fit whose verdict finds problems
        is first repeated from further starts by ``rip_core::identify``: multi-start; the
        first trusted result is returned, see :attr:`IdentifyResult.starts`.)

    Returns
    -------
    IdentifyResult

    Raises
    ------
    IdentifyError
        A log that cannot be identified from: too large (checked from its size before it is
        read), not a number, a wild sample, angles in degrees, time in milliseconds, voltage
        and arm acceleration of opposite signs (negated voltage or reversed arm encoder), too
        short, unevenly sampled, a balancing run, no excitation; the message names the log and
        the column.
    UntrustedIdentification
        With ``strict``, a fit whose verdict found problems.
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
    lab_values = read_lab(lab) if lab is not None and not isinstance(lab, dict) else dict(lab or {})
    loaded: List[RtLog] = []
    names: List[str] = []
    sources: List[str] = []
    rows = 0
    for i, item in enumerate(logs):
        if isinstance(item, RtLog):
            names.append(f"log {i}")
            sources.append(names[-1])
            rows += len(item.t)
        else:
            names.append(Path(os.fspath(item)).stem)
            sources.append(os.fspath(item))
            rows += _estimated_rows(names[-1], os.fspath(item))
        if rows > IDENTIFY_MAX_SAMPLES:
            raise IdentifyError(
                f"{names[-1]}: the logs hold about {rows} samples up to this one, more than the "
                f"{IDENTIFY_MAX_SAMPLES} one identification takes; cut the logs (a few minutes "
                "of excitation suffice)"
            )
    for item in logs:
        loaded.append(item if isinstance(item, RtLog) else load_log(item))
    if not loaded:
        raise IdentifyError("logs: at least one log is needed")
    settings, header_lab = _header_settings(names, loaded, sources)
    # The lab file given here, else the one rip-rt excite --lab recorded in the logs.
    if lab is None:
        lab_values = header_lab
    params0 = _apply_lab(params0, lab_values)
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
    # rip_core::identify repeats a fit that is not trusted from further starts (multi-start).
    raw = identify_logs(
        [(ts0, u, y) for _, u, y in data],
        params0,
        segment=segment,
        holdout=holdout,
        max_iter=max_iter,
        substeps=substeps,
        names=names,
        fixed=["Lr"] if "Lr" in lab_values else [],
        measured=[k for k in lab_values if k in _PARAMETERS],
        preset=_PRESETS[preset]() if preset in _PRESETS else None,
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
    result = IdentifyResult(
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
        starts=raw["starts"],
        linear_rse=dict(
            zip([*raw["linear_entries"], "unstable eigenvalue"], raw["linear_rse"], strict=True)
        ),
        segments=raw["segments"],
        Ad=raw["Ad"],
        Bd=raw["Bd"],
        Ts=ts0,
        holdout=holdout,
        segment=segment,
        names=tuple(names),
        warnings=tuple(notes),
        problems=tuple(raw["problems"]),
        covariance=np.array(raw["covariance"]),
        plant_covariance=np.array(raw["plant_covariance"]),
        held_out_motion=np.array(raw["held_out_motion"]),
        lab=dict(lab_values),
        values=tuple(raw["values"]),
        settings=settings,
        held={name: prior for name, _, prior in raw["held"]},
        km_tied=raw["km_tied"],
        not_done=tuple(raw["not_done"]),
    )
    if strict and result.problems:
        raise UntrustedIdentification(
            f"{', '.join(names)}: the identified model cannot be trusted:\n  - "
            + "\n  - ".join(result.problems),
            result,
        )
    return result


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
            ax.set_title(_fit_title(result, i, j), fontsize=9)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("t (s)")
    fig.suptitle(f"{name}: measured vs simulated")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


__all__ = [
    "MIN_HELDOUT_MOTION",
    "PRIOR_RSE",
    "IdentifyError",
    "IdentifyResult",
    "IdentifyWarning",
    "UntrustedIdentification",
    "identification_path",
    "identify",
    "plot_fit",
    "read_lab",
    "read_plant_covariance",
]

"""Per-rig tuning (``riprs tune``), the loop's robustness margins and the pre-flight check.

The work is done in ``rip-core`` (``rip_core::tune``, ``rip_core::margins``,
``rip_core::preflight``); this module shapes its results into typed objects and writes the
tuned file. ``docs/tuning.md`` has the method and the math.
"""

from __future__ import annotations

import operator
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Tuple, Union

import numpy as np

from riprs import _outputs, _progress
from riprs._riprs import (
    TS,
    ConfigError,
    Spec,
    identification_untrusted,
    load_config,
    loop_margins,
    loop_response,
    preflight_check,
    tune_check,
    tune_record_path,
    tune_robustness,
    tune_weights,
)
from riprs.identify import IdentifyError, identification_path, read_plant_covariance
from riprs.swing_tuning import SwingUpTuning

__all__ = [
    "Bar",
    "ControllerTuning",
    "Margins",
    "PreflightFinding",
    "TuneResult",
    "check_out",
    "loop_response",
    "margins",
    "preflight",
    "record_path",
    "tune",
]

PathLike = Union[str, "os.PathLike[str]"]
CONTROLLERS = ("LQR", "LQG", "MPC")


@dataclass(frozen=True)
class Margins:
    """Robustness margins of a controller's linearised loop broken at the plant input.

    Attributes
    ----------
    stable : bool
        Whether the closed loop is stable (every margin is 0 when it is not).
    gain_margin_db : float
        Smallest factor (dB, > 0) by which the loop gain may grow; ``inf`` for none.
    gain_reduction_db : float
        Largest factor (dB, < 0) by which it may shrink (the unstable pendulum needs gain).
    phase_margin_deg : float
        Smallest phase margin over the gain crossovers (degrees).
    crossover_rad_s : float
        Frequency of that crossover (rad/s).
    disk_margin : float
        Balanced disk margin alpha, as MATLAB's ``diskmargin``: ``1 / max |S - 1/2|``.
    disk_gain_margin_db : float
        ``20 log10((2 + alpha) / (2 - alpha))``.
    disk_phase_margin_deg : float
        ``2 atan(alpha / 2)`` in degrees.
    """

    stable: bool
    gain_margin_db: float
    gain_reduction_db: float
    phase_margin_deg: float
    crossover_rad_s: float
    disk_margin: float
    disk_gain_margin_db: float
    disk_phase_margin_deg: float

    @classmethod
    def _from(cls, d: Dict[str, float]) -> Margins:
        return cls(**{k: (bool(v) if k == "stable" else float(v)) for k, v in d.items()})


@dataclass(frozen=True)
class Bar:
    """The bar a tuned controller is held to on one rig (``rip_core::tune::Bar::for_rig``).

    Attributes
    ----------
    arm_peak_to_peak : float
        Largest steady-state arm peak-to-peak (rad): ``max(0.05, 2 * floor)``.
    floor : float
        The sensor's floor: the arm peak-to-peak of the file's own LQR on the same rig
        without dead zone, Coulomb friction or stiction, with the same encoders and noise
        (rad; ``inf`` when that LQR falls).
    pendulum, offset : float
        Largest steady-state ``|alpha|`` and arm offset from the reference (rad).
    gain_margin_db, phase_margin_deg : float
        LQR's smallest gain margin both ways (dB) and phase margin (degrees).
    disk_margin : float
        LQG's and the MPC's smallest balanced disk margin.
    off_compensation : float
        The relative error of the compensation (0.3: the dead zone and arm friction it
        assumes 0.7 and 1.3 times the plant's, with the arm's stiction on).
    off_peak_to_peak, off_peak_to_peak_mpc : float
        Largest arm peak-to-peak with the compensation off (rad): LQR and LQG, the MPC.
    summary : str
        The bar in one line.
    """

    arm_peak_to_peak: float
    floor: float
    pendulum: float
    offset: float
    gain_margin_db: float
    phase_margin_deg: float
    disk_margin: float
    off_compensation: float
    off_peak_to_peak: float
    off_peak_to_peak_mpc: float
    summary: str

    @classmethod
    def _from(cls, d: Dict[str, object]) -> Bar:
        floor = d["floor"]
        return cls(
            **{
                k: (str(v) if k == "summary" else float(v))  # type: ignore[arg-type]
                for k, v in d.items()
                if k != "floor"
            },
            floor=float("nan") if floor is None else float(floor),  # type: ignore[arg-type]
        )


@dataclass(frozen=True)
class ControllerTuning:
    """How one tuned controller does on the rig's model.

    Attributes
    ----------
    controller : str
        ``"LQR"``, ``"LQG"`` or ``"MPC"``.
    rmse : numpy.ndarray
        The paper's Tab. 1 RMSE ``(arm, pendulum, voltage)`` of the predicted run.
    margins : Margins
        Its loop's margins at the plant input.
    peak_voltage : float
        Largest applied voltage (V) on the step.
    saturated : bool
        Whether LQR or LQG reached the voltage bound.
    fell : bool
        Whether a predicted run fell.
    arm_peak_to_peak, pendulum, offset : float
        Steady state over the last 3 s (rad): arm peak-to-peak, largest ``|alpha|``, arm offset.
    margins_ok, works : bool
        Whether the margins, and everything of the bar, hold.
    off_compensation_peak_to_peak : float
        Steady-state arm peak-to-peak (rad) with the compensation 30 % off either way and the
        arm's stiction on, the worst over both; NaN where the rig compensates nothing.
    off_compensation_fell : bool
        Whether a run with the compensation off fell, on the tuning's noise seeds or on the
        further ones of its fall check (``rip_core::tune::FALL_CHECK_SEEDS``).
    misses : str or None
        What of :class:`Bar` it misses on this rig, or None when it works; ``rip-rt run``'s
        pre-flight refuses it with the same words (``--force`` runs it anyway).
    balanced_fraction : float
        Fraction of the robustness runs (rigs drawn around this one) it balanced; NaN when
        none were run.
    """

    controller: str
    rmse: np.ndarray
    margins: Margins
    peak_voltage: float
    saturated: bool
    fell: bool
    arm_peak_to_peak: float
    pendulum: float
    offset: float
    margins_ok: bool
    works: bool
    off_compensation_peak_to_peak: float = float("nan")
    off_compensation_fell: bool = False
    misses: str | None = None
    balanced_fraction: float = float("nan")


@dataclass(frozen=True)
class TuneResult:
    """The outcome of :func:`tune`.

    Attributes
    ----------
    spec : Spec
        The experiment with the tuned weights (what :meth:`to_toml` writes).
    weights : dict
        The change to the file's weights: factors ``arm``, ``pendulum``, ``input`` (on Q and R,
        and on the MPC's weights by their square roots), ``measurement_noise`` (on
        ``kalman.measurement_noise``), the ``integral_weight`` set and ``recovery``, the
        loop-transfer-recovery parameter ``q`` (``kalman.disturbance_gain`` and
        ``kalman.measurement_noise`` divided by it: ``rip_core::tune::RECOVERY``); and the
        controllers' own keys changed on top of these where the shared cost left them short
        of the bar (``rip_core::tune::own``): LQR's input-disturbance observer,
        ``lqr_disturbance_bandwidth`` (``lqr.disturbance_bandwidth``, Hz; 0 for none); LQG's
        filter, ``lqg_measurement_noise`` and
        ``lqg_disturbance`` (factors on ``kalman.measurement_noise`` and
        ``kalman.disturbance_gain``, which the MPC shares) or ``lqg_input_disturbance``
        (``kalman.input_disturbance`` set: LQG's own filter with an input disturbance its law
        cancels; 0 for none), ``lqg_regulate_outputs`` (``kalman.regulate_outputs``: LQG's law
        on the estimated outputs instead of the plant part of the estimate), and the MPC's
        weights,
        ``mpc_arm``, ``mpc_pendulum``, ``mpc_rate`` (factors on its output and input-rate
        weights, by their square roots) and ``mpc_input`` (an input weight, relative to the
        input-rate weight).
    kept_file_weights : bool
        Whether the file's own weights were kept (they already worked).
    works : bool
        Whether every controller meets the bar with them.
    bar : Bar
        The rig's bar.
    controllers : dict
        :class:`ControllerTuning` per controller name.
    tried : int
        Candidates assessed.
    runs : int
        Robustness runs per controller.
    perturbation : str
        How those runs drew rigs.
    header : list of str
        Comment lines of the input file kept at the top of the tuned file (an identification's
        ``# UNTRUSTED`` marker stays).
    record : str
        The tuning record (TOML) that :meth:`write` puts beside the tuned file: the checksum
        of the tuned design and each controller's prediction, which ``rip-rt run``'s
        pre-flight reads instead of simulating again while the checksum matches, and the
        rig's untrusted identification, if it is (``untrusted``).
    source : pathlib.Path or None
        The rig file tuned, which :meth:`write` does not overwrite unless asked.
    untrusted : str or None
        Why the rig's identification is not trusted (its ``# UNTRUSTED`` header, or the
        ``.identification.toml`` beside it), or None: the tuning is only as good as that model.
    refusal : str or None
        Why the tuning failed outright (every controller falls on the rig's model with the
        weights found), or None; :meth:`write` refuses such a result.
    notes : list of str
        Settings other than the weights that the tuning changed so that ``rip-rt`` runs the
        file as written, each with why (``swing_up.arm_limit`` lowered to the largest a stop
        during the swing can brake from inside ``safety.arm_limit``).
    swing_up : SwingUpTuning or None
        The swing-up settings searched on the tuned controllers and written into ``spec``'s
        ``[swing_up]``, with their verdict and statistics; None when not searched.
    """

    spec: Spec
    weights: Dict[str, float]
    kept_file_weights: bool
    works: bool
    bar: Bar
    controllers: Dict[str, ControllerTuning]
    tried: int
    runs: int
    perturbation: str
    header: List[str] = field(default_factory=list)
    record: str = ""
    source: Path | None = None
    untrusted: str | None = None
    refusal: str | None = None
    notes: List[str] = field(default_factory=list)
    swing_up: SwingUpTuning | None = None

    def write(self, out: PathLike, *, overwrite: bool = False) -> Path:
        """Write the tuned file to ``out`` and its record beside it (``OUT.tune.toml``, the
        name ``rip_core::preflight::tune_record_path`` gives): both, or neither.

        Parameters
        ----------
        out : path-like
            The tuned file.
        overwrite : bool
            Allow the tuned file or its record to replace the rig file tuned.

        Returns
        -------
        pathlib.Path
            The record's path.

        Raises
        ------
        ConfigError
            The tuning failed outright (``refusal``).
        riprs._outputs.OutputError
            ``out`` or its record is a directory, cannot be written, or is the rig file
            tuned (without ``overwrite``); nothing is written.
        """
        if self.refusal is not None:
            raise ConfigError(self.refusal)
        out, side = check_out(out, self.source, overwrite=overwrite)
        _outputs.write([(out, self.to_toml()), (side, self.record)])
        return side

    def report(self) -> str:
        """The per-controller table ``riprs tune`` prints."""
        w = self.weights
        lines = (
            [f"WARNING: {self.untrusted}; these weights are only as good as that model", ""]
            if self.untrusted
            else []
        )
        lines += [*self.notes, ""] if self.notes else []
        lines += [
            "weights: "
            + (
                "the file's own (they work)"
                if self.kept_file_weights
                else f"Q arm x{w['arm']:g}, Q pendulum x{w['pendulum']:g}, R x{w['input']:g}, "
                f"kalman.measurement_noise x{w['measurement_noise']:g}, "
                f"lqr.integral_weight {w['integral_weight']:g}, "
                f"loop transfer recovery q = {w['recovery']:g}"
                + (
                    f"; LQR cancelling an input disturbance: "
                    f"lqr.disturbance_bandwidth = {w['lqr_disturbance_bandwidth']:g} Hz"
                    if w["lqr_disturbance_bandwidth"] > 0.0
                    else ""
                )
                + (
                    f"; LQG's own filter cancelling an input disturbance: "
                    f"kalman.input_disturbance = {w['lqg_input_disturbance']:g} V^2"
                    if w["lqg_input_disturbance"] > 0.0
                    else ""
                )
                + (
                    "; LQG regulating the estimated outputs: kalman.regulate_outputs = true"
                    if w["lqg_regulate_outputs"]
                    else ""
                )
                + (
                    f"; LQG's own filter: kalman.measurement_noise "
                    f"x{w['lqg_measurement_noise']:g}, kalman.disturbance_gain "
                    f"x{w['lqg_disturbance']:g}"
                    if (w["lqg_measurement_noise"], w["lqg_disturbance"]) != (1.0, 1.0)
                    else ""
                )
                + (
                    f"; the MPC's own: output weights x sqrt({w['mpc_arm']:g}), "
                    f"x sqrt({w['mpc_pendulum']:g}), input rate x sqrt({w['mpc_rate']:g}), "
                    f"input weight {w['mpc_input']:g} x the rate's"
                    if (w["mpc_arm"], w["mpc_pendulum"], w["mpc_rate"], w["mpc_input"])
                    != (1.0, 1.0, 1.0, 0.0)
                    else ""
                )
            ),
            f"lqr.Q = {list(self.spec.lqr.Q)}, lqr.R = {self.spec.lqr.R:g}, "
            f"mpc.output_weights = {list(self.spec.mpc.output_weights)}, "
            f"mpc.input_rate_weights = {list(self.spec.mpc.input_rate_weights)}",
        ]
        c = self.spec.compensation
        if (c.dead_zone_gain, c.friction_gain) != (1.0, 1.0):
            lines.append(
                f"compensation.dead_zone_gain = {c.dead_zone_gain:g}, compensation.friction_gain "
                f"= {c.friction_gain:g}: the identified dead zone and friction compensated by "
                "these multiples, so that an identification 30 % off leaves no limit cycle"
            )
        lines += [
            "",
            f"{'':4} {'RMSE arm':>9} {'pend':>7} {'volt':>6} | {'GM dB':>11} {'PM deg':>6} "
            f"{'disk':>5} | {'p-p arm':>7} {'|alpha|':>7} {'offset':>6} {'peak V':>6} | "
            f"balanced ({self.perturbation})",
        ]
        for name, c in self.controllers.items():
            m = c.margins
            frac = "-" if np.isnan(c.balanced_fraction) else f"{c.balanced_fraction:.0%}"
            lines.append(
                f"{name:4} {c.rmse[0]:9.4f} {c.rmse[1]:7.4f} {c.rmse[2]:6.2f} | "
                f"{m.gain_margin_db:5.1f}/{m.gain_reduction_db:5.1f} {m.phase_margin_deg:6.1f} "
                f"{m.disk_margin:5.2f} | {c.arm_peak_to_peak:7.3f} {c.pendulum:7.3f} "
                f"{c.offset:6.3f} {c.peak_voltage:6.2f} | {frac} of {self.runs}"
                + ("  (falls)" if c.fell else "" if c.works else "  (misses the bar)")
            )
        off = [
            f"{n} falls"
            if c.off_compensation_fell
            else f"{n} p-p {c.off_compensation_peak_to_peak:.3f}"
            for n, c in self.controllers.items()
        ]
        lines.append(
            f"with the compensation {self.bar.off_compensation:.0%} off and stiction: "
            + ", ".join(off)
        )
        if self.swing_up is not None:
            sw = self.swing_up
            lines.append("")
            lines.append(
                f"swing-up: {sw.verdict.replace('_', ' ')} (method = {sw.method}, "
                + ", ".join(f"{k} = {v:g}" for k, v in sw.settings.items())
                + f"; {sw.tried} settings tried)"
            )
            if sw.plan is not None:
                lines.append(
                    f"  the plan: {sw.plan['duration_s']:.2f} s from hanging to upright, "
                    f"{sw.plan['voltage_left']:.2f} V and {sw.plan['arm_left']:.2f} rad of arm "
                    f"travel left on the nominal model, {sw.plan['rises']} rise(s) into the "
                    "upper half"
                )
            lines += [f"  {line}" for line in sw.summary.splitlines()]
        lines.append("")
        lines.append(f"the rig's bar: {self.bar.summary}")
        short = {n: c for n, c in self.controllers.items() if c.misses is not None}
        if self.works:
            lines.append("every controller meets the bar")
        elif self.refusal is not None:
            lines.append(f"NO controller balances this rig: {self.refusal}")
        else:
            lines.append(
                "NOT every controller meets the bar with any candidate tried: these weights miss "
                "it by least (rip-rt run's pre-flight refuses these with the same words):"
            )
            lines += [f"  SHORT {n}: {c.misses}" for n, c in short.items()]
        return "\n".join(lines)

    def to_toml(self) -> str:
        """The tuned experiment file: the input file's comment header, then every section
        resolved (``riprs compare``, ``riprs campaign`` and ``rip-rt run`` read it as is)."""
        head = list(self.header)
        summary = ", ".join(
            f"{n} {'ok' if c.works else 'misses the bar'}" for n, c in self.controllers.items()
        )
        head.append(f"# Tuned by riprs tune ({summary}).")
        body = _without_defaults(self.spec.to_toml(), ("controllers", "monte_carlo"))
        return "\n".join(head) + "\n" + body


@dataclass(frozen=True)
class PreflightFinding:
    """One pre-flight check's conclusion.

    Attributes
    ----------
    check : str
        ``"identification"``, ``"voltage"`` or ``"prediction"``.
    verdict : str
        ``"pass"``, ``"warn"`` or ``"refuse"``.
    message : str
        Why (the prediction, the margin, the voltage it would need).
    """

    check: str
    verdict: str
    message: str


def record_path(tuned: PathLike) -> Path:
    """The tuning record beside a tuned file: ``tuned.toml`` -> ``tuned.tune.toml``.

    The core's naming rule, the one ``rip-rt run`` reads the record by.

    Parameters
    ----------
    tuned : path-like
        The tuned experiment file.

    Returns
    -------
    pathlib.Path
        The record's path, beside ``tuned``.
    """
    return Path(tune_record_path(tuned))


def _blocks(text: str) -> List[Tuple[str, str]]:
    """``(name, text)`` of each top-level block of a resolved spec: the keys before the first
    table under ``""``, then each table (``[[...]]`` arrays under their own name)."""
    out: List[Tuple[str, str]] = [("", "")]
    for line in text.splitlines(keepends=True):
        if line.startswith("["):
            out.append((line.strip().strip("[]"), line))
        else:
            out[-1] = (out[-1][0], out[-1][1] + line)
    return out


def _without_defaults(text: str, names: Tuple[str, ...]) -> str:
    """``text`` without the top-level ``controllers`` key and the tables of ``names`` where
    they are the defaults, so that the tuned file is also the experiment part of a campaign
    spec (which sets its controllers and runs in ``[campaign]``)."""
    default = dict(_blocks(Spec().to_toml()))
    keep = []
    for name, block in _blocks(text):
        if name == "":
            lines = block.splitlines(keepends=True)
            plain = [ln for ln in lines if not ln.startswith("controllers")]
            if "controllers" in names and "".join(plain) != block:
                default_top = [ln for ln in default[""].splitlines(keepends=True)]
                if [ln for ln in lines if ln.startswith("controllers")] == [
                    ln for ln in default_top if ln.startswith("controllers")
                ]:
                    block = "".join(plain)
        elif name in names and block == default.get(name):
            continue
        keep.append(block)
    return "".join(keep).lstrip("\n")


def _spec(rig: Union[Spec, PathLike]) -> Spec:
    return rig if isinstance(rig, Spec) else load_config(os.fspath(rig))


def _controller(name: str) -> str:
    up = str(name).upper()
    if up not in CONTROLLERS:
        raise ValueError(f"controller: expected one of LQR, LQG, MPC, got {name!r}")
    return up


def margins(rig: Union[Spec, PathLike], controller: str, Ts: float = TS) -> Margins:
    """The robustness margins of ``controller``'s loop at the plant input.

    Parameters
    ----------
    rig : Spec or path
        The experiment (its design model, weights and estimator).
    controller : {"LQR", "LQG", "MPC"}
        The controller, without its compensation.
    Ts : float
        Sample time (s).

    Returns
    -------
    Margins
    """
    return Margins._from(loop_margins(_spec(rig), _controller(controller), Ts))


def preflight(
    rig: PathLike,
    controller: str,
    Ts: float = TS,
    arm_limit: float | None = None,
) -> List[PreflightFinding]:
    """The pre-flight check ``rip-rt run`` makes before enabling the motor, for a run that
    starts balanced: the swing_up check of ``rip-rt run --swing-up`` (whether the rig can be
    swung up at all) is not made.

    Parameters
    ----------
    rig : path
        The experiment file (its identification marker is read too).
    controller : {"LQR", "LQG", "MPC"}
        The controller to run.
    Ts : float
        Sample time (s).
    arm_limit : float, optional
        ``safety.arm_limit`` (rad): a predicted arm beyond it refuses.

    Returns
    -------
    list of PreflightFinding
    """
    spec = _spec(rig)
    return [
        PreflightFinding(*f)
        for f in preflight_check(spec, _controller(controller), Ts, os.fspath(rig), arm_limit)
    ]


def check_out(
    out: PathLike,
    rig: PathLike | None,
    *,
    overwrite: bool = False,
    key: str = "out",
    force: str = "overwrite=True",
) -> Tuple[Path, Path]:
    """Check, before a tuning, that its tuned file ``out`` and the record beside it can be
    written (:meth:`TuneResult.write` checks the same).

    Parameters
    ----------
    out : path-like
        The tuned file.
    rig : path-like or None
        The rig file tuned: neither output may replace it (nor its identification file)
        unless ``overwrite``.
    overwrite : bool
        Allow that.
    key, force : str
        The argument naming ``out``, and how the caller allows overwriting, for the message.

    Returns
    -------
    tuple of pathlib.Path
        ``(out, record)``.

    Raises
    ------
    riprs._outputs.OutputError
        The message begins with ``key``.
    """
    path = Path(os.fspath(out))
    inputs: List[PathLike] = []
    if rig is not None:
        inputs = [rig, identification_path(rig)]
    out_path, side = _outputs.check(
        [path, record_path(path)], key=key, inputs=inputs, overwrite=overwrite, force=force
    )
    return out_path, side


def _header(path: Path | None) -> List[str]:
    if path is None:
        return []
    out = []
    for line in path.read_text().splitlines():
        if line.strip().startswith("#"):
            out.append(line)
        elif line.strip():
            break
    return out


def _covariance(path: Path | None, spec: Spec) -> Tuple[List[str], np.ndarray] | None:
    """``(names, log_covariance)`` of the rig's ``[plant_covariance]``
    (:func:`riprs.identify.read_plant_covariance`: the rig file's or its identification
    file's), converted to the covariance of the parameters' logarithms at the file's values,
    ``C_ij / (p_i p_j)`` (first order); a parameter at zero (a friction identified as none) is
    held there."""
    if path is None:
        return None
    try:
        found = read_plant_covariance(path)
    except IdentifyError as exc:
        raise ConfigError(str(exc)) from None
    if found is None:
        return None
    names, matrix = found
    values = spec.params.to_dict()
    unknown = [n for n in names if n not in values]
    if unknown:
        raise ConfigError(
            f"{identification_path(path)}: plant_covariance: {unknown[0]!r} is not a [plant] "
            "parameter"
        )
    v = np.array([float(values[n]) for n in names])
    scale = np.divide(1.0, v, out=np.zeros_like(v), where=v > 0)
    return names, matrix * np.outer(scale, scale)


def tune(
    rig: Union[Spec, PathLike],
    *,
    Ts: float = TS,
    runs: int = 20,
    seed: int = 0,
    spread: float = 0.1,
    progress: bool = True,
    swing_up: bool = True,
) -> TuneResult:
    """Chooses shared weights for LQR, LQG and MPC on this rig (``riprs tune``).

    Keeps the file's weights when every controller meets the bar with them; otherwise tries
    the candidates of ``rip_core::tune::candidates`` (the estimator's measurement noise, R, the
    arm weight, integral action, then the pendulum weight) and keeps the first that works, or
    the one that misses by least; where a controller is still short, a second grid whose cost
    holds the pendulum harder against the arm (``rip_core::tune::pendulum_led_candidates``),
    kept when fewer controllers are short with it; a controller that works on the tuning's
    noise seeds and falls with the compensation 30 % off on further ones
    (``rip_core::tune::FALL_CHECK_SEEDS``) is short. Then draws ``runs`` rigs around this one,
    from the identification's covariance (the ``.identification.toml`` beside the file) or
    each parameter within ``1 +- spread``, and counts the runs each tuned controller
    balances.

    Parameters
    ----------
    rig : Spec or path
        The rig's experiment file (``riprs identify`` writes one).
    Ts : float
        Sample time (s).
    runs : int
        Robustness runs per controller (0 for none).
    seed : int
        Seed of the robustness runs.
    spread : float
        Relative spread of each parameter where there is no covariance.
    progress : bool
        Show a progress bar on a terminal.
    swing_up : bool
        Also search the swing-up's catch settings on the tuned controllers
        (``rip_core::tune::swing``: 25 s to a minute) and write them into the file's
        ``[swing_up]``, their verdict into the record (``TuneResult.swing_up``).

    Returns
    -------
    TuneResult

    Raises
    ------
    ConfigError
        The file is invalid, no controller can balance its rig at the voltage bound (the
        pre-flight's voltage check, before any search), no ``swing_up.arm_limit`` leaves a
        stop during the swing room inside ``safety.arm_limit`` (the message names the keys to
        change), or no candidate can be designed.
        An argument out of range is one too, naming it: ``Ts`` outside the loop periods a
        rig file allows (1-20 ms), ``runs`` outside 0-1000, ``seed`` not an integer in
        0..2**64-1, ``spread`` outside [0, 1) (``rip_core::tune::Settings``).
    KeyboardInterrupt
        Ctrl-C, within a fraction of a second.
    """
    path = None if isinstance(rig, Spec) else Path(os.fspath(rig))
    spec = _spec(rig)
    tune_check(spec, Ts, runs, seed, spread)
    # The swing-up's arm limit rip-rt accepts, before the search: the tuning record's
    # swing-up verdict is then the verdict on the file as written.
    fitted = spec.with_stoppable_swing_up()
    notes = []
    if fitted.swing_up["arm_limit"] != spec.swing_up["arm_limit"]:
        notes.append(
            f"swing_up.arm_limit: {spec.swing_up['arm_limit']:g} -> "
            f"{fitted.swing_up['arm_limit']:g} rad, the largest from which a stop during the "
            "swing can brake the arm inside safety.arm_limit (rip-rt run --swing-up refuses "
            "more)"
        )
        spec = fitted
    # Checked as integers (NumPy's too); as Python ints the chunks' seeds cannot overflow.
    runs, seed = operator.index(runs), operator.index(seed)
    cov = _covariance(path, spec)
    untrusted = None if path is None else identification_untrusted(path)
    bar = _progress.bar(progress, total=1 + runs, desc="riprs tune", unit="step")

    def advance(done: int, total: int) -> None:
        # The search's steps first (their count grows when it begins its second pass), then
        # one per robustness run.
        bar.total = total + runs
        bar.n = done
        bar.refresh()

    try:
        (
            tuned,
            weights,
            works,
            assessments,
            tried,
            record,
            refusal,
            shortfalls,
            rig_bar,
            searched,
        ) = tune_weights(
            spec, Ts, untrusted, None if bar is None else advance, swing_up=bool(swing_up)
        )
        if bar is not None:
            bar.n = bar.total - runs
            bar.refresh()
        fractions: Dict[str, float] = {}
        # Rigs drawn around one no controller balances would only confirm it.
        if runs > 0 and refusal is None:
            counts = {n: 0.0 for n in CONTROLLERS}
            done, chunk = 0, 5
            while done < runs:
                n = min(chunk, runs - done)
                # Each chunk draws from its own seed; past the last u64 they wrap around.
                at = (seed + done) % 2**64
                if cov is not None:
                    part = tune_robustness(
                        tuned, n, at, Ts, spread, cov[0], np.ascontiguousarray(cov[1])
                    )
                else:
                    part = tune_robustness(tuned, n, at, Ts, spread)
                for name, frac in part:
                    counts[name] += frac * n
                done += n
                if bar is not None:
                    bar.update(n)
            fractions = {n: c / runs for n, c in counts.items()}
    finally:
        if bar is not None:
            bar.close()
    controllers = {}
    for a in assessments:
        name = a["controller"]
        controllers[name] = ControllerTuning(
            controller=name,
            rmse=np.asarray(a["rmse"], dtype=float),
            margins=Margins._from(a["margins"]),
            peak_voltage=float(a["peak_voltage"]),
            saturated=bool(a["saturated"]),
            fell=bool(a["fell"]),
            arm_peak_to_peak=float(a["arm_peak_to_peak"]),
            pendulum=float(a["pendulum"]),
            offset=float(a["offset"]),
            margins_ok=bool(a["margins_ok"]),
            works=bool(a["works"]),
            off_compensation_peak_to_peak=float("nan")
            if a["off_compensation_peak_to_peak"] is None
            else float(a["off_compensation_peak_to_peak"]),
            off_compensation_fell=bool(a["off_compensation_fell"]),
            misses=shortfalls.get(name),
            balanced_fraction=fractions.get(name, float("nan")),
        )
    kept = weights == {
        "arm": 1.0,
        "pendulum": 1.0,
        "input": 1.0,
        "integral_weight": 0.0,
        "measurement_noise": 1.0,
        "recovery": 1.0,
        "lqr_disturbance_bandwidth": 0.0,
        "lqg_measurement_noise": 1.0,
        "lqg_disturbance": 1.0,
        "lqg_input_disturbance": 0.0,
        "lqg_regulate_outputs": False,
        "mpc_arm": 1.0,
        "mpc_pendulum": 1.0,
        "mpc_rate": 1.0,
        "mpc_input": 0.0,
    }
    return TuneResult(
        spec=tuned,
        weights=dict(weights),
        kept_file_weights=kept,
        works=bool(works),
        bar=Bar._from(rig_bar),
        controllers=controllers,
        tried=int(tried),
        runs=runs,
        perturbation=(
            "identification covariance" if cov is not None else f"+-{spread:.0%} per parameter"
        ),
        header=_header(path),
        record=record,
        source=path,
        untrusted=untrusted,
        refusal=refusal,
        notes=notes,
        swing_up=None if searched is None else SwingUpTuning._from(searched),
    )

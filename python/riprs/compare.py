"""The paper's experiment end to end: LQR, LQG and MPC on the nonlinear plant.

:func:`compare` designs the three controllers with the paper's identical weights (eq. (13) for
LQR/LQG, section 3 for the MPC, one Kalman filter shared by LQG and MPC), runs each on the
nonlinear ``paper`` plant with encoder quantisation and white measurement noise while the arm
reference steps 0 -> 1 rad (section 7), and reports the Tab. 1 indices next to the paper's
experimental numbers.

The indices are computed from what a rig records, the measured angles and the commanded
voltage, as

.. math::

    \\mathrm{RMSE}_\\theta = \\sqrt{\\tfrac1N \\sum_k (r_\\theta[k] - y_\\theta[k])^2},\\quad
    \\mathrm{RMSE}_\\alpha = \\sqrt{\\tfrac1N \\sum_k y_\\alpha[k]^2},\\quad
    \\mathrm{RMSE}_u = \\sqrt{\\tfrac1N \\sum_k u[k]^2},

over every sample of the run (a run that falls is cut at the fall and flagged).

With ``start="down"`` (``riprs compare --start down``) every controller starts with the
pendulum hanging at rest inside a :class:`riprs.SwingUp` (the ``[swing_up]`` settings of the
spec): it swings up, catches, and ``reference.step_time`` seconds after the catch the arm
reference steps 0 -> 1 rad, as ``rip-rt run --swing-up`` does on the rig, so that an overlay
lines up; the run is ``reference.duration + riprs.SWING_UP_ALLOWANCE`` seconds long. Its Tab. 1
indices are taken over the window that lines up with the paper's run (``reference.duration``
seconds from the catch, i.e. from ``reference.step_time`` before the step, the pendulum angle
wrapped). The table adds the time to upright (the catch), and the Monte Carlo reports per
controller the success rate and the time-to-upright distribution (``rip-core``'s definitions,
:attr:`riprs.SimResult.swing_up_succeeded`, :attr:`riprs.SimResult.time_to_upright`).
"""

from __future__ import annotations

import csv
import errno
import os
import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import numpy as np

from riprs import _progress as _bars
from riprs import paper
from riprs._riprs import (
    RiprsError,
    SwingUp,
    table1_rmse,
)
from riprs.config import ConfigError, Spec, load_config
from riprs.sim import BatchMetrics, SimResult, simulate, simulate_metrics

__all__ = [
    "MAX_MONTE_CARLO_RUNS",
    "STARTS",
    "CompareResult",
    "MonteCarloResult",
    "OutputPathError",
    "Trajectory",
    "build_controllers",
    "compare",
    "describes_paper_rig",
    "format_table",
    "rmse",
    "start_of_logs",
    "wrap_angle",
]

PathLike = Union[str, "os.PathLike[str]"]

#: Most Monte Carlo runs per controller: their metrics take about 90 bytes each.
MAX_MONTE_CARLO_RUNS = 1_000_000

#: Where a comparison starts: ``"up"`` balanced near upright (the paper's experiment),
#: ``"down"`` hanging at rest, swung up and caught first.
STARTS = ("up", "down")


class OutputPathError(RiprsError):
    """The output directory cannot take the results (empty path, a file in the way, not
    writable, too little free space); found before any simulation runs."""


@dataclass(frozen=True)
class Trajectory:
    """What the plots and CSV files need from one run: a simulation or a ``rip-rt`` log."""

    t: np.ndarray
    arm: np.ndarray
    pendulum: np.ndarray
    voltage: np.ndarray
    reference: np.ndarray
    fell: bool = False
    #: The switch from swing-up to balance (s), for runs that started hanging.
    catch_time: float | None = None

    @classmethod
    def from_sim(cls, result: SimResult) -> Trajectory:
        """From a simulation; the pendulum angle wrapped as a ``rip-rt`` log holds it."""
        return cls(
            t=result.t,
            arm=result.y[:, 0],
            pendulum=wrap_angle(result.y[:, 1]),
            voltage=result.u,
            reference=result.r[:, 0],
            fell=result.fell,
            catch_time=result.catch_time,
        )

    @classmethod
    def from_log(cls, log: Any) -> Trajectory:
        """From a :class:`riprs.RtLog` (``riprs.load_log``), on a simulation's time axis.

        A swing-up's log (``swing_up`` rows in its ``phase`` column) counts its time from its
        first ``swing_up`` row, as a simulation started hanging counts from the start of its
        swing: the sign check and the wait for rest before it are left out, and its catch
        (the first ``balance`` row after the swing) is marked like the simulation's. A log of
        a run started upright is taken as it is.
        """
        t = np.asarray(log.t, dtype=float)
        swinging = np.flatnonzero(np.asarray(log.phase) == "swing_up")
        if swinging.size == 0:
            return cls(
                t=t,
                arm=log.theta,
                pendulum=wrap_angle(log.alpha),
                voltage=log.u,
                reference=log.theta_ref,
            )
        first = int(swinging[0])
        catch = log.catch_index
        t0 = t[first]
        return cls(
            t=t[first:] - t0,
            arm=np.asarray(log.theta)[first:],
            pendulum=wrap_angle(np.asarray(log.alpha)[first:]),
            voltage=np.asarray(log.u)[first:],
            reference=np.asarray(log.theta_ref)[first:],
            catch_time=None if catch is None or catch < first else float(t[catch] - t0),
        )


def wrap_angle(angle: Any) -> np.ndarray:
    """An angle wrapped to (-pi, pi], as ``rip-rt`` measures the pendulum (0 upright).

    A swing-up's simulated pendulum angle is continuous and climbs past pi with every turn; the
    rig's log holds it wrapped. Figures, CSV files and the indices of a run started hanging use
    this one wrapping for both, so that they draw and compare alike.
    """
    a = np.asarray(angle, dtype=float)
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


def start_of_logs(logs: Mapping[str, Any], start: str | None = None) -> str:
    """How the runs of ``rip-rt`` logs started, to overlay them on simulations started alike.

    A log whose ``phase`` column holds ``swing_up`` rows is of a run started hanging
    (``rip-rt run --swing-up``): ``"down"``; any other is of a run balanced from upright:
    ``"up"``.

    Parameters
    ----------
    logs : mapping of str to riprs.RtLog
        The logs, by the name used in messages (their file).
    start : {"up", "down"}, optional
        The start asked for (``riprs compare --start``); default: the logs'.

    Returns
    -------
    str
        ``"up"`` or ``"down"``: ``start`` if given and the logs agree, else the logs' (``"up"``
        without logs).

    Raises
    ------
    riprs.ConfigError
        The logs started differently, or not as ``start`` says.
    """
    if start is not None and start not in STARTS:
        raise ConfigError(f"start must be one of {STARTS}, got {start!r}")
    starts = {
        name: "down" if np.any(log.phase == "swing_up") else "up" for name, log in logs.items()
    }
    found = set(starts.values())
    if len(found) > 1:
        listed = ", ".join(f"{name}: {how}" for name, how in starts.items())
        raise ConfigError(
            f"the logs started differently ({listed}); overlay each with its own --start"
        )
    if start is not None and found and start not in found:
        name, how = next(iter(starts.items()))
        reason = "swings up first" if how == "down" else "has no swing-up"
        raise ConfigError(
            f"--start {start}, but the log {name} {reason} (its phase column): overlay it with "
            f"--start {how} or without --start"
        )
    return start if start is not None else (found.pop() if found else "up")


def rmse(traj: Trajectory) -> tuple[float, float, float]:
    """The Tab. 1 indices ``(arm, pendulum, voltage)`` of a run or a log: ``rip-core``'s one
    definition (module docs), the same as :attr:`riprs.SimResult.rmse`."""
    return table1_rmse(
        np.ascontiguousarray(traj.arm, dtype=float),
        np.ascontiguousarray(traj.pendulum, dtype=float),
        np.ascontiguousarray(traj.voltage, dtype=float),
        np.ascontiguousarray(traj.reference, dtype=float),
    )


@dataclass(frozen=True)
class MonteCarloResult:
    """Per controller, the metrics of every Monte Carlo run (:class:`riprs.BatchMetrics`).

    Only a few numbers per run are kept, never a trajectory, so a study of any size fits in
    memory. The RMSE indices are :attr:`riprs.SimResult.rmse`'s (``rip-core``'s Tab. 1
    definition).
    """

    runs: dict[str, BatchMetrics]

    @property
    def rmse(self) -> dict[str, np.ndarray]:
        """Per controller, one row ``(rmse_arm, rmse_pendulum, rmse_voltage)`` per run."""
        return {name: m.rmse for name, m in self.runs.items()}

    @property
    def fell(self) -> dict[str, np.ndarray]:
        """Per controller, whether each run fell."""
        return {name: m.fell for name, m in self.runs.items()}

    @property
    def time_to_upright(self) -> dict[str, np.ndarray]:
        """Per controller, the time to upright of each run (NaN without a catch; swing-up
        studies only)."""
        return {name: m.time_to_upright for name, m in self.runs.items()}

    def swing_up_summary(self) -> dict[str, dict[str, float]]:
        """Per controller: the success rate (:attr:`riprs.SimResult.swing_up_succeeded`) and
        the median and 95th percentile of the time to upright over the runs that caught."""
        out: dict[str, dict[str, float]] = {}
        for name, m in self.runs.items():
            caught = m.time_to_upright[np.isfinite(m.time_to_upright)]
            out[name] = {
                "success_rate": float(np.mean(m.swing_up_succeeded)),
                "caught_rate": float(len(caught) / len(m)),
                "upright_median": float(np.median(caught)) if len(caught) else float("nan"),
                "upright_p95": float(np.percentile(caught, 95)) if len(caught) else float("nan"),
                "peak_arm": float(np.max(m.peak_arm)),
                "peak_voltage": float(np.max(m.peak_voltage)),
            }
        return out

    def summary(self) -> dict[str, dict[str, float]]:
        """Mean and standard deviation of each index over the runs that stayed up, and the fall
        rate."""
        out: dict[str, dict[str, float]] = {}
        for name, m in self.runs.items():
            up = m.rmse[~m.fell]
            stats: dict[str, float] = {"fall_rate": float(m.fell.mean())}
            for j, key in enumerate(("arm", "pendulum", "voltage")):
                column = up[:, j] if len(up) else np.array([np.nan])
                stats[f"{key}_mean"] = float(np.mean(column))
                stats[f"{key}_std"] = float(np.std(column))
            out[name] = stats
        return out


@dataclass
class CompareResult:
    """Everything :func:`compare` produced."""

    config: Spec
    seed: int
    runs: dict[str, SimResult]
    trajectories: dict[str, Trajectory]
    summary: dict[str, tuple[float, float, float]]
    monte_carlo: MonteCarloResult | None = None
    files: list[Path] = field(default_factory=list)
    start: str = "up"
    #: The logged runs drawn over the simulations (``overlays``), by label.
    overlays: dict[str, Trajectory] = field(default_factory=dict)

    @property
    def logged(self) -> dict[str, tuple[float, float, float]]:
        """Each logged run's own Tab. 1 indices, over the same window as a simulation's."""
        return {name: rmse(_paper_window(tr, self.config)) for name, tr in self.overlays.items()}

    def table(self) -> str:
        """The Tab. 1 layout: each simulation and each logged run, the paper's experiment
        beside them where the configuration is the paper's rig (and the time to upright for
        a run started hanging)."""
        return format_table(
            self.summary,
            self.runs,
            config=self.config,
            logged=self.logged,
            overlays=self.overlays,
        )


def build_controllers(config: Spec | None = None) -> dict[str, Any]:
    """The configured controllers by name, from ``rip-core``'s one assembly
    (:meth:`riprs.config.Spec.build_controllers` at the paper's sample time)."""
    return (config or Spec()).build_controllers(paper.TS)


def _sim_options(config: Spec, start: str = "up") -> dict[str, Any]:
    """The :func:`riprs.simulate` keywords of a run of ``config`` (rip-core's one mapping of the
    file onto a simulation), without ``duration``."""
    options = config.simulation_options(start, paper.TS)
    del options["duration"]
    return options


def _paper_window(traj: Trajectory, config: Spec) -> Trajectory:
    """The part of a run the Tab. 1 indices are taken over. A run started upright is the
    paper's experiment as it is. Of a run started hanging, the window that lines up with it:
    ``reference.duration`` seconds starting ``reference.step_time`` before the step (so the
    step sits where the paper's does), the pendulum angle wrapped to (-pi, pi]; a run never
    caught is taken whole."""
    if traj.catch_time is None or traj.t[0] == traj.catch_time:
        return traj
    # The step comes reference.step_time after the catch, so the window starts at the catch.
    t0 = traj.catch_time
    window = (traj.t >= t0 - 1e-9) & (traj.t < t0 + config.reference.duration - 1e-9)
    wrapped = wrap_angle(traj.pendulum)
    return Trajectory(
        t=traj.t[window],
        arm=traj.arm[window],
        pendulum=wrapped[window],
        voltage=traj.voltage[window],
        reference=traj.reference[window],
        fell=traj.fell,
        catch_time=traj.catch_time,
    )


def _duration(config: Spec, start: str) -> float:
    return float(config.simulation_options(start, paper.TS)["duration"])


def _supervised(config: Spec, controllers: Mapping[str, Any]) -> dict[str, Any]:
    """Each balance controller inside a :class:`riprs.SwingUp` with the spec's ``[swing_up]``
    settings, designed on its ``[plant]``."""
    plant = config.build_plant()
    return {
        name: SwingUp(balance=c, plant=plant, **config.swing_up) for name, c in controllers.items()
    }


def _progress(iterable: Sequence[Any], desc: str, enabled: bool) -> Any:
    shown = _bars.bar(enabled, iterable=iterable, desc=desc, unit="run", leave=False)
    return iterable if shown is None else shown


def compare(
    config: Spec | PathLike | None = None,
    out: PathLike | None = None,
    seed: int = 0,
    *,
    monte_carlo: int | None = None,
    plots: bool = True,
    progress: bool = True,
    overlays: Mapping[str, Trajectory] | None = None,
    start: str = "up",
) -> CompareResult:
    """Run the paper's comparison.

    Parameters
    ----------
    config : Spec, path to a TOML file, or None
        Settings; the paper's by default (see :mod:`riprs.config`). The whole file is checked,
        including that every controller can be designed, before any simulation.
    out : path, optional
        Directory for ``summary.csv``, ``trajectories.csv`` and the figures (created if needed).
        It is checked before anything runs (:class:`OutputPathError`: an empty path, a file in
        the way, not writable, too little free space); the files are written to a temporary
        directory beside it and moved into place only when all are complete, so a failure or
        Ctrl-C never leaves a half-written result.
    seed : int
        Noise seed; equal seeds give identical results.
    monte_carlo : int, optional
        Overrides ``config.monte_carlo.runs``: that many extra runs over noise seeds and
        parameter perturbations, in parallel.
    plots : bool
        Write PNG and SVG figures (needs ``out``).
    progress : bool
        Show progress bars (on standard error, and only when it is a terminal).
    overlays : mapping of str to Trajectory, optional
        Further runs (e.g. ``rip-rt`` logs) drawn over the simulations in extra figures
        ``*_with_logs`` (needs ``out`` and ``plots``).
    start : {"up", "down"}
        ``"up"``: the paper's experiment, started near upright. ``"down"``: hanging at rest,
        swung up and caught by a :class:`riprs.SwingUp` around each controller, the arm step
        ``reference.step_time`` after the catch (module docs).

    Returns
    -------
    CompareResult
    """
    if start not in STARTS:
        raise ConfigError(f"start must be one of {STARTS}, got {start!r}")
    if config is None:
        cfg = Spec()
    elif isinstance(config, Spec):
        # A Spec is immutable: overrides below make a new one, the caller's stays as it was.
        cfg = config
    else:
        cfg = load_config(config)
    if monte_carlo is not None:
        if isinstance(monte_carlo, bool) or not isinstance(monte_carlo, int) or monte_carlo < 0:
            raise ConfigError(f"monte_carlo must be a non-negative integer, got {monte_carlo!r}")
        if monte_carlo > MAX_MONTE_CARLO_RUNS:
            raise ConfigError(
                f"monte_carlo.runs must be at most {MAX_MONTE_CARLO_RUNS}, got {monte_carlo}"
            )
        cfg = cfg.updated({"monte_carlo": {"runs": monte_carlo}})
    if cfg.monte_carlo.runs > MAX_MONTE_CARLO_RUNS:
        raise ConfigError(
            f"monte_carlo.runs must be at most {MAX_MONTE_CARLO_RUNS}, got {cfg.monte_carlo.runs}"
        )
    # The output path is checked, and a staging directory made next to it, before any design or
    # simulation: a bad --out fails at once, and a failure later leaves the old results intact.
    staging = _Staging(out, _expected_bytes(cfg, plots)) if out is not None else None
    try:
        # Every design is made, and a failure named by its key, before anything is simulated.
        controllers = build_controllers(cfg)
        if start == "down":
            controllers = _supervised(cfg, controllers)
        plant = cfg.build_plant()
        options = _sim_options(cfg, start)
        runs: dict[str, SimResult] = {}
        for name in _progress(list(controllers), "simulating", progress):
            runs[name] = simulate(
                plant, controllers[name], _duration(cfg, start), seed=seed, **options
            )
        trajectories = {name: Trajectory.from_sim(r) for name, r in runs.items()}
        summary = {name: rmse(_paper_window(t, cfg)) for name, t in trajectories.items()}
        mc = None
        if cfg.monte_carlo.runs > 0:
            mc = _monte_carlo(cfg, controllers, seed, progress, start)
        result = CompareResult(
            cfg,
            seed,
            runs,
            trajectories,
            summary,
            mc,
            start=start,
            overlays=dict(overlays or {}),
        )
        if staging is not None:
            written = write_outputs(result, staging.path, plots=plots)
            if plots and overlays:
                from riprs import plots as plotting

                written += plotting.plot_comparison(
                    {**trajectories, **overlays}, staging.path, suffix="_with_logs"
                )
            result.files = staging.commit(written)
    except BaseException:
        if staging is not None:
            staging.abort()
        raise
    return result


def _expected_bytes(cfg: Spec, plots: bool) -> int:
    """A generous estimate of what the outputs take on disk."""
    samples = round(cfg.reference.duration / paper.TS)
    trajectories = samples * (24 + 4 * 24 * len(cfg.controllers))
    monte_carlo = cfg.monte_carlo.runs * len(cfg.controllers) * 200
    figures = 8 * 2**20 if plots else 0
    return 4096 + trajectories + monte_carlo + figures


class _Staging:
    """Results are written into a temporary directory on the destination's filesystem and
    moved into place only when all of them are complete.

    A new destination is the staging directory renamed (one atomic step); into an existing
    directory each file is moved with :func:`os.replace` (atomic per file, so no file is ever
    half-written). On failure the staging directory is removed and the destination is as it
    was.
    """

    def __init__(self, out: PathLike, needed: int) -> None:
        text = os.fspath(out)
        if not text.strip():
            raise OutputPathError("out: the output directory is an empty path")
        dest = Path(text).expanduser().absolute()
        if dest.exists() and not dest.is_dir():
            raise OutputPathError(f"out: {dest} exists and is not a directory")
        if dest.exists():
            base = dest
        else:
            # The nearest existing ancestor must be a directory we can create entries in.
            base = dest.parent
            while not base.exists():
                base = base.parent
            if not base.is_dir():
                raise OutputPathError(f"out: {base} is not a directory")
        if not os.access(base, os.W_OK | os.X_OK):
            raise OutputPathError(f"out: {base} is not writable")
        free = shutil.disk_usage(base).free
        if free < needed:
            raise OutputPathError(
                f"out: {base} has {free / 2**20:.1f} MiB free; the results need about "
                f"{needed / 2**20:.1f} MiB"
            )
        self.dest = dest
        self._created: list[Path] = []
        parent = dest if dest.exists() else dest.parent
        missing = [p for p in [parent, *parent.parents] if not p.exists()]
        try:
            for p in reversed(missing):
                p.mkdir()
                self._created.append(p)
            self.path = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".tmp", dir=parent))
            # mkdtemp makes it private (0700); the renamed result gets the usual permissions.
            umask = os.umask(0)
            os.umask(umask)
            self.path.chmod(0o777 & ~umask)
        except OSError as exc:
            self._remove_created()
            raise OutputPathError(f"out: cannot create a directory for {dest}: {exc}") from None

    def commit(self, files: list[Path]) -> list[Path]:
        """Move the finished files into the destination; return their final paths."""
        if not self.dest.exists():
            os.rename(self.path, self.dest)
            return [self.dest / f.relative_to(self.path) for f in files]
        final = []
        for f in files:
            target = self.dest / f.relative_to(self.path)
            os.replace(f, target)
            final.append(target)
        shutil.rmtree(self.path, ignore_errors=True)
        return final

    def abort(self) -> None:
        """Remove the staging directory (and directories made for it); the destination is as
        it was."""
        shutil.rmtree(self.path, ignore_errors=True)
        self._remove_created()

    def _remove_created(self) -> None:
        for p in reversed(self._created):
            try:
                p.rmdir()
            except OSError as exc:
                if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOENT):
                    raise


def _monte_carlo(
    cfg: Spec, controllers: Mapping[str, Any], seed: int, progress: bool, start: str = "up"
) -> MonteCarloResult:
    """Run ``i`` uses noise seed ``seed + 1 + i`` and its own parameter draw (see
    :func:`riprs.simulate_metrics`); only per-run metrics are kept."""
    options = _sim_options(cfg, start)
    runs = cfg.monte_carlo.runs
    results: dict[str, BatchMetrics] = {}
    for name, controller in controllers.items():
        bar = _progress_bar(runs, f"monte carlo {name}", progress)
        report = None if bar is None else (lambda done, _total, b=bar: b.update(done - b.n))
        try:
            results[name] = simulate_metrics(
                cfg.build_plant(),
                controller,
                runs,
                _duration(cfg, start),
                seed=seed + 1,
                perturbation=cfg.monte_carlo.perturbation,
                parameters=cfg.monte_carlo.parameters,
                progress=report,
                **options,
            )
        finally:
            if bar is not None:
                bar.close()
    return MonteCarloResult(results)


def _progress_bar(total: int, desc: str, enabled: bool) -> Any:
    return _bars.bar(enabled, total=total, desc=desc, unit="run", leave=False)


def describes_paper_rig(config: Spec) -> bool:
    """Whether ``config``'s plant is the paper's rig (the ``paper`` preset's parameters), the
    one its Tab. 1 experiment was run on."""
    return bool(config.params == Spec().params)


def format_table(
    summary: Mapping[str, tuple[float, float, float]],
    runs: Mapping[str, SimResult] | None = None,
    *,
    config: Spec | None = None,
    logged: Mapping[str, tuple[float, float, float]] | None = None,
    overlays: Mapping[str, Trajectory] | None = None,
) -> str:
    """Tab. 1 layout: per controller, riprs's RMSE, then each logged run's own.

    The paper's experimental values stand beside them only where ``config`` is the paper's
    rig (:func:`describes_paper_rig`; no ``config`` counts as the paper's): on another rig
    they describe a different plant.

    Parameters
    ----------
    summary : mapping of str to (float, float, float)
        Per simulated controller, ``(arm, pendulum, voltage)`` RMSE.
    runs : mapping of str to SimResult, optional
        The simulations (their fall, phase and time to upright).
    config : Spec, optional
        The configuration: its plant, and its ``reference.step_time`` for the header.
    logged : mapping of str to (float, float, float), optional
        Per logged run, its own RMSE over the same window.
    overlays : mapping of str to Trajectory, optional
        The logged runs (their catch, for the time to upright).
    """
    logged = dict(logged or {})
    overlays = dict(overlays or {})
    paper_rig = config is None or describes_paper_rig(config)
    groups = ("arm angle [rad]", "pendulum angle [rad]", "voltage [V]")
    names = list(summary) + list(logged)
    width = max([11, *(len(n) + 2 for n in names)])
    if paper_rig:
        title = "Tab. 1: RMSE in simulation (riprs) and in the paper's experiment (paper)"
        lines = [
            title,
            f"{'':<{width}}" + "".join(f"{g:>22}" for g in groups),
            f"{'run':<{width}}" + f"{'riprs':>12}{'paper':>10}" * 3,
        ]
    else:
        title = (
            "Tab. 1 indices: RMSE in simulation (riprs); the paper's experimental values are "
            'of its own rig (plant.preset = "paper"), not this one'
        )
        lines = [
            title,
            f"{'run':<{width}}" + "".join(f"{g:>22}" for g in groups),
        ]
    down = runs is not None and any(r.phase is not None and r.phase[0] == 0 for r in runs.values())
    down = down or any(tr.catch_time is not None for tr in overlays.values())
    # The time to upright's column: its unit under it beside the paper's two header lines,
    # beside it on the one line otherwise.
    up_width = 10 if paper_rig else 13
    if down:
        step = config.reference.step_time if config is not None else Spec().reference.step_time
        lines[0] += f"; started hanging, the step {step:g} s after the catch"
        if paper_rig:
            lines[1] += f"{'upright':>{up_width}}"
            lines[2] += f"{'[s]':>{up_width}}"
        else:
            lines[1] += f"{'upright [s]':>{up_width}}"

    def cells(values: tuple[float, float, float], ref: tuple[float, ...] | None) -> str:
        if ref is None:
            return "".join(f"{v:>22.4f}" for v in values)
        return "".join(f"{v:>12.4f}{p:>10.3f}" for v, p in zip(values, ref, strict=True))

    def upright(t_up: float | None) -> str:
        return f"{t_up:>{up_width}.2f}" if t_up is not None else f"{'never':>{up_width}}"

    for name, values in summary.items():
        ref = paper.TABLE1.get(name, (float("nan"),) * 3) if paper_rig else None
        note = "  (fell)" if runs is not None and name in runs and runs[name].fell else ""
        row = cells(values, ref)
        if down and runs is not None and name in runs:
            row += upright(runs[name].time_to_upright)
            if not runs[name].swing_up_succeeded and not runs[name].fell:
                note += "  (not caught)"
        lines.append(f"{name:<{width}}{row}{note}")
    for name, values in logged.items():
        row = cells(values, (float("nan"),) * 3 if paper_rig else None)
        if down:
            tr = overlays.get(name)
            row += upright(tr.catch_time if tr is not None else None)
        lines.append(f"{name:<{width}}{row}  (logged)")
    return "\n".join(lines)


def format_swing_up_monte_carlo(mc: MonteCarloResult) -> str:
    """Per controller: swing-up success rate and time to upright (median, 95th percentile)."""
    n = len(next(iter(mc.runs.values())))
    lines = [
        f"Swing-up Monte Carlo: {n} runs per controller from hanging at rest",
        f"{'controller':<11}{'success':>9}{'caught':>9}{'upright median':>16}{'p95':>8}"
        f"{'max |arm|':>11}{'max |u|':>9}",
    ]
    for name, s in mc.swing_up_summary().items():
        lines.append(
            f"{name:<11}{100 * s['success_rate']:>8.1f}%{100 * s['caught_rate']:>8.1f}%"
            f"{s['upright_median']:>14.2f} s{s['upright_p95']:>6.2f} s"
            f"{s['peak_arm']:>9.3f} rad{s['peak_voltage']:>6.2f} V"
        )
    return "\n".join(lines)


def format_monte_carlo(mc: MonteCarloResult) -> str:
    """Mean +- std of each index over the runs that stayed up, and the fall rate."""
    lines = [
        f"Monte Carlo: {len(next(iter(mc.fell.values())))} runs per controller",
        f"{'controller':<11}{'arm [rad]':>20}{'pendulum [rad]':>22}{'voltage [V]':>20}{'falls':>8}",
    ]
    for name, s in mc.summary().items():
        lines.append(
            f"{name:<11}{s['arm_mean']:>11.4f} ± {s['arm_std']:<6.4f}"
            f"{s['pendulum_mean']:>13.5f} ± {s['pendulum_std']:<7.5f}"
            f"{s['voltage_mean']:>11.3f} ± {s['voltage_std']:<6.3f}"
            f"{100 * s['fall_rate']:>7.1f}%"
        )
    return "\n".join(lines)


def write_outputs(result: CompareResult, out: Path, *, plots: bool = True) -> list[Path]:
    """Write ``summary.csv``, ``trajectories.csv`` and the figures into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    files = [_write_summary(result.summary, out / "summary.csv")]
    files.append(_write_trajectories(result.trajectories, out / "trajectories.csv"))
    if result.monte_carlo is not None:
        files.append(_write_monte_carlo(result.monte_carlo, out / "monte_carlo.csv"))
    if plots:
        from riprs import plots as plotting

        files += plotting.plot_comparison(result.trajectories, out)
        if result.monte_carlo is not None:
            files += plotting.plot_monte_carlo(result.monte_carlo, out)
            if result.start == "down":
                files += plotting.plot_time_to_upright(result.monte_carlo, out)
    return files


def _write_summary(summary: Mapping[str, tuple[float, float, float]], path: Path) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["controller", "rmse_arm", "rmse_pendulum", "rmse_voltage"])
        for name, values in summary.items():
            w.writerow([name, *(repr(float(v)) for v in values)])
    return path


def _write_trajectories(trajectories: Mapping[str, Trajectory], path: Path) -> Path:
    """One row per sample; a run that fell leaves its cells empty after the fall."""
    longest = max(trajectories.values(), key=lambda tr: len(tr.t))
    header = ["time"]
    for name in trajectories:
        key = name.lower()
        header += [f"{key}_arm", f"{key}_pendulum", f"{key}_voltage", f"{key}_reference"]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for k, t in enumerate(longest.t):
            row = [repr(float(t))]
            for tr in trajectories.values():
                if k < len(tr.t):
                    row += [
                        repr(float(v))
                        for v in (tr.arm[k], tr.pendulum[k], tr.voltage[k], tr.reference[k])
                    ]
                else:
                    row += ["", "", "", ""]
            w.writerow(row)
    return path


def _write_monte_carlo(mc: MonteCarloResult, path: Path) -> Path:
    """One row per controller and run; empty cells for a fall time or settling time that does
    not exist."""

    def cell(v: float) -> str:
        return repr(float(v)) if np.isfinite(v) else ""

    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "controller",
                "run",
                "seed",
                "rmse_arm",
                "rmse_pendulum",
                "rmse_voltage",
                "fell",
                "fall_time",
                "peak_voltage",
                "settle_time",
                "time_to_upright",
                "swing_up_succeeded",
            ]
        )
        for name, m in mc.runs.items():
            for i in range(len(m)):
                w.writerow(
                    [
                        name,
                        int(m.run[i]),
                        int(m.seed[i]),
                        *(repr(float(v)) for v in m.rmse[i]),
                        int(m.fell[i]),
                        cell(m.fall_time[i]),
                        repr(float(m.peak_voltage[i])),
                        cell(m.settle_time[i]),
                        cell(m.time_to_upright[i]),
                        int(m.swing_up_succeeded[i]),
                    ]
                )
    return path

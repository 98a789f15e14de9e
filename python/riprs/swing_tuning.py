"""The swing-up's statistics and the settings ``riprs tune`` searches for it.

The work is ``rip-core``'s (``rip_core::spec::study::swing_monte_carlo``,
``rip_core::tune::swing``); this module shapes its results into typed objects.
``docs/swing-up.md`` ("The searched swing-up") has the method and the measured figures.
"""

from __future__ import annotations

import operator
import os
from dataclasses import dataclass
from typing import Dict, List, Literal, Tuple, Union

from riprs._riprs import TS, ConfigError, Spec, load_config
from riprs._riprs import swing_up_monte_carlo as _swing_up_monte_carlo

__all__ = ["SwingUpStudy", "SwingUpTuning", "swing_up_monte_carlo"]

PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True)
class SwingUpStudy:
    """One controller's swing-up Monte Carlo over rigs drawn around the file's.

    Each draw multiplies every physical parameter by a factor uniform in
    ``[1 - spread, 1 + spread]``; a dead zone and an arm Coulomb friction the file sets to 0
    are drawn from 0-0.3 V and 0-0.002 N m instead, unknown to the controllers. A run
    succeeds when it is caught and the true pendulum is still within ``plant.fall_limit``
    3 s after the catch; the arm's step after that is reported apart.

    Attributes
    ----------
    controller : {"LQR", "LQG", "MPC"}
        The balance controller.
    runs : int
        Draws.
    excluded : int
        Draws whose swing-up the energy bound proves impossible: not judged.
    caught : int
        Runs caught.
    held : int
        Successes: caught and balanced 3 s later.
    step_tracked : int
        Successes whose arm step was then tracked to the end without a fall.
    caught_on_first : int
        Runs caught on the pendulum's first arrival near upright.
    at_most_two_over_tops : int
        Runs with at most two passes over the top before the catch.
    most_over_tops : int
        The most passes over the top of any run.
    interval : tuple of float
        The Wilson 95 % interval of the success rate ``held / (runs - excluded)``
        (NaN with no run judged).
    """

    controller: Literal["LQR", "LQG", "MPC"]
    runs: int
    excluded: int
    caught: int
    held: int
    step_tracked: int
    caught_on_first: int
    at_most_two_over_tops: int
    most_over_tops: int
    interval: Tuple[float, float]

    @property
    def judged(self) -> int:
        """Runs judged: those drawn less those excluded."""
        return self.runs - self.excluded

    @property
    def success_rate(self) -> float:
        """``held / judged`` (NaN with no run judged)."""
        return self.held / self.judged if self.judged else float("nan")

    @classmethod
    def _from(cls, d: Dict) -> SwingUpStudy:
        lo, hi = d["interval"]
        return cls(
            controller=d["controller"],
            runs=int(d["runs"]),
            excluded=int(d["excluded"]),
            caught=int(d["caught"]),
            held=int(d["held"]),
            step_tracked=int(d["step_tracked"]),
            caught_on_first=int(d["caught_on_first"]),
            at_most_two_over_tops=int(d["at_most_two_over_tops"]),
            most_over_tops=int(d["most_over_tops"]),
            interval=(float(lo), float(hi)),
        )


@dataclass(frozen=True)
class SwingUpTuning:
    """The swing-up settings ``riprs tune`` searched for the rig.

    Attributes
    ----------
    verdict : {"found", "not_found", "impossible"}
        ``"found"`` when every controller's Wilson lower bound on the confirmation runs is at
        least 95 % and at least 99 % of its runs pass over the top at most twice before the
        catch; ``"impossible"`` when the energy bound forbids a swing-up (nothing is
        searched). ``rip-rt run --swing-up`` refuses every controller of a rig whose
        verdict is not ``"found"``, naming those short of either (exit 16, ``--force``
        overrides).
    method : {"energy", "trajectory"}
        The ``swing_up.method`` kept: the plan where the search found it better than the
        energy law (or the file asks for it), the energy law otherwise.
    plan : dict or None
        With the plan kept, its length and margins on the nominal model: ``duration_s``
        (from hanging to upright), ``voltage_left`` (V, the swing-up's bound after the
        compensation's share less the plan's largest voltage), ``arm_left`` (rad,
        ``swing_up.arm_limit`` less the plan's largest arm angle) and ``rises`` (how many
        times the plan's pendulum rises into the upper half, the last time to upright: 1
        where it reaches upright on its first rise); None for the energy law.
    settings : dict
        The numeric ``[swing_up]`` keys the search set: ``catch_prediction``,
        ``catch_margin``, ``energy_margin``, ``rise_damping``, ``reference_return_rate``.
    confirmed : list of SwingUpStudy
        Each controller's study on 1000 fresh draws with those settings, taken 100 at a
        time: a study that can no longer reach 95 % ends there (its ``runs`` say where).
    tried : int
        Candidates judged.
    summary : str
        One line per controller.
    """

    verdict: Literal["found", "not_found", "impossible"]
    method: Literal["energy", "trajectory"]
    plan: Dict[str, float | int] | None
    settings: Dict[str, float]
    confirmed: List[SwingUpStudy]
    tried: int
    summary: str

    @classmethod
    def _from(cls, d: Dict) -> SwingUpTuning:
        return cls(
            verdict=d["verdict"],
            method=d["method"],
            plan=None
            if d["plan"] is None
            else {k: v if k == "rises" else float(v) for k, v in d["plan"].items()},
            settings={k: float(v) for k, v in d["settings"].items()},
            confirmed=[SwingUpStudy._from(m) for m in d["confirmed"]],
            tried=int(d["tried"]),
            summary=str(d["summary"]),
        )


def swing_up_monte_carlo(
    rig: Union[Spec, PathLike],
    controller: str,
    *,
    runs: int = 200,
    seed: int = 2024,
    spread: float = 0.1,
    Ts: float = TS,
) -> SwingUpStudy:
    """The swing-up Monte Carlo of one controller on rigs drawn around this one.

    The controllers and the swing-up are the file's, designed on its nominal plant; each run
    swings up one drawn rig from hanging at rest (:class:`SwingUpStudy` says how they are
    drawn and judged).

    Parameters
    ----------
    rig : Spec or path
        The experiment file.
    controller : {"LQR", "LQG", "MPC"}
        The balance controller.
    runs : int
        Draws (1-100000).
    seed : int
        Seed of the draws and of each run's noise (0..2**64-1).
    spread : float
        Relative half-width of each parameter's factor, in [0, 1).
    Ts : float
        Sample time (s).

    Returns
    -------
    SwingUpStudy

    Raises
    ------
    ConfigError
        A bad argument (naming it) or a file whose controllers cannot be designed.
    KeyboardInterrupt
        Ctrl-C, between two runs.

    Examples
    --------
    >>> import riprs
    >>> spec = riprs.load_config("rig.toml")  # doctest: +SKIP
    >>> study = riprs.swing_up_monte_carlo(spec, "LQR", runs=100)  # doctest: +SKIP
    >>> study.held, study.interval  # doctest: +SKIP
    """
    for name, value in (("runs", runs), ("seed", seed)):
        if isinstance(value, bool):
            raise ConfigError(f"{name} must be an integer, got {value!r}")
        try:
            operator.index(value)
        except TypeError:
            raise ConfigError(f"{name} must be an integer, got {value!r}") from None
    runs, seed = operator.index(runs), operator.index(seed)
    try:
        spread = float(spread)
    except (TypeError, ValueError):
        raise ConfigError(f"spread must be a number, got {spread!r}") from None
    if not 1 <= runs <= 100_000:
        raise ConfigError(f"runs must be in 1..=100000, got {runs}")
    if not 0 <= seed < 2**64:
        raise ConfigError(f"seed must be in 0..2**64-1, got {seed}")
    up = str(controller).upper()
    if up not in ("LQR", "LQG", "MPC"):
        raise ConfigError(f"controller: expected one of LQR, LQG, MPC, got {controller!r}")
    spec = rig if isinstance(rig, Spec) else load_config(os.fspath(rig))
    return SwingUpStudy._from(_swing_up_monte_carlo(spec, up, runs, seed, spread, Ts))

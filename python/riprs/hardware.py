"""The paper's hardware column: its controllers, as printed, on the rig that explains it.

The paper's Tab. 1 was measured on its rig, not simulated. :data:`RIG` is the rig found by the
study of ``scripts/paper_rig_study.py`` (``docs/paper.md``, "The hardware column"): the
``paper`` plant with a voltage dead zone ``Vd``, the arm's Coulomb friction ``Cr``, the cable's
stiffness ``Kc`` and encoders of ``counts`` per revolution with ``noise`` (rad) of white noise,
each within the plausible range of :data:`RANGES`. The controllers are the paper's as printed
(designed on its model, eq. (3), with its weights; they know nothing of the rig's
imperfections and compensate none), so :func:`run` is the paper's experiment on that rig.

The paper states neither when its arm step happens nor over which window its RMSE is taken. The
study fixed one window for all three controllers before it ran: a run of :data:`DURATION`
seconds, the arm reference stepping 0 -> 1 rad at :data:`STEP_TIME`, the indices over
``[WINDOW_START, DURATION)``: the steady state, three seconds after the step, when each
controller on the nominal plant has settled (its arm RMSE over the window is 4-8 mrad with the
default sensor). (Its LQR and MPC arm RMSE,
0.061 and 0.073 rad, are below what the step's transient alone gives over any window that
holds it, about 0.2 rad over 10 s; and the paper describes them as oscillation around the
reference.)
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Mapping

import numpy as np

from riprs import paper
from riprs.config import Spec
from riprs.sim import SimResult, simulate

__all__ = [
    "DURATION",
    "RANGES",
    "RIG",
    "STEP_TIME",
    "WINDOW_START",
    "controllers",
    "format_table",
    "objective",
    "run",
    "spec",
    "table1",
]

#: Length of a run (s).
DURATION = 20.0
#: Time of the 0 -> 1 rad arm step (s).
STEP_TIME = 1.0
#: Start of the RMSE window (s); it ends with the run.
WINDOW_START = 4.0

#: The plausible range of each rig imperfection the study fits (``counts`` of both encoders,
#: ``noise`` the white angle noise in rad).
RANGES: Mapping[str, tuple[float, float]] = MappingProxyType(
    {
        "Vd": (0.0, 1.0),
        "Cr": (0.0, 0.006),
        "Kc": (0.0, 5e-3),
        "counts": (512.0, 8192.0),
        "noise": (0.0, 2e-3),
    }
)

#: The rig the study found (``examples/data/paper_rig_study.json``), to three significant
#: digits: the least objective of its search, 4.26 (docs/paper.md, "The hardware column").
RIG: Mapping[str, float] = MappingProxyType(
    {"Vd": 0.0156, "Cr": 0.000412, "Kc": 0.00317, "counts": 1120.0, "noise": 0.000693}
)


def spec(rig: Mapping[str, float] = RIG) -> Spec:
    """The experiment file of the paper's rig: the ``paper`` plant with ``rig``'s dead zone,
    arm friction and cable, its encoders and noise, and the study's run and step.

    Parameters
    ----------
    rig : mapping of str to float
        ``Vd`` (V), ``Cr`` (N m), ``Kc`` (N m/rad), ``counts`` (per revolution, both
        encoders) and ``noise`` (rad), as :data:`RIG`.

    Returns
    -------
    Spec

    Raises
    ------
    ConfigError
        A value out of its key's range (the message names ``plant.Kc`` and so on).
    """
    counts = round(rig["counts"])
    return Spec().updated(
        {
            "plant": {"Vd": rig["Vd"], "Cr": rig["Cr"], "Kc": rig["Kc"]},
            "sensor": {"encoder_counts": [counts, counts], "noise_std": [rig["noise"]] * 2},
            "reference": {"duration": DURATION, "step_time": STEP_TIME},
        }
    )


def controllers() -> dict[str, object]:
    """LQR, LQG and MPC as the paper printed them: designed on its model with its weights,
    no compensation.

    Returns
    -------
    dict
        ``{"LQR": Lqr, "LQG": Lqg, "MPC": Mpc}``, the default experiment file's controllers.
    """
    return Spec().build_controllers(paper.TS)


def table1(result: SimResult) -> tuple[float, float, float]:
    """Tab. 1's indices of one run over the study's window.

    Parameters
    ----------
    result : SimResult
        A run of :data:`DURATION` seconds.

    Returns
    -------
    tuple of float
        RMSE of the measured arm angle against its reference and of the measured pendulum
        angle (rad), RMS voltage (V), over ``[WINDOW_START, DURATION)``; NaN for a run that
        fell.
    """
    if result.fell:
        return (math.nan,) * 3
    w = result.t >= WINDOW_START - 1e-9
    arm = result.r[w, 0] - result.y[w, 0]
    return (
        float(np.sqrt(np.mean(arm**2))),
        float(np.sqrt(np.mean(result.y[w, 1] ** 2))),
        float(np.sqrt(np.mean(result.u[w] ** 2))),
    )


def run(
    rig: Mapping[str, float] = RIG, seeds: tuple[int, ...] = (0, 1, 2)
) -> dict[str, tuple[float, float, float]]:
    """The paper's experiment on ``rig`` (``riprs compare --hardware``).

    Parameters
    ----------
    rig : mapping of str to float
        The rig (:func:`spec`); the fitted one by default.
    seeds : tuple of int
        Noise seeds; the study's are 0, 1, 2.

    Returns
    -------
    dict of str to tuple of float
        Per controller, Tab. 1's indices (:func:`table1`), each the mean over ``seeds`` (NaN
        when any run fell).
    """
    cfg = spec(rig)
    plant = cfg.build_plant()
    options = cfg.simulation_options("up", paper.TS)
    out = {}
    for name, controller in controllers().items():
        rows = [table1(simulate(plant, controller, seed=s, **options)) for s in seeds]
        out[name] = tuple(float(v) for v in np.mean(rows, axis=0))
    return out


def objective(summary: Mapping[str, tuple[float, float, float]]) -> float:
    r"""The study's objective: the sum over the nine numbers of Tab. 1 of the squared log
    ratio of simulated to printed, :math:`J = \sum_{c,s} \ln^2(\hat e_{c,s} / e_{c,s})`.

    Parameters
    ----------
    summary : mapping of str to tuple of float
        Per controller, ``(arm, pendulum, voltage)`` as :func:`run` returns them.

    Returns
    -------
    float
        ``J``; infinite when a controller fell.
    """
    total = 0.0
    for name, printed in paper.TABLE1.items():
        for sim, ref in zip(summary[name], printed, strict=True):
            if not (sim > 0.0 and math.isfinite(sim)):
                return math.inf
            total += math.log(sim / ref) ** 2
    return total


def format_table(summary: Mapping[str, tuple[float, float, float]]) -> str:
    """Tab. 1 of the rig beside the paper's hardware column, and the objective.

    Parameters
    ----------
    summary : mapping of str to tuple of float
        As :func:`run` returns it.

    Returns
    -------
    str
    """
    groups = ("arm angle [rad]", "pendulum angle [rad]", "voltage [V]")
    lines = [
        "Tab. 1 on the paper's rig (riprs.hardware.RIG), RMSE over "
        f"[{WINDOW_START:g}, {DURATION:g}) s, the step at {STEP_TIME:g} s, beside the paper's "
        "hardware column",
        f"{'':<6}" + "".join(f"{g:>24}" for g in groups),
        f"{'run':<6}" + f"{'riprs':>12}{'paper':>12}" * 3,
    ]
    for name, values in summary.items():
        ref = paper.TABLE1[name]
        lines.append(
            f"{name:<6}"
            + "".join(f"{v:>12.3f}{p:>12.3f}" for v, p in zip(values, ref, strict=True))
        )
    j = objective(summary)
    lines.append(
        f"objective (sum of squared log ratios over the nine numbers): {j:.3f}; "
        f"typical factor exp(sqrt(J/9)) = {math.exp(math.sqrt(j / 9)):.2f}"
    )
    return "\n".join(lines)

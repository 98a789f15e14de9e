"""The model, weights and results of the reproduced study.

Huynh et al., *A survey of LQG over MPC and LQR control for rotary inverted pendulum*,
section 3. State order: arm angle, arm rate, pendulum angle (0 = upright), pendulum rate;
input: motor voltage; outputs: arm and pendulum angle; ``Ts = 0.01`` s.

How the printed model was recovered
-----------------------------------
The paper prints ``A_d`` and ``B_d`` rounded to 2–5 digits, and the Kalman gains ``L`` and ``M``
of eq. (12) that MATLAB computed from the unrounded model. Designing the filter from the printed
``A_d`` misses eq. (12) by up to 6e-3. riprs therefore fits the eight parameters of the
continuous-time linearised Furuta structure::

    dx/dt = [0 1 0 0; 0 a11 a12 a13; 0 0 0 1; 0 a31 a32 a33] x + [0; b1; 0; b3] u

(discretised by zero-order hold) to the 40 printed entries of ``A_d``, ``B_d``, ``L`` and ``M``,
each residual in units of half the last printed digit. The fitted model reproduces every printed
entry of ``L``, ``M`` and ``B_d`` exactly after rounding and every entry of ``A_d`` to its
printed precision (``tests/test_paper.py`` checks this).

Corrections to the printed numbers
----------------------------------
1. ``A_d[0, 1]`` is printed ``0.001`` but is ``0.009916``: a sampled double integrator has
   ``~Ts`` there, and with ``0.001`` the designed ``L[0, 0]`` is ``0.0143`` instead of the printed
   ``0.0723`` (``0.0099`` gives ``0.0721``; the fitted model gives ``0.0723``).
2. Eq. (8) prints ``Q[1, 0] = 0.008``; ``Q = B B^T`` is symmetric with ``Q[0, 1] = 0.0008``
   (``= 0.002 * 0.398``), so a zero was dropped.
3. ``A_d[2, 1]`` is printed ``0``; the model has ``-0.000053``, which the row's three-decimal
   precision (``1.003``) rounds to zero.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

import numpy as np

from riprs import _riprs
from riprs._typing import FloatArray
from riprs.statespace import StateSpace

__all__ = [
    "INPUT_SCALE",
    "PRINTED",
    "TABLE1",
    "TS",
    "augmented_model",
    "continuous_model",
    "discrete_model",
    "kalman_gains",
    "lqr_gain",
    "lqr_weights",
    "mpc",
    "noise_model",
    "plant",
]

_printed = _riprs.paper_printed()

TS: float = _riprs.TS
"""Sample time of the study (s)."""

INPUT_SCALE: float = float(_printed["input_scale"])
"""MPC input scale factor ``L_su``."""

PRINTED: Mapping[str, FloatArray] = MappingProxyType(
    {key: np.asarray(_printed[key]) for key in ("Ad", "Bd", "L", "M")}
)
"""The paper's matrices exactly as printed (``Ad`` with its ``0.001`` typo)."""

TABLE1: Mapping[str, tuple[float, float, float]] = MappingProxyType(
    {name: tuple(values) for name, values in _printed["table1"].items()}
)
"""Tab. 1: experimental RMSE of (arm angle [rad], pendulum angle [rad], voltage [V])."""


def _state_space(kind: str) -> StateSpace:
    A, B, C, D, Ts = _riprs.paper_state_space(kind)
    return StateSpace(A, B, C, D, Ts)


def continuous_model() -> StateSpace:
    """The fitted continuous-time linear model (``Ts == 0``)."""
    return _state_space("continuous")


def discrete_model() -> StateSpace:
    """The plant of section 3: ``A_d`` (4x4), ``B_d`` (4x1), ``C`` (2x4), ``D = 0``, ``Ts``."""
    return _state_space("discrete")


def augmented_model() -> StateSpace:
    """The 5-state observer model of eq. (3).

    The plant plus one integrated-white-noise output disturbance feeding both outputs
    (eq. (1)); inputs are ``[u, w_od, w_n1, w_n2]``::

        A = [A_d 0; 0 1],  B = [B_d*L_su 0 0 0; 0 0.01 0 0],  C = [C [1; 1]],  D = [0 0 I]
    """
    return _state_space("augmented")


def noise_model() -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(Q, R, N) = (B B^T, D D^T, B D^T)`` of eqs. (8)–(10) for :func:`augmented_model`."""
    return _riprs.paper_noise_model()


def lqr_weights() -> tuple[FloatArray, FloatArray]:
    """LQR weights of eq. (13): ``Q = diag(25, 0, 50, 0)``, ``R = [[0.1]]``."""
    return np.diag([25.0, 0.0, 50.0, 0.0]), np.array([[0.1]])


def lqr_gain() -> FloatArray:
    """The LQR gain ``K`` (``u = -K x``) from eq. (13) on :func:`discrete_model`."""
    from riprs.design import dlqr

    plant = discrete_model()
    Q, R = lqr_weights()
    K, _, _ = dlqr(plant.A, plant.B, Q, R)
    return K


def kalman_gains() -> tuple[FloatArray, FloatArray]:
    """``(L, M)`` of eq. (11) designed from the augmented model: compare with eq. (12)."""
    L, M, _, _ = _riprs.paper_kalman()
    return L, M


def plant() -> _riprs.Plant:
    """The nonlinear plant fitted to the paper's model (:meth:`riprs.FurutaParams.paper`).

    Its linearisation about upright, discretised at ``TS``, reproduces the printed ``A_d`` and
    ``B_d`` to their printed precision; see :mod:`riprs.plant` for what was fitted.
    """
    return _riprs.Plant.paper()


def mpc(solver: str = "active_set") -> _riprs.Mpc:
    """The study's MPC (section 3) on :func:`discrete_model`.

    ``Ts = 0.01``, ``P = 50``, ``m = 3``, output weights ``(25, 50)``, input weight 0, input-rate
    weight 1, input scale ``L_su = 10``, output scales 1, ``|u| <= 12`` V (hard), soft bound
    ``+-pi/6`` rad on the pendulum angle, ``rho_eps = 100``, the output disturbance of eq. (1)
    (``A_od = 1``, ``B_od = 0.01``, ``C_od = [1; 1]``) and unit measurement noise (eq. (2)).
    Its Kalman gains are those of eq. (11), i.e. :func:`kalman_gains`, which reproduce eq. (12).

    The soft bound is on the pendulum angle, not the arm: the paper writes it on "alpha", and
    its Tab. 1 uses alpha for the arm, but the experiment steps the arm reference to 1 rad,
    above pi/6, so a bound on the arm would be violated for the whole second half of the run and
    the reported arm tracking would not be possible without a large slack. ``+-pi/6`` on the
    pendulum is a "stay near upright" limit the controller can honour.

    It is the experiment file's ``[mpc]`` default (``riprs.Spec().build_controllers()["MPC"]``)
    and ``rip-rt``'s MPC: the same settings and the same solver.

    Parameters
    ----------
    solver : {"active_set", "clarabel"}
        QP backend; the active set by default, as in the experiment file (both reach the same
        minimiser, the active set about a hundred times faster and without allocating).
    """
    return _riprs.Mpc.paper(solver)

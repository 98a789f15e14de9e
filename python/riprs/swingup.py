"""Swing-up feasibility: an independent, constructive check by trajectory optimisation.

:func:`find_swing_up` looks for a voltage sequence within ``±max_voltage`` that takes the
pendulum from hanging at rest to upright (nearly at rest) while the arm stays within
``±arm_limit``, by multiple shooting: the horizon ``T`` is cut into ``N`` intervals with the
voltage held over each, the state at every node is a decision variable, and the defects

.. math::

    d_k = F(s_k, u_k) - s_{k+1} = 0, \\qquad k = 0 \\dots N-1,

(``F`` is one interval of the riprs plant's RK4, :meth:`riprs.Plant.integrate`, the same model
the simulator and the controllers use) are equality constraints of an SLSQP problem
(``scipy.optimize.minimize``), with ``s_0`` hanging, ``|θ_k| ≤ arm_limit`` at every node and the
final node within a small box around upright. The Jacobian of the defects is block-sparse
and taken by finite differences interval by interval.

The model is the smooth part of the rig's (no dead zone, no Coulomb friction), with the
voltage bound lowered by what those take (``V_d + C_r R_m / k_t``), as rip-core's energy
balance does.

A local optimiser that finds nothing is not a proof: :func:`find_swing_up` reports
``found=False`` ("not found"), which is a different statement from rip-core's
"impossible": the energy bound's verdict, which ``riprs tune`` stores in the tuning record's
``[swing_up]`` table and ``rip-rt run --swing-up`` reads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize

from . import _riprs

__all__ = ["SwingUpTrajectory", "find_swing_up"]

_F = NDArray[np.float64]


@dataclass(frozen=True)
class SwingUpTrajectory:
    """The result of :func:`find_swing_up`.

    Attributes
    ----------
    found : bool
        Whether a trajectory meeting every constraint (to ``tol``) was found.
    t : ndarray, shape (N + 1,)
        Node times (s).
    x : ndarray, shape (N + 1, 4)
        States at the nodes, ``[θ, θ̇, α, α̇]``, α unwrapped from π.
    u : ndarray, shape (N,)
        The voltage held over each interval (V), for the smooth model.
    max_defect : float
        Largest continuity defect of the solution (state units).
    max_arm : float
        Largest ``|θ|`` at the nodes (rad).
    message : str
        What the optimiser said.
    """

    found: bool
    t: _F
    x: _F
    u: _F
    max_defect: float
    max_arm: float
    message: str = field(default="")


def _smooth(params: _riprs.FurutaParams) -> tuple[_riprs.Plant, float]:
    d = params.to_dict()
    loss = d["Vd"] + d["Cr"] * d["Rm"] / d["kt"]
    smooth = params.replace(Vd=0.0, Cr=0.0, Cp=0.0)
    return _riprs.Plant(smooth), loss


def find_swing_up(
    plant: _riprs.Plant | _riprs.FurutaParams,
    *,
    max_voltage: float = _riprs.DEFAULT_U_LIMIT,
    arm_limit: float = 1.5,
    horizon: float = 4.0,
    intervals: int = 60,
    substeps: int = 4,
    tol: float = 1e-3,
    max_iter: int = 300,
    upright_tolerance: tuple[float, float, float] = (0.05, 0.5, 1.0),
) -> SwingUpTrajectory:
    """Look for an arm-limited swing-up at a voltage bound by multiple shooting (module docs).

    Parameters
    ----------
    plant : Plant or FurutaParams
        The rig's model.
    max_voltage : float
        Voltage bound (V); default the paper's ``|u| ≤ 12 V`` (``riprs._riprs.DEFAULT_U_LIMIT``).
    arm_limit : float
        The arm stays within ``±arm_limit`` (rad) at every node.
    horizon : float
        Time allowed (s).
    intervals : int
        Shooting intervals ``N``.
    substeps : int
        RK4 steps per interval.
    tol : float
        Largest defect and constraint violation accepted as "found".
    max_iter : int
        SLSQP iterations.
    upright_tolerance : tuple of float
        Final ``|α − 0|`` (rad, wrapped to the nearer upright), ``|α̇|`` and ``|θ̇|`` (rad/s).

    Returns
    -------
    SwingUpTrajectory

    Raises
    ------
    ValueError
        A bound, the horizon or the interval count is not positive and finite.
    """
    for name, v in (("max_voltage", max_voltage), ("arm_limit", arm_limit), ("horizon", horizon)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be positive and finite, got {v}")
    if intervals < 2 or substeps < 1:
        raise ValueError(
            f"intervals must be at least 2 and substeps at least 1, got {intervals}, {substeps}"
        )
    params = plant.params() if isinstance(plant, _riprs.Plant) else plant
    model, lost = _smooth(params)
    u_max = max(max_voltage - lost, 0.0)
    n = intervals
    dt = horizon / n
    x0 = np.array([0.0, 0.0, math.pi, 0.0])

    def shoot(s: _F, u: float) -> _F:
        try:
            return np.asarray(model.integrate(s, [u], dt, substeps)[1], dtype=float)
        except _riprs.DivergedError:
            # An iterate far outside the model's range: a large, finite defect.
            return np.asarray(s, dtype=float) + 1e3

    def unpack(z: _F) -> tuple[_F, _F]:
        return z[: 4 * (n + 1)].reshape(n + 1, 4), z[4 * (n + 1) :]

    def defects(z: _F) -> _F:
        s, u = unpack(z)
        d = [s[0] - x0]
        d += [shoot(s[k], u[k]) - s[k + 1] for k in range(n)]
        return np.concatenate(d)

    def defects_jac(z: _F) -> _F:
        s, u = unpack(z)
        nz = z.size
        jac = np.zeros((4 * (n + 1), nz))
        jac[0:4, 0:4] = np.eye(4)
        h = 1e-6
        for k in range(n):
            rows = slice(4 * (k + 1), 4 * (k + 2))
            base = shoot(s[k], u[k])
            for i in range(4):
                e = s[k].copy()
                e[i] += h
                jac[rows, 4 * k + i] = (shoot(e, u[k]) - base) / h
            jac[rows, 4 * (n + 1) + k] = (shoot(s[k], u[k] + h) - base) / h
            jac[rows, 4 * (k + 1) : 4 * (k + 2)] -= np.eye(4)
        return jac

    def best(target: float) -> SwingUpTrajectory:
        # The first guess: a rollout of a voltage at the pendulum's natural frequency.
        d = params.to_dict()
        ja = d["Jp"] + d["mp"] * d["Lp"] ** 2 / 4
        w = math.sqrt(d["mp"] * d["g"] * d["Lp"] / 2 / ja)
        t = np.arange(n) * dt
        u0 = 0.5 * u_max * np.sign(np.sin(w * t + 1e-9)) * (target - math.pi) / math.pi
        s0 = np.asarray(model.integrate(x0, u0, dt, substeps), dtype=float)
        s0[:, 0] = np.clip(s0[:, 0], -arm_limit, arm_limit)
        z0 = np.concatenate([s0.ravel(), u0])
        a_tol, rate_tol, arm_rate_tol = upright_tolerance
        last = 4 * n
        idx = np.arange(n + 1) * 4

        def ineq(z: _F) -> _F:
            s, _ = unpack(z)
            return np.concatenate(
                [
                    arm_limit - np.abs(s[:, 0]),
                    [a_tol - abs(s[n, 2] - target)],
                    [rate_tol - abs(s[n, 3])],
                    [arm_rate_tol - abs(s[n, 1])],
                ]
            )

        def ineq_jac(z: _F) -> _F:
            s, _ = unpack(z)
            jac = np.zeros((n + 4, z.size))
            jac[np.arange(n + 1), idx] = -np.sign(s[:, 0])
            jac[n + 1, last + 2] = -np.sign(s[n, 2] - target)
            jac[n + 2, last + 3] = -np.sign(s[n, 3])
            jac[n + 3, last + 1] = -np.sign(s[n, 1])
            return jac

        scale = 1.0 / (n * u_max**2)

        def cost(z: _F) -> float:
            return float(scale * np.sum(z[4 * (n + 1) :] ** 2))

        def cost_grad(z: _F) -> _F:
            g = np.zeros_like(z)
            g[4 * (n + 1) :] = 2 * scale * z[4 * (n + 1) :]
            return g

        bounds = [(None, None)] * (4 * (n + 1)) + [(-u_max, u_max)] * n
        res = minimize(
            cost,
            z0,
            jac=cost_grad,
            method="SLSQP",
            bounds=bounds,
            constraints=[
                {"type": "eq", "fun": defects, "jac": defects_jac},
                {"type": "ineq", "fun": ineq, "jac": ineq_jac},
            ],
            options={"maxiter": max_iter, "ftol": 1e-9},
        )
        _, u = unpack(res.x)
        u = np.clip(u, -u_max, u_max)
        # Judge the result on a fresh rollout of its voltages, not on the optimiser's word.
        try:
            roll = np.asarray(model.integrate(x0, u, dt, substeps), dtype=float)
        except _riprs.DivergedError:
            roll = np.full((n + 1, 4), np.inf)
        max_defect = float(np.max(np.abs(defects(res.x))))
        max_arm = float(np.max(np.abs(roll[:, 0])))
        end = roll[-1]
        found = bool(
            max_arm <= arm_limit + tol
            and abs(end[2] - target) <= a_tol + 10 * tol
            and abs(end[3]) <= rate_tol + 10 * tol
            and abs(end[1]) <= arm_rate_tol + 10 * tol
        )
        return SwingUpTrajectory(
            found=found,
            t=np.arange(n + 1) * dt,
            x=roll,
            u=u,
            max_defect=max_defect,
            max_arm=max_arm,
            message=str(res.message),
        )

    first = best(0.0)
    if first.found:
        return first
    second = best(2 * math.pi)
    return second if second.found else first

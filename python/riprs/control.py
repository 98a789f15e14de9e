"""The paper's regulators, with one interface shared by every riprs controller.

Every controller has ``step(y, r=None) -> u`` (measured angles ``y = [theta, alpha]``,
reference ``r = [theta_ref, alpha_ref]``, input ``u`` as a length-1 array), ``reset()`` and the
read-only attributes ``Ts``, ``u_min``, ``u_max`` and ``x_hat``. :func:`riprs.simulate` accepts
any of them.

:class:`Lqr`
    The paper's LQR (section 4): angles measured, rates from a low-pass filtered difference, no
    estimator, ``u = sat(-K (x_hat - x_ref))`` with ``x_ref = [r_theta, 0, r_alpha, 0]``.
:class:`Lqg`
    The same gain on the plant part of the steady-state Kalman filter's current estimate
    ``x[k|k]`` (eqs. (3)-(12)); the output-disturbance state is estimated, not fed back.

Both clamp their input to ``[u_min, u_max]`` (default +-12 V). ``Lqr.paper()`` and
``Lqg.paper()`` build the study's designs.

:class:`SwingUp`
    Swing-up from rest and catch around any balance controller: energy pumping (Astrom &
    Furuta, 2000) that keeps the arm inside its limit, then the balance controller inside a
    catch region, bumplessly. ``riprs.simulate(plant, riprs.SwingUp(balance=riprs.Lqr.paper()),
    15.0, x0=[0, 0, math.pi, 0])`` swings up the hanging pendulum; the result's ``catch_time``
    is the time to upright.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from riprs._riprs import Lqg, Lqr, SwingUp

__all__ = ["Controller", "Lqg", "Lqr", "SwingUp"]


@runtime_checkable
class Controller(Protocol):
    """What :func:`riprs.simulate` and ``riprs compare`` accept as a controller:
    :class:`Lqr`, :class:`Lqg`, :class:`riprs.Mpc` and :class:`SwingUp` all satisfy it."""

    def step(self, y: ArrayLike, r: ArrayLike | None = None) -> NDArray[np.float64]:
        """The input ``u[k]`` for the measured angles ``y[k]`` and reference ``r[k]``."""
        ...

    def reset(self) -> None:
        """Return to the state right after construction."""
        ...

    @property
    def Ts(self) -> float:
        """The sample time (s) the controller was designed for."""
        ...

"""Constrained MPC with soft output bounds and the disturbance-model Kalman filter.

:class:`Mpc` follows MATLAB's MPC Toolbox (the paper's section 3): a plant augmented with an
output-disturbance model, a steady-state Kalman filter in current form designed from that model
with ``Q = B B^T``, ``R = D D^T``, ``N = B D^T``, and at every sample a QP over the moves
``du(k..k+m-1)`` and one slack ``eps`` with weighted, scaled output, input and input-rate terms,
hard input bounds and soft output bounds (equal concern). Two QP backends solve it:
``solver="active_set"`` (dense, warm-started, allocation-free; the default everywhere), exact to
rounding, and ``solver="clarabel"`` (interior point), accurate to its stopping tolerances: about
1e-6 V in the first move, farther later in the plan on some problems (the design page gives the
measured accuracy of both against the exact QP solution).

``Mpc(...)``'s keyword defaults are MATLAB's ``mpc`` defaults (``P = 10``, ``m = 2``, ...), so
a MATLAB design ports keyword for keyword; :func:`riprs.paper.mpc` (``Mpc.paper()``) is the
paper's MPC and equals the experiment file's ``[mpc]`` defaults.

Examples
--------
>>> import numpy as np, riprs
>>> mpc = riprs.paper.mpc()
>>> u = mpc.step([0.0, 0.05], [0.0, 0.0])
>>> bool(np.all(np.abs(u) <= 12.0))
True
>>> sol = mpc.last_solution
>>> sol.status
'solved'

:class:`Mpc` has the same ``step(y, r)`` / ``reset()`` interface as :class:`riprs.Lqr` and
:class:`riprs.Lqg`, so :func:`riprs.simulate` runs it on the nonlinear plant.
"""

from __future__ import annotations

from riprs._riprs import Mpc, MpcSolution

__all__ = ["Mpc", "MpcSolution"]

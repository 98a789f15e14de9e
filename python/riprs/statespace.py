"""A minimal state-space container."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from riprs._typing import FloatArray


@dataclass(frozen=True)
class StateSpace:
    """``x[k+1] = A x + B u``, ``y = C x + D u`` sampled every ``Ts`` seconds.

    ``Ts == 0`` marks a continuous-time model ``dx/dt = A x + B u``.
    """

    A: FloatArray
    B: FloatArray
    C: FloatArray
    D: FloatArray
    Ts: float

    @property
    def nstates(self) -> int:
        return int(self.A.shape[0])

    @property
    def ninputs(self) -> int:
        return int(self.B.shape[1])

    @property
    def noutputs(self) -> int:
        return int(self.C.shape[0])

    def __repr__(self) -> str:
        with np.printoptions(precision=6, suppress=True):
            return (
                f"StateSpace(nstates={self.nstates}, ninputs={self.ninputs}, "
                f"noutputs={self.noutputs}, Ts={self.Ts})\nA =\n{self.A}\nB =\n{self.B}"
            )

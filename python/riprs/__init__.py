"""riprs: LQR, LQG and constrained MPC for the rotary inverted pendulum.

A Rust core (``rip-core``) with numpy in and out. The design functions follow python-control's
names, argument and return orders; :func:`kalman` follows MATLAB and returns both gains.
"""

from riprs import paper, stats
from riprs._riprs import (
    DivergedError,
    InvalidParameterError,
    NonFiniteError,
    NoStabilizingSolutionError,
    NotDetectableError,
    NotPositiveDefiniteError,
    NotPositiveSemidefiniteError,
    NotStabilizableError,
    NotSymmetricError,
    RiprsError,
    ShapeError,
    __version__,
)
from riprs.config import ConfigError, Spec, load_config
from riprs.control import Controller, Lqg, Lqr, SwingUp
from riprs.design import KalmanDesign, c2d, dare, dlqe, dlqr, kalman
from riprs.excitation import excitation, excitation_defaults
from riprs.identify import IdentifyError, IdentifyResult, IdentifyWarning, identify
from riprs.log import LogError, RtLog, load_log
from riprs.mpc import Mpc, MpcSolution
from riprs.plant import FurutaParams, Plant
from riprs.rig import NamedRig, Rig, named_rig, named_rigs, random_rig
from riprs.sim import BatchMetrics, SimResult, simulate, simulate_batch, simulate_metrics
from riprs.statespace import StateSpace
from riprs.swing_tuning import SwingUpStudy, SwingUpTuning, swing_up_monte_carlo
from riprs.tune import TuneResult, tune

__all__ = [
    "BatchMetrics",
    "ConfigError",
    "Controller",
    "DivergedError",
    "FurutaParams",
    "IdentifyError",
    "IdentifyResult",
    "IdentifyWarning",
    "InvalidParameterError",
    "KalmanDesign",
    "LogError",
    "Lqg",
    "Lqr",
    "Mpc",
    "MpcSolution",
    "NamedRig",
    "NoStabilizingSolutionError",
    "NonFiniteError",
    "NotDetectableError",
    "NotPositiveDefiniteError",
    "NotPositiveSemidefiniteError",
    "NotStabilizableError",
    "NotSymmetricError",
    "Plant",
    "Rig",
    "RiprsError",
    "RtLog",
    "ShapeError",
    "SimResult",
    "Spec",
    "StateSpace",
    "SwingUp",
    "SwingUpStudy",
    "SwingUpTuning",
    "TuneResult",
    "__version__",
    "c2d",
    "dare",
    "dlqe",
    "dlqr",
    "excitation",
    "excitation_defaults",
    "identify",
    "kalman",
    "load_config",
    "load_log",
    "named_rig",
    "named_rigs",
    "paper",
    "random_rig",
    "simulate",
    "simulate_batch",
    "simulate_metrics",
    "stats",
    "swing_up_monte_carlo",
    "tune",
]

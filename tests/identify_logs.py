"""Excitation logs of a known rig, as ``rip-rt excite`` records them, for the identification
tests: the simulated run, its CSV log, and ``riprs.identify`` without its warnings."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

import riprs

TS = 0.01
COLUMNS = "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status"
#: Kick (V, s) and length (s) of the free-swing runs docs/rig.md asks for: a kick that swings
#: the pendulum wide, so that its decay determines its damping.
FREE_AMPLITUDE = 6.0
FREE_KICK = 0.3
FREE_DURATION = 60.0


def excitation_run(
    params: riprs.FurutaParams,
    signal: str,
    seed: int,
    *,
    duration: float = 30.0,
    counts: int = 2048,
    noise: float = 5e-4,
    kick: float = FREE_KICK,
    free_duration: float = FREE_DURATION,
) -> tuple[np.ndarray, ...]:
    """``(t, theta, alpha, u)`` of an excitation run from hanging at rest, as rip-rt excite
    drives it (the signal through a 1 V/rad arm-centring pull on the measured arm angle; a
    free swing's kick and coast without it), through ``counts``-count encoders plus Gaussian
    noise, alpha wrapped to (-pi, pi]."""
    plant = riprs.Plant(params)
    rng = np.random.default_rng(seed)
    free = signal == "free-swing"
    if free:
        e = riprs.excitation(
            signal, dt=TS, duration=free_duration, amplitude=FREE_AMPLITUDE, kick=kick
        )
    else:
        e = riprs.excitation(signal, dt=TS, duration=duration, amplitude=2.5, seed=seed)
    q = 2 * math.pi / counts
    x = np.array([0.0, 0.0, math.pi, 0.0])
    y = np.empty((len(e), 2))
    u = np.empty(len(e))
    for k in range(len(e)):
        y[k] = np.round(x[[0, 2]] / q) * q + rng.normal(0.0, noise, 2)
        u[k] = float(e[k] if free else np.clip(e[k] - y[k, 0], -10.0, 10.0))
        x = plant.step(x, u[k], TS, 10)
    alpha = np.remainder(y[:, 1] + math.pi, 2 * math.pi) - math.pi
    return np.arange(len(e)) * TS, y[:, 0], alpha, u


def write_log(path: Path, run: tuple[np.ndarray, ...], *, period_ms: int | None = 10) -> Path:
    """``run`` as a rip-rt excite log at ``path`` (no ``period_ms`` header when None)."""
    t, theta, alpha, u = run
    lines = ["# rip-rt excite log"]
    if period_ms is not None:
        lines.append(f"# period_ms: {period_ms}")
    lines.append(COLUMNS)
    lines += [
        f"{t[k]:.3f},{k},{theta[k]:.17g},{alpha[k]:.17g},0,{u[k]:.17g},50,10,0"
        for k in range(len(t))
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def quiet_identify(*args, **kw) -> riprs.IdentifyResult:
    """``riprs.identify`` with its warnings silenced (the tests judge its result)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return riprs.identify(*args, **kw)

"""Figures like the paper's Figs. 9-11 (arm angle, pendulum angle, control voltage), and the
Monte Carlo box plot. matplotlib runs headless (Agg) so the figures render on any machine."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "plot_comparison",
    "plot_monte_carlo",
    "plot_time_to_upright",
    "plot_trajectories",
    "with_gaps",
]

_COLORS = {"LQR": "tab:blue", "LQG": "tab:orange", "MPC": "tab:green"}
_PANELS = (
    ("arm_angle", "arm", "Arm angle (cf. Fig. 9)", "arm angle θ [rad]"),
    ("pendulum_angle", "pendulum", "Pendulum angle (cf. Fig. 10)", "pendulum angle α [rad]"),
    ("control_voltage", "voltage", "Control voltage (cf. Fig. 11)", "voltage u [V]"),
)


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def with_gaps(t: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    """``t`` and ``y`` with a NaN point inside every gap, so that a line is broken there
    rather than drawn straight across it (a log's periods without rows).

    A gap is a step in ``t`` longer than 1.5 times the median step.

    Parameters
    ----------
    t, y : array_like
        Times (s), increasing, and the values at them.

    Returns
    -------
    t, y : numpy.ndarray
        The same points, with one ``(midpoint, NaN)`` point added in each gap.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.size < 3:
        return t, y
    dt = np.diff(t)
    gaps = np.flatnonzero(dt > 1.5 * np.median(dt))
    if gaps.size == 0:
        return t, y
    return (
        np.insert(t, gaps + 1, t[gaps] + 0.5 * dt[gaps]),
        np.insert(y, gaps + 1, np.nan),
    )


def plot_trajectories(trajectories: Mapping[str, Any], quantity: str, ax: Any = None) -> Any:
    """Draw one quantity (``"arm"``, ``"pendulum"`` or ``"voltage"``) of every run on one axes.

    ``trajectories`` maps a label to a :class:`riprs.compare.Trajectory` (from a simulation or
    a ``rip-rt`` log). Returns the axes.
    """
    plt = _pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(8, 3.6))
    for i, (name, tr) in enumerate(trajectories.items()):
        color = _COLORS.get(name, f"C{i}")
        t, y = with_gaps(tr.t, getattr(tr, quantity))
        ax.plot(t, y, label=name, color=color, linewidth=1.1)
    if quantity == "arm":
        first = next(iter(trajectories.values()))
        ax.plot(*with_gaps(first.t, first.reference), "k--", linewidth=1.0, label="reference")
    # A run that started hanging: its switch from swing-up to balance (the catch).
    for i, (name, tr) in enumerate(trajectories.items()):
        t_catch = getattr(tr, "catch_time", None)
        if t_catch is None:
            continue
        color = _COLORS.get(name, f"C{i}")
        ax.axvline(t_catch, color=color, linestyle=":", linewidth=1.0)
        ax.annotate(
            f"{name} catch {t_catch:.2f} s",
            xy=(t_catch, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(3, -12 - 11 * i),
            textcoords="offset points",
            fontsize=8,
            color=color,
        )
    ax.set_xlabel("time [s]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=9)
    return ax


def plot_comparison(trajectories: Mapping[str, Any], out: Path, *, suffix: str = "") -> list[Path]:
    """Write ``arm_angle``, ``pendulum_angle`` and ``control_voltage`` (each followed by
    ``suffix``) as PNG and SVG; ``trajectories`` may mix simulations and ``rip-rt`` logs."""
    plt = _pyplot()
    files: list[Path] = []
    for stem, quantity, title, ylabel in _PANELS:
        fig, ax = plt.subplots(figsize=(8, 3.6), constrained_layout=True)
        plot_trajectories(trajectories, quantity, ax)
        ax.set_title(title)
        ax.set_ylabel(ylabel)
        for ext in ("png", "svg"):
            path = out / f"{stem}{suffix}.{ext}"
            fig.savefig(path, dpi=120)
            files.append(path)
        plt.close(fig)
    return files


def plot_monte_carlo(mc: Any, out: Path) -> list[Path]:
    """Box plots of each RMSE index over the Monte Carlo runs that stayed up."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.6), constrained_layout=True)
    names = list(mc.rmse)
    for j, (ax, label) in enumerate(
        zip(
            axes,
            ("arm angle RMSE [rad]", "pendulum angle RMSE [rad]", "voltage RMSE [V]"),
            strict=True,
        )
    ):
        data = [mc.rmse[n][~mc.fell[n], j] for n in names]
        data = [d if len(d) else np.array([np.nan]) for d in data]
        ax.boxplot(data, tick_labels=names)
        ax.set_title(label)
        ax.grid(True, axis="y", alpha=0.3)
    files = []
    for ext in ("png", "svg"):
        path = out / f"monte_carlo.{ext}"
        fig.savefig(path, dpi=120)
        files.append(path)
    plt.close(fig)
    return files


def plot_time_to_upright(mc: Any, out: Path) -> list[Path]:
    """Empirical distribution (ECDF) of the time to upright per controller over the Monte Carlo
    runs of a swing-up study; runs never caught keep the curve below 1."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.6), constrained_layout=True)
    for i, (name, times) in enumerate(mc.time_to_upright.items()):
        caught = np.sort(times[np.isfinite(times)])
        share = np.arange(1, len(caught) + 1) / max(len(times), 1)
        color = _COLORS.get(name, f"C{i}")
        ax.step(caught, share, where="post", color=color, label=f"{name} ({len(times)} runs)")
    ax.set_xlabel("time to upright [s]")
    ax.set_ylabel("share of runs caught")
    ax.set_ylim(0.0, 1.02)
    ax.set_title("Swing-up: time to upright (ECDF)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize=9)
    files = []
    for ext in ("png", "svg"):
        path = out / f"time_to_upright.{ext}"
        fig.savefig(path, dpi=120)
        files.append(path)
    plt.close(fig)
    return files

"""Figures of a campaign: robustness maps over two axes and marginal plots over each axis.

Every value is an average over the runs of a cell (all seeds, and all values of the axes not
shown): the fall rate over every run, an RMSE over the runs that stayed up (a cell where every
run fell is blank). Each figure takes a table of runs or, for a campaign of any size, its
:class:`Aggregates` (sums kept chunk by chunk). matplotlib runs headless (Agg).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Aggregates", "aggregate", "plot_campaign", "plot_map", "plot_marginals"]

LABELS = {
    "fall_rate": "fall rate",
    "rmse_arm": "arm angle RMSE [rad]",
    "rmse_pendulum": "pendulum angle RMSE [rad]",
    "rmse_voltage": "voltage RMSE [V]",
    "peak_voltage": "peak voltage [V]",
    "settle_time": "settling time [s]",
}
_COLORS = {"LQR": "tab:blue", "LQG": "tab:orange", "MPC": "tab:green"}


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _column(table: Any, name: str) -> np.ndarray:
    if name not in table.column_names:
        raise KeyError(f"no column {name!r}; columns: {', '.join(table.column_names)}")
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False))


def _sums(
    cells: np.ndarray, size: int, columns: Mapping[str, Any], metric: str
) -> tuple[np.ndarray, np.ndarray]:
    """Per cell (``cells[i]`` is run ``i``'s), the sum of ``metric`` over the runs it counts
    and their number: every run for ``"fall_rate"`` (the value is ``fell``); for a result
    column, the runs that neither fell nor diverged and have a value."""
    fell = np.asarray(columns["fell"]).astype(bool)
    if metric == "fall_rate":
        weight = np.ones(len(fell))
        data = fell.astype(float)
    else:
        column = np.asarray(columns[metric]).astype(float)
        up = ~fell
        if "diverged" in columns:
            up &= ~np.asarray(columns["diverged"]).astype(bool)
        weight = (up & np.isfinite(column)).astype(float)
        data = np.where(weight > 0, column, 0.0)
    total = np.bincount(cells, weights=data * weight, minlength=size)
    count = np.bincount(cells, weights=weight, minlength=size)
    return total, count


def _mean(total: np.ndarray, count: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1e-300), np.nan)


def aggregate(
    table: Any, axes: Sequence[str], metric: str
) -> tuple[list[str], list[np.ndarray], np.ndarray]:
    """Per controller, the mean of ``metric`` over each cell of ``axes``.

    ``metric`` is ``"fall_rate"`` (mean of ``fell`` over every run) or a result column (mean
    over the runs that neither fell nor diverged and have a value). ``table`` is a
    ``pyarrow.Table`` of runs or the :class:`Aggregates` of a campaign. Returns the
    controllers, the sorted values of each axis and an array of shape
    ``(controllers, len(values[0]), len(values[1]), ...)``.
    """
    if isinstance(table, Aggregates):
        return table.aggregate(axes, metric)
    controllers = list(dict.fromkeys(_column(table, "controller").tolist()))
    ctrl = np.array([controllers.index(c) for c in _column(table, "controller").tolist()])
    values, index = [], []
    for name in axes:
        col = _column(table, name)
        uniq, inv = np.unique(col, return_inverse=True)
        values.append(uniq)
        index.append(inv)
    shape = (len(controllers), *(len(v) for v in values))
    flat = np.ravel_multi_index((ctrl, *index), shape)
    names = [n for n in ("fell", "diverged", metric) if n in table.column_names]
    columns = {name: _column(table, name) for name in names}
    total, count = _sums(flat, int(np.prod(shape)), columns, metric)
    return controllers, values, _mean(total, count).reshape(shape)


class Aggregates:
    """What the summary and the figures of a campaign show, summed chunk by chunk.

    Holds, per controller and per cell of each group of axes (``()`` for the whole campaign,
    one axis for a marginal plot, two for a map), the sum and count of each of
    :attr:`METRICS` (:func:`aggregate`'s rule). Memory grows with the cells, never with the
    runs: a campaign of any size is summarised while its chunks stream past.

    Parameters
    ----------
    campaign : Campaign
    groups : sequence of tuples of axis names
    """

    #: The means kept: the fall rate and the three RMSEs.
    METRICS = ("fall_rate", "rmse_arm", "rmse_pendulum", "rmse_voltage")

    def __init__(self, campaign: Any, groups: Sequence[tuple[str, ...]]) -> None:
        self.campaign = campaign
        self.controllers = list(campaign.controllers)
        self.runs = 0
        axes = {a.name: a for a in campaign.axes}
        # Cells are the distinct axis values (equal values of two points share a cell).
        self._unique = {
            name: np.unique(a.values, return_inverse=True) for name, a in axes.items()
        }
        self._sums: dict[tuple[tuple[str, ...], str], list[np.ndarray]] = {}
        self._shapes: dict[tuple[str, ...], tuple[int, ...]] = {}
        for group in dict.fromkeys(tuple(g) for g in groups):
            for name in group:
                if name not in axes:
                    raise KeyError(f"no axis {name!r}; axes: {', '.join(axes)}")
            shape = (len(self.controllers), *(len(self._unique[n][0]) for n in group))
            self._shapes[group] = shape
            size = int(np.prod(shape))
            for metric in self.METRICS:
                self._sums[(group, metric)] = [np.zeros(size), np.zeros(size)]

    def add(self, columns: Mapping[str, Any]) -> None:
        """Fold in the result columns of some runs (a chunk, or a Parquet file of one)."""
        runs = np.asarray(columns["run"], dtype=np.int64)
        idx = self.campaign.index(runs)
        for group, shape in self._shapes.items():
            index = [self._unique[n][1][idx[f"axis:{n}"]] for n in group]
            cells = np.ravel_multi_index((idx["controller"], *index), shape)
            for metric in self.METRICS:
                total, count = _sums(cells, int(np.prod(shape)), columns, metric)
                sums = self._sums[(group, metric)]
                sums[0] += total
                sums[1] += count
        self.runs += len(runs)

    def run_counts(self) -> list[int]:
        """Runs added per controller."""
        return [int(n) for n in self._sums[((), "fall_rate")][1]]

    def aggregate(
        self, axes: Sequence[str], metric: str
    ) -> tuple[list[str], list[np.ndarray], np.ndarray]:
        """As :func:`aggregate` of the table of every run added."""
        group = tuple(axes)
        if (group, metric) not in self._sums:
            raise KeyError(f"{metric!r} over {list(group)} was not aggregated")
        total, count = self._sums[(group, metric)]
        values = [self._unique[n][0] for n in group]
        return self.controllers, values, _mean(total, count).reshape(self._shapes[group])


def _edges(v: np.ndarray) -> np.ndarray:
    if len(v) == 1:
        return np.array([v[0] - 0.5, v[0] + 0.5]) if v[0] == 0 else v[0] * np.array([0.95, 1.05])
    mid = (v[1:] + v[:-1]) / 2
    return np.concatenate([[v[0] - (mid[0] - v[0])], mid, [v[-1] + (v[-1] - mid[-1])]])


def _save(fig: Any, out: Path, stem: str) -> list[Path]:
    files = []
    for ext in ("png", "svg"):
        path = out / f"{stem}.{ext}"
        fig.savefig(path, dpi=120)
        files.append(path)
    _pyplot().close(fig)
    return files


def plot_map(
    table: Any, x: str, y: str, metric: str, out: Path, *, stem: str | None = None
) -> list[Path]:
    """One panel per controller of ``metric`` over axes ``x`` and ``y``, one colour scale for
    all panels; writes ``{metric}_map_{x}_{y}`` (or ``stem``) as PNG and SVG."""
    plt = _pyplot()
    controllers, (xv, yv), mean = aggregate(table, (x, y), metric)
    if metric == "fall_rate":
        vmin, vmax, cmap = 0.0, 1.0, "Reds"
    else:
        finite = mean[np.isfinite(mean)]
        vmin, vmax = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 1.0)
        if vmin == vmax:
            vmax = vmin + 1e-12
        cmap = "viridis"
    fig, axes = plt.subplots(
        1,
        len(controllers),
        figsize=(3.6 * len(controllers) + 1.2, 3.6),
        sharey=True,
        constrained_layout=True,
        squeeze=False,
    )
    mesh = None
    for ax, name, grid in zip(axes[0], controllers, mean, strict=True):
        mesh = ax.pcolormesh(_edges(xv), _edges(yv), grid.T, vmin=vmin, vmax=vmax, cmap=cmap)
        ax.set_title(name)
        ax.set_xlabel(x)
        if metric == "fall_rate":
            ax.text(
                0.03,
                0.04,
                f"mean {np.nanmean(grid):.0%}",
                transform=ax.transAxes,
                fontsize=9,
                bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0},
            )
    axes[0][0].set_ylabel(y)
    fig.colorbar(mesh, ax=axes[0].tolist(), label=LABELS.get(metric, metric))
    return _save(fig, out, stem or f"{metric}_map_{x}_{y}".replace(".", "_"))


def plot_marginals(
    table: Any,
    axes: Sequence[str],
    out: Path,
    metrics: Sequence[str] = ("fall_rate", "rmse_pendulum"),
) -> list[Path]:
    """For each axis (columns) and metric (rows), the metric against the axis value, one line
    per controller; writes ``marginals`` as PNG and SVG."""
    plt = _pyplot()
    fig, grid = plt.subplots(
        len(metrics),
        len(axes),
        figsize=(3.8 * len(axes) + 0.6, 2.8 * len(metrics)),
        constrained_layout=True,
        squeeze=False,
        sharex="col",
    )
    for j, axis in enumerate(axes):
        for i, metric in enumerate(metrics):
            controllers, (values,), mean = aggregate(table, (axis,), metric)
            ax = grid[i][j]
            for k, name in enumerate(controllers):
                ax.plot(
                    values,
                    mean[k],
                    marker="o",
                    markersize=3,
                    label=name,
                    color=_COLORS.get(name, f"C{k}"),
                )
            ax.grid(True, alpha=0.3)
            if j == 0:
                ax.set_ylabel(LABELS.get(metric, metric))
            if i == len(metrics) - 1:
                ax.set_xlabel(axis)
            if metric == "fall_rate":
                ax.set_ylim(-0.03, 1.03)
    grid[0][0].legend(fontsize=8)
    return _save(fig, out, "marginals")


def plot_campaign(
    campaign: Any, table: Any, out: Path, axes: tuple[str, str] | None = None
) -> list[Path]:
    """The default figures: fall-rate and pendulum-RMSE maps over ``axes`` (default: the first
    two axes of the spec), and the marginal plots over every axis. ``table`` is a table of
    runs or :class:`Aggregates` holding those axes."""
    names = [a.name for a in campaign.axes]
    files: list[Path] = []
    pair = axes or (tuple(names[:2]) if len(names) >= 2 else None)
    if pair is not None:
        for metric in ("fall_rate", "rmse_pendulum"):
            files += plot_map(table, pair[0], pair[1], metric, out, stem=f"{metric}_map")
    if names:
        files += plot_marginals(table, names, out)
    return files

"""One chunk of runs through the Rust batch API (:func:`riprs.simulate_metrics`)."""

from __future__ import annotations

import copy
import threading
from collections.abc import Mapping
from typing import Any

import numpy as np

from riprs import __version__
from riprs._riprs import FurutaParams
from riprs.campaign.spec import METRICS, Campaign, CampaignError, _parse, _sim_setup

__all__ = ["compute_chunk"]


def _segment_metrics(
    params: FurutaParams,
    controller: Any,
    noise_seed: int,
    first: int,
    count: int,
    duration: float,
    options: Mapping[str, Any],
    settle_band: float | None,
    cancel: threading.Event | None,
) -> dict[str, np.ndarray]:
    """Seeds ``first .. first + count - 1`` of one grid point, in parallel on all cores: seed
    index ``s`` uses noise seed ``noise_seed + s``. Only metrics come back (no trajectories, no
    Python per run)."""
    from riprs.sim import simulate_metrics

    # The batch API's own default band, unless the spec names one.
    band = {} if settle_band is None else {"settle_band": settle_band}
    if cancel is not None and cancel.is_set():
        raise KeyboardInterrupt
    m = simulate_metrics(
        params,
        controller,
        count,
        duration,
        seed=noise_seed,
        first_run=first,
        cancel=cancel,
        **band,
        **options,
    )
    return {
        "rmse_arm": m.rmse[:, 0],
        "rmse_pendulum": m.rmse[:, 1],
        "rmse_voltage": m.rmse[:, 2],
        "fell": m.fell,
        "diverged": m.diverged,
        "fall_time": m.fall_time,
        "peak_voltage": m.peak_voltage,
        "settle_time": m.settle_time,
        "seed": m.seed,
    }


_CAMPAIGNS: dict[str, Campaign] = {}


def _campaign_from_payload(payload: Mapping[str, Any]) -> Campaign:
    """A worker's parsed campaign, parsed once per process."""
    if payload["version"] != __version__:
        raise CampaignError(
            f"this worker has riprs {__version__}, the campaign was started with riprs "
            f"{payload['version']}: install the same version everywhere"
        )
    campaign = _CAMPAIGNS.get(payload["hash"])
    if campaign is None:
        campaign = _parse(copy.deepcopy(payload["spec"]))
        if len(_CAMPAIGNS) > 8:
            _CAMPAIGNS.clear()
        _CAMPAIGNS[payload["hash"]] = campaign
    return campaign


def _run_payload_chunk(payload: Mapping[str, Any], start: int, stop: int) -> dict[str, Any]:
    """What a Dask worker runs: one chunk, from the spec's tables (plain data, no objects)."""
    return compute_chunk(_campaign_from_payload(payload), start, stop)


def compute_chunk(
    campaign: Campaign, start: int, stop: int, cancel: threading.Event | None = None
) -> dict[str, np.ndarray]:
    """Runs ``start .. stop-1`` of ``campaign``: the result columns as numpy arrays.

    Setting ``cancel`` from another thread stops the chunk with ``KeyboardInterrupt`` within a
    control sample.

    The seeds of one grid point and controller are consecutive runs; each such segment is one
    call of the Rust batch API, which runs its seeds in parallel and returns metrics only.
    A controller is designed once per chunk for each combination of setting axes it meets.
    """
    if not 0 <= start < stop <= campaign.runs:
        raise CampaignError(f"chunk {start}..{stop} is outside 0..{campaign.runs}")
    runs = np.arange(start, stop, dtype=np.int64)
    idx = campaign.index(runs)
    n = len(runs)
    columns: dict[str, Any] = {
        "run": runs,
        "controller": np.array([campaign.controllers[c] for c in idx["controller"]], dtype=object),
        "point": idx["point"],
        "seed_index": idx["seed_index"].astype(np.int32),
        "noise_seed": idx["noise_seed"],
    }
    for axis in campaign.axes:
        columns[axis.name] = axis.values[idx[f"axis:{axis.name}"]]
    for name in METRICS:
        columns[name] = np.empty(n, dtype=bool if name in ("fell", "diverged") else np.float64)

    settings = campaign.setting_axes()
    plant_axes = [a for a in campaign.axes if a.parameter is not None or a.draws is not None]
    designs: dict[tuple[int, ...], tuple[Any, FurutaParams, dict[str, Any]]] = {}
    # Segment boundaries: where the controller or the grid point changes.
    cut = np.flatnonzero((np.diff(idx["controller"]) != 0) | (np.diff(idx["point"]) != 0)) + 1
    for a, b in zip(np.r_[0, cut], np.r_[cut, n], strict=True):
        c = int(idx["controller"][a])
        key = (c, *(int(idx[f"axis:{ax.name}"][a]) for ax in settings))
        if key not in designs:
            config = campaign.config_for(key[1:])
            params, options = _sim_setup(config)
            designs[key] = (campaign.design(c, key[1:]), params, options)
        controller, params, options = designs[key]
        if plant_axes:
            nominal = params.to_dict()
            changes = {}
            for ax in plant_axes:
                if ax.draws is not None:  # a rig drawn from an identification's covariance
                    draw = ax.draws[idx[f"axis:{ax.name}"][a]]
                    changes.update(zip(ax.draw_names, map(float, draw), strict=True))
                    continue
                v = float(ax.values[idx[f"axis:{ax.name}"][a]])
                assert ax.parameter is not None
                changes[ax.parameter] = nominal[ax.parameter] * v if ax.relative else v
            params = params.replace(**changes)
        point = int(idx["point"][a])
        metrics = _segment_metrics(
            params,
            controller,
            campaign.seed + point * campaign.seeds,
            int(idx["seed_index"][a]),
            int(b - a),
            campaign.duration,
            options,
            campaign.settle_band,
            cancel,
        )
        if not np.array_equal(metrics["seed"], idx["noise_seed"][a:b]):
            raise CampaignError("the batch API numbered the seeds differently")  # pragma: no cover
        for name in METRICS:
            columns[name][a:b] = metrics[name]
    return columns

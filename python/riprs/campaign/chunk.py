"""One chunk of runs through the Rust batch API, and the per-run metrics."""

from __future__ import annotations

import copy
import os
import sys
from collections.abc import Mapping, Sequence
from typing import Any, Union

import numpy as np

from riprs import __version__
from riprs._riprs import Plant
from riprs.campaign.spec import METRICS, Campaign, CampaignError, _design, _parse, _sim_setup

if sys.version_info >= (3, 11):
    pass
else:  # pragma: no cover
    pass

__all__ = ["compute_chunk"]

PathLike = Union[str, "os.PathLike[str]"]

EXAMPLE_SPEC = """\
# riprs campaign: LQR vs LQG vs MPC when the pendulum mass and the arm length are not what the
# controllers were designed for (the paper's robustness question, as a map).
# Every section of the experiment spec ([plant], [sensor], [reference], [lqr], [mpc], ...)
# may follow; without them the paper's setting is used.

[campaign]
controllers = ["LQR", "LQG", "MPC"]
seeds = 20                 # noise seeds per grid point
duration = 10.0            # s per run

[[campaign.axis]]
name = "mp"                # pendulum mass: a scale factor on the base plant's value
scale = [0.7, 1.3]
points = 13

[[campaign.axis]]
name = "Lr"                # arm length
scale = [0.8, 1.2]
points = 9
"""


# -- the batch runner ---------------------------------------------------------------------------


def _simulate_metrics(
    plants: Sequence[Plant],
    controller: Any,
    seeds: Sequence[int],
    duration: float,
    options: Mapping[str, Any],
    settle_band: float,
) -> dict[str, np.ndarray]:
    """Run ``(plants[i], seeds[i])`` in parallel through the Rust batch API; one value of each
    of :data:`METRICS` per run.

    Settling time: the first time after the reference step from which the true arm angle stays
    within ``settle_band * |arm_step|`` (or ``settle_band`` rad for a zero step) of its
    reference until the end of the run, measured from the step; NaN for a run that falls or is
    outside the band at its end.
    """
    from riprs.sim import simulate_batch

    results = simulate_batch(
        list(plants), controller, list(seeds), duration, paired=True, **options
    )
    n = len(results)
    out = {
        "rmse_arm": np.empty(n),
        "rmse_pendulum": np.empty(n),
        "rmse_voltage": np.empty(n),
        "fell": np.empty(n, dtype=bool),
        "fall_time": np.full(n, np.nan),
        "peak_voltage": np.empty(n),
        "settle_time": np.full(n, np.nan),
    }
    step = float(options.get("reference") or 0.0)
    step_time = float(options.get("reference_time", 0.0))
    band = settle_band * abs(step) if step else settle_band
    for i, r in enumerate(results):
        out["rmse_arm"][i], out["rmse_pendulum"][i], out["rmse_voltage"][i] = r.rmse
        out["fell"][i] = r.fell
        if r.fell and r.fall_time is not None:
            out["fall_time"][i] = r.fall_time
        out["peak_voltage"][i] = float(np.max(np.abs(r.u))) if len(r.u) else 0.0
        if not r.fell:
            outside = np.flatnonzero(np.abs(r.x[:, 0] - r.r[:, 0]) > band)
            if not len(outside):
                out["settle_time"][i] = 0.0
            elif outside[-1] + 1 < len(r.t):
                out["settle_time"][i] = max(float(r.t[outside[-1] + 1]) - step_time, 0.0)
    return out


# -- one chunk ----------------------------------------------------------------------------------

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


def compute_chunk(campaign: Campaign, start: int, stop: int) -> dict[str, np.ndarray]:
    """Runs ``start .. stop-1`` of ``campaign``: the result columns as numpy arrays.

    Runs that share a controller and the setting-axis values go to the Rust batch API in one
    call (a plant variant and a noise seed per run), so a chunk costs a few Python calls, not
    one per run.
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
        columns[name] = np.empty(n, dtype=bool if name == "fell" else np.float64)

    settings = campaign.setting_axes()
    plant_axes = [a for a in campaign.axes if a.parameter is not None]
    keys = np.column_stack([idx["controller"], *(idx[f"axis:{a.name}"] for a in settings)]).astype(
        np.int64
    )
    groups: dict[tuple[int, ...], list[int]] = {}
    for i, key in enumerate(map(tuple, keys.tolist())):
        groups.setdefault(key, []).append(i)
    for key, members in groups.items():
        config = campaign.config_for(tuple(key[1:]))
        controller = _design(config, campaign.controllers[key[0]])
        params, options = _sim_setup(config)
        nominal = params.to_dict()
        plants = []
        for i in members:
            changes = {}
            for a in plant_axes:
                v = float(a.values[idx[f"axis:{a.name}"][i]])
                assert a.parameter is not None
                changes[a.parameter] = nominal[a.parameter] * v if a.relative else v
            plants.append(Plant(params.replace(**changes)) if changes else Plant(params))
        metrics = _simulate_metrics(
            plants,
            controller,
            [int(s) for s in idx["noise_seed"][members]],
            campaign.duration,
            options,
            campaign.settle_band,
        )
        for name in METRICS:
            columns[name][members] = metrics[name]
    return columns

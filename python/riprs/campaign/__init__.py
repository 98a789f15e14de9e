"""Robustness and tuning campaigns: many closed-loop runs over a grid of plant errors and settings.

A campaign spec is an experiment spec (``[plant]``, ``[sensor]``, ``[reference]``, ``[lqr]``,
``[mpc]``, ... as read by ``riprs compare``) plus a ``[campaign]`` section::

    [campaign]
    controllers = ["LQR", "LQG", "MPC"]
    seeds = 20              # noise seeds per grid point
    duration = 10.0         # s per run (default: reference.duration)
    seed = 0                # first noise seed
    chunk_size = 256        # runs per unit of work (default: automatic; no result depends on it)
    settle_band = 0.02      # rad: the arm counts as settled within this of its reference

    [[campaign.axis]]
    name = "mp"             # a FurutaParams name: the true plant's value, design unchanged
    scale = [0.7, 1.3]      # factors on the base value ...
    points = 13             # ... on an even grid (or `samples = N`: N uniform random draws)

    [[campaign.axis]]
    name = "mpc.prediction_horizon"   # any numeric setting of the base spec, by its key path
    values = [20, 50, 100]            # absolute values (or `range = [lo, hi]` + points/samples)

An axis is named by a physical parameter of :class:`riprs.FurutaParams` (``mr``, ``Lr``, ``Jr``,
``mp``, ``Lp``, ``Jp``, ``Dr``, ``Dp``, ``Rm``, ``kt``, ``km``), which changes the simulated
plant while the controllers stay designed for the base plant (a model error), or by the key
path of a numeric setting (``lqr.R``, ``mpc.output_weights``, ``sensor.noise_std``,
``plant.initial_state[2]``, ...), which changes the experiment and, for controller sections, the
design; ``noise_std`` and ``initial_tilt`` are short for ``sensor.noise_std`` and
``plant.initial_state[2]``. A list setting given one value per point takes it in every entry.
``scale`` multiplies the base value and the result column holds the factor; ``range`` and
``values`` give the value itself, which the column holds.

An axis ``name = "plant_covariance"`` with ``file = "rig.toml"`` and ``samples = N`` runs each
of ``N`` rigs drawn from that identified rig's ``[plant_covariance]`` (the identification's
uncertainty as the perturbation; its column holds the draw's number).

Runs are numbered ``run = (c * P + p) * S + s`` for controller ``c``, grid point ``p`` (axes in
spec order, the last varying fastest) and seed index ``s`` out of ``S``; run ``run`` uses noise
seed ``seed + p * S + s``, the same for every controller (common random numbers, so controllers
are compared on the same noise). Everything a run does follows from its index and the spec, so
results are identical whatever the engine, the chunking or the order in which chunks finish.

Results go to ``DIR/runs/*.parquet``, one row per run, written chunk by chunk (temporary file,
then rename) with ``DIR/manifest.json`` (spec hash, and the engine and package versions of
each session that wrote runs) and a copy of the spec. Running the same spec into the same
``DIR`` again skips the runs already on disk; another spec, or results of another riprs
version, is refused. The summary and the figures are summed chunk by chunk
(:class:`Aggregates`): memory does not grow with the number of runs.
"""

from riprs.campaign.chunk import compute_chunk
from riprs.campaign.engine import CampaignResult, run, summary
from riprs.campaign.plots import Aggregates
from riprs.campaign.spec import (
    COLUMNS,
    EXAMPLE_SPEC,
    METRICS,
    Axis,
    Campaign,
    CampaignError,
    load_spec,
)
from riprs.campaign.store import load

__all__ = [
    "COLUMNS",
    "EXAMPLE_SPEC",
    "METRICS",
    "Aggregates",
    "Axis",
    "Campaign",
    "CampaignError",
    "CampaignResult",
    "compute_chunk",
    "load",
    "load_spec",
    "run",
    "summary",
]

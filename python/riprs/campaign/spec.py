"""The campaign spec: ``[campaign]`` and its axes over the base experiment spec."""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np

from riprs import paper
from riprs._riprs import FurutaParams, RiprsError
from riprs.config import PARAMETERS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "ALIASES",
    "COLUMNS",
    "CONTROLLERS",
    "EXAMPLE_SPEC",
    "METRICS",
    "PLANT_PARAMETERS",
    "Axis",
    "Campaign",
    "CampaignError",
    "load_spec",
]

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
PLANT_PARAMETERS = tuple(PARAMETERS)  # the FurutaParams names, as the spec's [plant] has them
ALIASES = {"noise_std": "sensor.noise_std", "initial_tilt": "plant.initial_state[2]"}
# Sections whose settings may span an axis; the controller sections change the design.
AXIS_SECTIONS = ("plant", "sensor", "reference", "lqr", "kalman", "mpc")
CONTROLLERS = ("LQR", "LQG", "MPC")
DEFAULT_CHUNK_SIZE = 256
MAX_RUNS = 10**9
METRICS = (
    "rmse_arm",
    "rmse_pendulum",
    "rmse_voltage",
    "fell",
    "diverged",
    "fall_time",
    "peak_voltage",
    "settle_time",
)
# Columns before the axis columns; the axis columns (one per axis, named by the axis) follow,
# then METRICS.
COLUMNS = ("run", "controller", "point", "seed_index", "noise_seed")


class CampaignError(RiprsError):
    """A campaign spec, results directory or cluster problem; the message names the key or
    path. ``key`` is the key or argument the message begins with, as data, when it names one
    (so a command line can name its option instead)."""

    def __init__(self, message: str, *, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key

    def renamed(self, name: str) -> CampaignError:
        """The same error naming ``name`` in place of its key."""
        text = str(self)
        if self.key is None or not text.startswith(self.key):
            return self
        return CampaignError(name + text[len(self.key) :], key=name)


# -- the base experiment spec -------------------------------------------------------------------
# The three functions below are the only place that knows how the base sections are read: as
# the core's one experiment spec (``riprs.config.Spec``).


def _load_base(data: Mapping[str, Any]) -> Any:
    """The validated base experiment from its TOML tables (everything except ``[campaign]``)."""
    from riprs.config import Spec

    return Spec.from_dict(dict(data))


def _design(config: Any, controller: str) -> Any:
    """The controller named ``controller``, designed from ``config`` by the core's assembly."""
    from riprs.compare import build_controllers

    return build_controllers(config.updated({"controllers": [controller]}))[controller]


def _sim_setup(config: Any) -> tuple[FurutaParams, dict[str, Any]]:
    """The base plant's parameters and the options of :func:`riprs.simulate` for ``config``."""
    from riprs.compare import _sim_options

    return config.params, _sim_options(config)


# -- the spec -----------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Axis:
    """One dimension of the grid.

    Attributes
    ----------
    name : str
        As written in the spec; also the name of its result column.
    path : str or None
        The setting it changes (``"mpc.prediction_horizon"``), None for a plant parameter.
    parameter : str or None
        The :class:`riprs.FurutaParams` name it scales, None for a setting.
    relative : bool
        Whether :attr:`values` are factors on the base value (``scale``) or values (``range``,
        ``values``).
    values : ndarray
        The axis values, as stored in the result column (for a ``plant_covariance`` axis: the
        draw's number).
    draws : ndarray or None
        For a ``plant_covariance`` axis, shape ``(samples, len(draw_names))``: the plant
        parameters of each drawn rig (SI units).
    draw_names : tuple of str
        The ``[plant]`` names of :attr:`draws`' columns.
    """

    name: str
    path: str | None
    parameter: str | None
    relative: bool
    values: np.ndarray
    draws: np.ndarray | None = None
    draw_names: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.values)


@dataclass
class Campaign:
    """A parsed, validated campaign spec; see the module docs for its sections."""

    data: dict[str, Any]
    base: Any
    controllers: list[str]
    seeds: int
    duration: float
    seed: int
    chunk_size: int | None
    settle_band: float | None
    axes: list[Axis]
    spec_hash: str
    _configs: dict[tuple[int, ...], Any] = field(default_factory=dict, repr=False)
    _designs: dict[tuple[int, ...], Any] = field(default_factory=dict, repr=False)

    @property
    def shape(self) -> tuple[int, ...]:
        """Points along each axis."""
        return tuple(len(a) for a in self.axes)

    @property
    def points(self) -> int:
        """Grid points (the product of :attr:`shape`; 1 without axes)."""
        return math.prod(self.shape)  # Python ints: a huge grid is counted, never wrapped

    @property
    def runs(self) -> int:
        """Total runs: controllers x points x seeds."""
        return len(self.controllers) * self.points * self.seeds

    def index(self, runs: np.ndarray) -> dict[str, np.ndarray]:
        """Decompose run indices into controller index, point, seed index, noise seed and the
        index along each axis."""
        runs = np.asarray(runs, dtype=np.int64)
        per_controller = self.points * self.seeds
        point = (runs // self.seeds) % self.points
        seed_index = runs % self.seeds
        out = {
            "controller": runs // per_controller,
            "point": point,
            "seed_index": seed_index,
            "noise_seed": (self.seed + point * self.seeds + seed_index).astype(np.uint64),
        }
        if self.axes:
            for axis, idx in zip(self.axes, np.unravel_index(point, self.shape), strict=True):
                out[f"axis:{axis.name}"] = idx.astype(np.int64)
        return out

    def config_for(self, setting_index: tuple[int, ...]) -> Any:
        """The base experiment with the setting axes at the given indices (in the order of
        :meth:`setting_axes`)."""
        cached = self._configs.get(setting_index)
        if cached is None:
            cached = _config_with(self, dict(zip(self.setting_axes(), setting_index, strict=True)))
            if len(self._configs) < 4096:
                self._configs[setting_index] = cached
        return cached

    def design(self, controller: int, setting_index: tuple[int, ...]) -> Any:
        """Controller ``controller`` designed for the setting axes at ``setting_index``: once
        per distinct combination (cached). A failure names the axes and their values."""
        key = (controller, *setting_index)
        cached = self._designs.get(key)
        if cached is None:
            try:
                cached = _design(self.config_for(setting_index), self.controllers[controller])
            except (RiprsError, ValueError, ArithmeticError) as exc:
                where = ", ".join(
                    f"{a.name} = {np.asarray(a.values[i]).item()!r}"
                    for a, i in zip(self.setting_axes(), setting_index, strict=True)
                )
                at = f" at {where}" if where else ""
                raise CampaignError(
                    f"cannot design {self.controllers[controller]}{at}: {exc}"
                ) from None
            if len(self._designs) < 4096:
                self._designs[key] = cached
        return cached

    def design_all(self) -> None:
        """Designs every controller for every combination of setting axes, so that a setting
        that cannot be designed fails before any run."""
        for combo in np.ndindex(*(len(a) for a in self.setting_axes())):
            for c in range(len(self.controllers)):
                self.design(c, tuple(int(i) for i in combo))

    def setting_axes(self) -> list[Axis]:
        """The axes that change a setting (not a plant parameter)."""
        return [a for a in self.axes if a.path is not None]


def load_spec(spec: PathLike | Mapping[str, Any]) -> Campaign:
    """Read and validate a campaign spec: a TOML file or its parsed tables.

    Raises
    ------
    CampaignError
        A bad ``[campaign]`` key or value (named, e.g. ``campaign.axis[1].points``) or TOML
        syntax.
    riprs.config.ConfigError
        A bad key or value in a base section (named), including an axis value it rejects.
    OSError
        The file cannot be read.
    """
    if isinstance(spec, Mapping):
        return _parse(copy.deepcopy(dict(spec)))
    path = os.fspath(spec)
    with open(path, "rb") as fh:
        try:
            data = tomllib.load(fh)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise CampaignError(f"{path}: invalid TOML: {exc}") from None
        except RecursionError:
            raise CampaignError(
                f"{path}: invalid TOML: arrays or tables nested too deeply"
            ) from None
    try:
        return _parse(data, os.path.dirname(os.path.abspath(path)))
    except RiprsError as exc:
        raise type(exc)(f"{path}: {exc}") from None


_IGNORED_TOP = {
    "controllers": "set the controllers in [campaign] as campaign.controllers",
    "monte_carlo": "a campaign's runs are set in [campaign] (campaign.seeds, campaign.seed)",
}
# Settings that the runs never read (each run's length is campaign.duration): an axis over one
# would label columns with values that change nothing.
_NO_EFFECT = {"reference.duration": "set the run length with campaign.duration"}
_CAMPAIGN_KEYS = ("axis", "chunk_size", "controllers", "duration", "seed", "seeds", "settle_band")
_AXIS_KEYS = ("file", "name", "points", "range", "samples", "scale", "values")
#: The name of the axis whose points are rigs drawn from an identification's covariance.
COVARIANCE_AXIS = "plant_covariance"
#: Draws of a ``plant_covariance`` axis tried per sample before the covariance is refused (a
#: draw that is not a valid plant, e.g. a negative friction, is drawn again).
MAX_REDRAWS = 100


def _parse(data: dict[str, Any], base_dir: str = ".") -> Campaign:
    if "campaign" not in data:
        raise CampaignError("missing [campaign] section (see `riprs campaign --example`)")
    section = data["campaign"]
    if not isinstance(section, dict):
        raise CampaignError(f"campaign must be a table, got {section!r}")
    unknown = sorted(set(section) - set(_CAMPAIGN_KEYS))
    if unknown:
        raise CampaignError(
            f"unknown key 'campaign.{unknown[0]}'; valid keys: {', '.join(_CAMPAIGN_KEYS)}"
        )
    # Settings of `riprs compare` that a campaign would silently ignore: refused, with the place
    # the campaign takes them from.
    for k, instead in _IGNORED_TOP.items():
        if k in data:
            raise CampaignError(f"'{k}' is not used by a campaign; {instead}")
    base_data = {k: v for k, v in data.items() if k != "campaign"}
    base = _load_base(base_data)

    controllers = section.get("controllers", list(CONTROLLERS))
    if not isinstance(controllers, list) or not controllers:
        raise CampaignError(
            f"campaign.controllers must be a non-empty array of {', '.join(CONTROLLERS)}, "
            f"got {controllers!r}"
        )
    for i, name in enumerate(controllers):
        if name not in CONTROLLERS:
            raise CampaignError(
                f"campaign.controllers[{i}] must be one of {', '.join(CONTROLLERS)}, got {name!r}"
            )
    if len(set(controllers)) != len(controllers):
        raise CampaignError(f"campaign.controllers has duplicates: {controllers}")
    seeds = _int(section.get("seeds", 1), "campaign.seeds", 1)
    seed = _int(section.get("seed", 0), "campaign.seed", 0)
    chunk_size = section.get("chunk_size")
    if chunk_size is not None:
        chunk_size = _int(chunk_size, "campaign.chunk_size", 1)
    duration = _number(section.get("duration", base.reference.duration), "campaign.duration")
    if not paper.TS <= duration <= 3600.0:
        raise CampaignError(
            f"campaign.duration must be between one sample ({paper.TS} s) and 3600 s, "
            f"got {duration}"
        )
    settle_band = section.get("settle_band")
    if settle_band is not None:
        settle_band = _number(settle_band, "campaign.settle_band")
        if not settle_band > 0:
            raise CampaignError(f"campaign.settle_band must be positive, got {settle_band}")

    raw_axes = section.get("axis", [])
    if not isinstance(raw_axes, list):
        raise CampaignError("campaign.axis must be an array of tables ([[campaign.axis]])")
    axes = [
        _parse_axis(a, f"campaign.axis[{i}]", i, seed, base, base_dir)
        for i, a in enumerate(raw_axes)
    ]
    for i, axis in enumerate(axes):
        for a in axes[:i]:
            if _overlap(a, axis):
                same = a.name if a.name == axis.name else f"{a.name!r} ({a.path or a.name})"
                raise CampaignError(
                    f"campaign.axis[{i}].name: {axis.name!r} ({axis.path or axis.name}) "
                    f"overlaps the axis {same}; a setting can span one axis only"
                )
        if axis.name in COLUMNS or axis.name in METRICS:
            raise CampaignError(f"campaign.axis[{i}].name: {axis.name!r} is a result column")

    hashed = copy.deepcopy(data)
    hashed["campaign"].pop("chunk_size", None)  # chunking never changes a result
    for i, axis in enumerate(axes):
        if axis.draws is not None:  # the drawn rigs, not only the file's name, fix the runs
            hashed["campaign"]["axis"][i]["draws"] = axis.draws.tolist()
    spec_hash = hashlib.sha256(
        json.dumps(hashed, sort_keys=True, separators=(",", ":"), default=str).encode()
    ).hexdigest()
    campaign = Campaign(
        data=data,
        base=base,
        controllers=list(controllers),
        seeds=seeds,
        duration=duration,
        seed=seed,
        chunk_size=chunk_size,
        settle_band=settle_band,
        axes=axes,
        spec_hash=spec_hash,
    )
    if campaign.runs > MAX_RUNS:
        raise CampaignError(f"the campaign has {campaign.runs} runs; at most {MAX_RUNS}")
    if seed + campaign.points * seeds >= 2**63:
        raise CampaignError(
            f"campaign.seed must leave every run's noise seed below 2**63, got {seed}"
        )
    # Every combination of setting values is checked now, so that no chunk fails on one later.
    settings = campaign.setting_axes()
    combos = math.prod(len(a) for a in settings)
    if combos > 100_000:
        raise CampaignError(
            f"the setting axes span {combos} combinations (each a separate design); at most 100000"
        )
    for combo in np.ndindex(*(len(a) for a in settings)):
        campaign.config_for(tuple(int(i) for i in combo))
    return campaign


def _parse_axis(
    raw: Any, key: str, index: int, seed: int, base: Any, base_dir: str = "."
) -> Axis:
    if not isinstance(raw, dict):
        raise CampaignError(f"{key} must be a table, got {raw!r}")
    unknown = sorted(set(raw) - set(_AXIS_KEYS))
    if unknown:
        raise CampaignError(
            f"unknown key '{key}.{unknown[0]}'; valid keys: {', '.join(_AXIS_KEYS)}"
        )
    name = raw.get("name")
    if not isinstance(name, str) or not name:
        raise CampaignError(f"{key}.name must be a string, got {name!r}")
    if name == COVARIANCE_AXIS:
        return _covariance_axis(raw, key, index, seed, base, base_dir)
    if "file" in raw:
        raise CampaignError(f"{key}.file goes with name = {COVARIANCE_AXIS!r} only")
    parameter = name if name in PLANT_PARAMETERS else None
    path = None if parameter else ALIASES.get(name, name)
    base_value: Any = None
    if path in _NO_EFFECT:
        raise CampaignError(f"{key}.name: {path} has no effect on the runs; {_NO_EFFECT[path]}")
    if path is not None:
        base_value = _resolve(base, path, f"{key}.name")

    given = [k for k in ("scale", "range", "values") if k in raw]
    if len(given) != 1:
        raise CampaignError(f"{key} needs exactly one of scale, range or values, got {given}")
    kind = given[0]
    if kind == "values":
        values = raw["values"]
        if not isinstance(values, list) or not values:
            raise CampaignError(f"{key}.values must be a non-empty array, got {values!r}")
        for k in ("points", "samples"):
            if k in raw:
                raise CampaignError(f"{key}.{k} goes with scale or range, not with values")
        array = np.array([_number(v, f"{key}.values[{i}]") for i, v in enumerate(values)])
        if len(set(array.tolist())) != len(array):
            raise CampaignError(f"{key}.values has duplicates: {values}")
    else:
        bounds = raw[kind]
        if not isinstance(bounds, list) or len(bounds) != 2:
            raise CampaignError(f"{key}.{kind} must be [low, high], got {bounds!r}")
        lo = _number(bounds[0], f"{key}.{kind}[0]")
        hi = _number(bounds[1], f"{key}.{kind}[1]")
        if lo > hi:
            raise CampaignError(f"{key}.{kind} must have low <= high, got {bounds}")
        counts = [k for k in ("points", "samples") if k in raw]
        if len(counts) != 1:
            raise CampaignError(f"{key} needs exactly one of points or samples with {kind}")
        n = _int(raw[counts[0]], f"{key}.{counts[0]}", 1)
        if n > 100_000:
            raise CampaignError(f"{key}.{counts[0]} must be at most 100000, got {n}")
        if counts[0] == "points":
            array = np.linspace(lo, hi, n) if n > 1 else np.array([lo])
            if n > 1 and lo == hi:
                raise CampaignError(f"{key}.{kind} must have low < high for {n} points")
        else:
            # Drawn from the campaign seed and the axis position, so the spec fixes them.
            rng = np.random.default_rng([seed, index])
            array = np.sort(rng.uniform(lo, hi, n))
    relative = kind == "scale"
    if relative and np.any(array <= 0):
        raise CampaignError(f"{key}.{kind}: scale factors must be positive")
    whole = _is_int(base_value) or (
        isinstance(base_value, list) and all(_is_int(v) for v in base_value)
    )
    if whole:
        if kind == "values" and np.any(array != np.round(array)):
            raise CampaignError(f"{key}.values: {path} takes whole numbers, got {raw['values']}")
        # A grid over a whole-number setting lands on whole numbers (a scale on a list of them
        # rounds each entry when the setting is made).
        if not (relative and isinstance(base_value, list)):
            factor = base_value if relative else 1
            rounded = np.round(array * factor)
            if np.any(array * factor != rounded):
                if len(np.unique(rounded)) != len(rounded):
                    raise CampaignError(
                        f"{key}: {path} takes whole numbers and the axis values round to "
                        f"duplicates ({rounded.tolist()}); give integer values"
                    )
                array = rounded / factor
    if parameter is not None:
        nominal = getattr(base.params, parameter)
        for v in (array.min(), array.max()):
            try:
                base.params.replace(**{parameter: nominal * v if relative else v})
            except RiprsError as exc:
                raise CampaignError(f"{key}: {exc}") from None
    return Axis(name=name, path=path, parameter=parameter, relative=relative, values=array)


def _covariance_axis(
    raw: dict[str, Any], key: str, index: int, seed: int, base: Any, base_dir: str
) -> Axis:
    """A ``plant_covariance`` axis: ``samples`` rigs drawn from the ``[plant_covariance]`` of
    ``file`` (:func:`riprs.identify.read_plant_covariance`), ``[plant] + N(0, matrix)`` on the
    named parameters, a draw that is not a valid plant drawn again (as ``riprs.envs`` draws)."""
    from riprs._riprs import Plant
    from riprs.identify import IdentifyError, read_plant_covariance

    extra = sorted(set(raw) - {"name", "samples", "file"})
    if extra:
        raise CampaignError(
            f"{key}.{extra[0]}: a {COVARIANCE_AXIS} axis takes file and samples only"
        )
    if "samples" not in raw:
        raise CampaignError(f"{key} needs samples (the number of rigs drawn)")
    n = _int(raw["samples"], f"{key}.samples", 1)
    if n > 100_000:
        raise CampaignError(f"{key}.samples must be at most 100000, got {n}")
    file = raw.get("file")
    if not isinstance(file, str) or not file:
        raise CampaignError(
            f"{key}.file must name the identified rig file (or its .identification.toml), "
            f"got {file!r}"
        )
    path = os.path.join(base_dir, file)
    if not os.path.isfile(path):
        raise CampaignError(f"{key}.file: {path} does not exist")
    try:
        found = read_plant_covariance(path)
    except IdentifyError as exc:
        raise CampaignError(f"{key}.file: {exc}") from None
    if found is None:
        raise CampaignError(
            f"{key}.file: {path} holds no [plant_covariance], nor does an identification file "
            "beside it (riprs identify writes one)"
        )
    names, matrix = found
    for name in names:
        if name not in PLANT_PARAMETERS:
            raise CampaignError(f"{key}.file: {path}: {name!r} is not a [plant] parameter")
    # A symmetric square root that allows a semi-definite matrix (a parameter held at zero).
    w, v = np.linalg.eigh(0.5 * (matrix + matrix.T))
    if not (np.all(np.isfinite(w)) and w.min() >= -1e-9 * max(w.max(), 0.0)):
        raise CampaignError(f"{key}.file: {path}: plant_covariance is not a covariance matrix")
    root = v * np.sqrt(np.clip(w, 0.0, None))
    nominal = base.params.to_dict()
    mean = np.array([float(nominal[name]) for name in names])
    rng = np.random.default_rng([seed, index])
    draws = np.empty((n, len(names)))
    for i in range(n):
        for _ in range(MAX_REDRAWS):
            x = mean + root @ rng.standard_normal(len(names))
            try:
                Plant(base.params.replace(**dict(zip(names, map(float, x), strict=True))))
            except (RiprsError, ValueError):
                continue
            draws[i] = x
            break
        else:
            raise CampaignError(
                f"{key}.file: {path}: {MAX_REDRAWS} draws in a row from plant_covariance are "
                "not valid plants; the covariance is too wide for this rig"
            )
    return Axis(
        name=COVARIANCE_AXIS,
        path=None,
        parameter=None,
        relative=False,
        values=np.arange(n, dtype=np.float64),
        draws=draws,
        draw_names=tuple(names),
    )


_PATH = re.compile(r"^([A-Za-z_]\w*)\.([A-Za-z_]\w*)(?:\[(\d+)\])?$")


def _resolve(base: Any, path: str, key: str) -> Any:
    """The base value at ``path`` (a number, or a list of numbers); refuses any other path."""
    m = _PATH.match(path)
    if m is None or m.group(1) not in AXIS_SECTIONS:
        raise CampaignError(
            f"{key}: unknown axis {path!r}; give a FurutaParams name "
            f"({', '.join(PLANT_PARAMETERS)}), {', '.join(ALIASES)}, or the key path of a "
            f"numeric setting in [{'], ['.join(AXIS_SECTIONS)}] such as mpc.prediction_horizon"
        )
    section, name, idx = m.group(1), m.group(2), m.group(3)
    holder = getattr(base, section, None)
    value = _plain(getattr(holder, name, None)) if holder is not None else None
    if idx is not None:
        if not isinstance(value, list) or int(idx) >= len(value):
            raise CampaignError(f"{key}: {path} does not name an entry of a list setting")
        value = value[int(idx)]
    numeric = _is_number(value) or (
        isinstance(value, list) and value and all(_is_number(v) for v in value)
    )
    if not numeric:
        raise CampaignError(f"{key}: {path} is not a numeric setting of the base spec")
    return value


def _overlap(a: Axis, b: Axis) -> bool:
    """Whether two axes change the same setting (a list setting and one of its entries, or the
    same entry) or the same plant parameter."""
    if a.draws is not None or b.draws is not None:
        changed = [set(x.draw_names) | ({x.parameter} if x.parameter else set()) for x in (a, b)]
        return bool(changed[0] & changed[1])
    if a.path is None or b.path is None:
        return a.parameter is not None and a.parameter == b.parameter
    ma, mb = _PATH.match(a.path), _PATH.match(b.path)
    assert ma is not None and mb is not None
    if ma.group(1, 2) != mb.group(1, 2):
        return False
    return ma.group(3) is None or mb.group(3) is None or ma.group(3) == mb.group(3)


def _config_with(campaign: Campaign, at: Mapping[Axis, int]) -> Any:
    """The base experiment with each setting axis in ``at`` at its given index."""
    data = copy.deepcopy({k: v for k, v in campaign.data.items() if k != "campaign"})
    for axis, i in at.items():
        assert axis.path is not None
        m = _PATH.match(axis.path)
        assert m is not None
        section, name, idx = m.group(1), m.group(2), m.group(3)
        base_value = _plain(getattr(getattr(campaign.base, section), name))
        v = float(axis.values[i])

        def new(old: Any, v: float = v, relative: bool = axis.relative) -> Any:
            value = old * v if relative else v
            return round(value) if _is_int(old) else float(value)

        if idx is not None:
            leaf = list(base_value)
            leaf[int(idx)] = new(leaf[int(idx)])
        elif isinstance(base_value, list):
            leaf = [new(old) for old in base_value]
        else:
            leaf = new(base_value)
        table = data.setdefault(section, {})
        if not isinstance(table, dict):
            raise CampaignError(f"{section} must be a table")
        table[name] = leaf
    try:
        return _load_base(data)
    except RiprsError as exc:
        where = ", ".join(f"{a.name} = {a.values[i]:g}" for a, i in at.items())
        raise type(exc)(f"at {where}: {exc}") from None


def _plain(v: Any) -> Any:
    """A setting as plain Python numbers and lists, however the spec object returns it."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _int(v: Any, key: str, minimum: int) -> int:
    if not _is_int(v) or v < minimum:
        raise CampaignError(f"{key} must be an integer >= {minimum}, got {v!r}", key=key)
    return int(v)


def _number(v: Any, key: str) -> float:
    if not _is_number(v) or not math.isfinite(v):
        raise CampaignError(f"{key} must be a finite number, got {v!r}")
    return float(v)

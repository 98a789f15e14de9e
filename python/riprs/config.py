"""Configuration of ``riprs compare``: TOML in, validated dataclasses out.

Every default is the paper's setting (section 3 for the MPC, eq. (13) for LQR/LQG, section 7 for
the 0 -> 1 rad arm step). A key that does not exist, or a value of the wrong type, shape or
range, raises :class:`ConfigError` naming the key, e.g. ``mpc.prediction_horizon``.

Example (every section and key is optional)::

    [plant]
    preset = "paper"            # or "qube_servo2"
    substeps = 10               # RK4 steps per control period
    initial_state = [0.0, 0.0, 0.05, 0.0]

    [sensor]
    encoder_counts = [2048, 2048]
    noise_std = [0.001, 0.001]  # rad

    [reference]
    arm_step = 1.0              # rad
    step_time = 1.0             # s
    duration = 10.0             # s

    [lqr]
    Q = [25.0, 0.0, 50.0, 0.0]  # diagonal of eq. (13)
    R = 0.1
    rate_cutoff = 20.0          # Hz, the rate filter of the measured angles

    [lqg]
    Q = [25.0, 0.0, 50.0, 0.0]
    R = 0.1

    [mpc]
    prediction_horizon = 50
    control_horizon = 3
    solver = "active_set"
    disturbance_gain = 0.01     # eq. (1): integrated white noise on both outputs

    [monte_carlo]
    runs = 100
    perturbation = 0.1          # +-10 % on every physical parameter
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from dataclasses import dataclass, field
from typing import Any, Union

from riprs._riprs import MAX_PREDICTION_HORIZON, RiprsError
from riprs.paper import TS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "CompareConfig",
    "ConfigError",
    "LqgConfig",
    "LqrConfig",
    "MonteCarloConfig",
    "MpcConfig",
    "PlantConfig",
    "ReferenceConfig",
    "SensorConfig",
    "load_config",
]

CONTROLLERS = ("LQR", "LQG", "MPC")
PRESETS = ("paper", "qube_servo2")
SOLVERS = ("active_set", "clarabel")
PERTURBABLE = ("mr", "Lr", "Jr", "mp", "Lp", "Jp", "Dr", "Dp", "Rm", "kt", "km")
# Longest simulated run: an hour of the paper's 100 Hz loop (360 000 samples per controller).
MAX_DURATION = 3600.0


class ConfigError(RiprsError):
    """A configuration key or value is invalid; the message names it."""


@dataclass
class PlantConfig:
    """The simulated nonlinear plant."""

    preset: str = "paper"
    substeps: int = 10
    initial_state: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.05, 0.0])
    fall_limit: float = math.pi / 2

    def validate(self, prefix: str) -> None:
        _one_of(self.preset, PRESETS, f"{prefix}.preset")
        _positive_int(self.substeps, f"{prefix}.substeps")
        _length(self.initial_state, 4, f"{prefix}.initial_state")
        for i, v in enumerate(self.initial_state):
            _finite(v, f"{prefix}.initial_state[{i}]")
        _positive(self.fall_limit, f"{prefix}.fall_limit")


@dataclass
class SensorConfig:
    """Encoders and measurement noise.

    The defaults model a 2048-count quadrature encoder on each joint (the QUBE-Servo 2's) and
    1 mrad of white noise, about a third of one count: the paper does not state its sensors.
    """

    encoder_counts: list[float] = field(default_factory=lambda: [2048.0, 2048.0])
    noise_std: list[float] = field(default_factory=lambda: [1e-3, 1e-3])

    def validate(self, prefix: str) -> None:
        _length(self.encoder_counts, 2, f"{prefix}.encoder_counts")
        for i, c in enumerate(self.encoder_counts):
            if not (math.isfinite(c) and c >= 1 and c == int(c)):
                raise ConfigError(
                    f"{prefix}.encoder_counts[{i}] must be a whole number of counts per "
                    f"revolution, at least 1; got {c}"
                )
        _length(self.noise_std, 2, f"{prefix}.noise_std")
        for i, s in enumerate(self.noise_std):
            _non_negative(s, f"{prefix}.noise_std[{i}]")


@dataclass
class ReferenceConfig:
    """The arm-angle step of section 7."""

    arm_step: float = 1.0
    step_time: float = 1.0
    duration: float = 10.0

    def validate(self, prefix: str) -> None:
        if not (math.isfinite(self.arm_step) and abs(self.arm_step) <= math.pi):
            raise ConfigError(
                f"{prefix}.arm_step must be within [-pi, pi] rad, got {self.arm_step}"
            )
        _non_negative(self.step_time, f"{prefix}.step_time")
        if not (math.isfinite(self.duration) and TS <= self.duration <= MAX_DURATION):
            raise ConfigError(
                f"{prefix}.duration must be between one sample ({TS} s) and {MAX_DURATION} s, "
                f"got {self.duration}"
            )


@dataclass
class LqgConfig:
    """The LQR weights of eq. (13), ``Q = diag(Q)`` and ``R``, on the estimate of the Kalman
    filter the LQG shares with the MPC (eqs. (3)-(12); its noise model is ``[mpc]``'s)."""

    Q: list[float] = field(default_factory=lambda: [25.0, 0.0, 50.0, 0.0])
    R: float = 0.1

    def validate(self, prefix: str) -> None:
        _length(self.Q, 4, f"{prefix}.Q")
        for i, q in enumerate(self.Q):
            _non_negative(q, f"{prefix}.Q[{i}]")
        _positive(self.R, f"{prefix}.R")


@dataclass
class LqrConfig(LqgConfig):
    """Eq. (13): ``Q = diag(Q)``, ``R``; the rates come from the measured angles through a
    first-order filtered difference with cut-off ``rate_cutoff`` (Hz, ``inf`` for the plain
    difference), as :class:`riprs.Lqr`."""

    rate_cutoff: float = 20.0

    def validate(self, prefix: str) -> None:
        super().validate(prefix)
        if math.isnan(self.rate_cutoff) or self.rate_cutoff <= 0:
            raise ConfigError(
                f"{prefix}.rate_cutoff must be positive (Hz) or inf, got {self.rate_cutoff}"
            )


@dataclass
class MpcConfig:
    """Section 3's MPC settings (MATLAB MPC Toolbox semantics).

    ``output_bounds`` holds ``[lower, upper]`` per output or an empty list for none; the default
    bounds the pendulum angle (see :func:`riprs.paper.mpc` for why).
    """

    prediction_horizon: int = 50
    control_horizon: int = 3
    output_weights: list[float] = field(default_factory=lambda: [25.0, 50.0])
    input_rate_weights: list[float] = field(default_factory=lambda: [1.0])
    input_weights: list[float] = field(default_factory=lambda: [0.0])
    input_bounds: list[float] = field(default_factory=lambda: [-12.0, 12.0])
    output_bounds: list[list[float]] = field(
        default_factory=lambda: [[], [-math.pi / 6, math.pi / 6]]
    )
    ecr_weight: float = 100.0
    input_scales: list[float] = field(default_factory=lambda: [10.0])
    output_scales: list[float] = field(default_factory=lambda: [1.0, 1.0])
    solver: str = "active_set"
    disturbance_gain: float = 0.01

    def validate(self, prefix: str) -> None:
        _positive_int(self.prediction_horizon, f"{prefix}.prediction_horizon")
        if self.prediction_horizon > MAX_PREDICTION_HORIZON:
            raise ConfigError(
                f"{prefix}.prediction_horizon must be at most {MAX_PREDICTION_HORIZON}, "
                f"got {self.prediction_horizon}"
            )
        _positive_int(self.control_horizon, f"{prefix}.control_horizon")
        if self.control_horizon > self.prediction_horizon:
            raise ConfigError(
                f"{prefix}.control_horizon ({self.control_horizon}) must not exceed "
                f"{prefix}.prediction_horizon ({self.prediction_horizon})"
            )
        for name, n in (
            ("output_weights", 2),
            ("input_rate_weights", 1),
            ("input_weights", 1),
            ("input_scales", 1),
            ("output_scales", 2),
        ):
            values = getattr(self, name)
            _length(values, n, f"{prefix}.{name}")
            for i, v in enumerate(values):
                check = _positive if name.endswith("scales") else _non_negative
                check(v, f"{prefix}.{name}[{i}]")
        _bounds(self.input_bounds, f"{prefix}.input_bounds")
        _length(self.output_bounds, 2, f"{prefix}.output_bounds")
        for i, b in enumerate(self.output_bounds):
            if not isinstance(b, list):
                raise ConfigError(f"{prefix}.output_bounds[{i}] must be a list, got {b!r}")
            if b:
                _bounds(b, f"{prefix}.output_bounds[{i}]")
        _positive(self.ecr_weight, f"{prefix}.ecr_weight")
        _one_of(self.solver, SOLVERS, f"{prefix}.solver")
        _positive(self.disturbance_gain, f"{prefix}.disturbance_gain")


@dataclass
class MonteCarloConfig:
    """Runs over noise seeds and plant-parameter perturbations.

    Run ``i`` uses noise seed ``seed + i`` and multiplies each parameter named in ``parameters``
    by an independent factor drawn uniformly from ``[1 - perturbation, 1 + perturbation]``.
    """

    runs: int = 0
    perturbation: float = 0.1
    parameters: list[str] = field(default_factory=lambda: list(PERTURBABLE))

    def validate(self, prefix: str) -> None:
        if isinstance(self.runs, bool) or not isinstance(self.runs, int) or self.runs < 0:
            raise ConfigError(f"{prefix}.runs must be a non-negative integer, got {self.runs!r}")
        _non_negative(self.perturbation, f"{prefix}.perturbation")
        if self.perturbation >= 1:
            raise ConfigError(f"{prefix}.perturbation must be below 1, got {self.perturbation}")
        for i, name in enumerate(self.parameters):
            _one_of(name, PERTURBABLE, f"{prefix}.parameters[{i}]")


@dataclass
class CompareConfig:
    """Everything ``riprs compare`` runs; the defaults reproduce the paper's setting."""

    controllers: list[str] = field(default_factory=lambda: list(CONTROLLERS))
    plant: PlantConfig = field(default_factory=PlantConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    lqr: LqrConfig = field(default_factory=LqrConfig)
    lqg: LqgConfig = field(default_factory=LqgConfig)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    monte_carlo: MonteCarloConfig = field(default_factory=MonteCarloConfig)

    def validate(self) -> CompareConfig:
        """Check every value; return ``self`` so calls chain."""
        if not self.controllers:
            raise ConfigError("controllers must name at least one of LQR, LQG, MPC")
        for i, name in enumerate(self.controllers):
            _one_of(name, CONTROLLERS, f"controllers[{i}]")
        if len(set(self.controllers)) != len(self.controllers):
            raise ConfigError(f"controllers has duplicates: {self.controllers}")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if hasattr(value, "validate"):
                value.validate(f.name)
        return self

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CompareConfig:
        """Build from nested dicts (a parsed TOML document), rejecting unknown keys."""
        return _build(cls, data, "").validate()


def load_config(path: Union[str, os.PathLike[str]]) -> CompareConfig:
    """Read and validate a TOML configuration file.

    Raises
    ------
    ConfigError
        Unknown key, wrong type or out-of-range value (the message names it), or TOML syntax.
    OSError
        The file cannot be read.
    """
    with open(path, "rb") as fh:
        try:
            data = tomllib.load(fh)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{os.fspath(path)}: invalid TOML: {exc}") from None
    try:
        return CompareConfig.from_dict(data)
    except ConfigError as exc:
        raise ConfigError(f"{os.fspath(path)}: {exc}") from None


def _build(cls: type, data: Any, prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix or 'configuration'} must be a table, got {data!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        where = f"[{prefix}]" if prefix else "the top level"
        raise ConfigError(
            f"unknown key {_join(prefix, unknown[0])!r} in {where}; "
            f"valid keys: {', '.join(sorted(fields))}"
        )
    kwargs: dict[str, Any] = {}
    defaults = cls()
    for name, value in data.items():
        key = _join(prefix, name)
        default = getattr(defaults, name)
        if dataclasses.is_dataclass(default):
            kwargs[name] = _build(type(default), value, key)
        else:
            kwargs[name] = _coerce(value, default, key)
    return cls(**kwargs)


def _coerce(value: Any, default: Any, key: str) -> Any:
    """Check ``value`` against the type of ``default`` (ints widen to floats)."""
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise ConfigError(f"{key} must be true or false, got {value!r}")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key} must be an integer, got {value!r}")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key} must be a number, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise ConfigError(f"{key} must be a string, got {value!r}")
        return value
    if isinstance(default, list):
        if not isinstance(value, list):
            raise ConfigError(f"{key} must be an array, got {value!r}")
        sample = default[0] if default else None
        if isinstance(sample, list) or (default and any(isinstance(d, list) for d in default)):
            return [_coerce(v, [0.0], f"{key}[{i}]") for i, v in enumerate(value)]
        if isinstance(sample, str):
            return [_coerce(v, "", f"{key}[{i}]") for i, v in enumerate(value)]
        return [_coerce(v, 0.0, f"{key}[{i}]") for i, v in enumerate(value)]
    raise ConfigError(f"{key}: unsupported setting")  # pragma: no cover


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _finite(v: float, key: str) -> None:
    if not math.isfinite(v):
        raise ConfigError(f"{key} must be finite, got {v}")


def _positive(v: float, key: str) -> None:
    if not (math.isfinite(v) and v > 0):
        raise ConfigError(f"{key} must be positive and finite, got {v}")


def _non_negative(v: float, key: str) -> None:
    if not (math.isfinite(v) and v >= 0):
        raise ConfigError(f"{key} must be non-negative and finite, got {v}")


def _positive_int(v: int, key: str) -> None:
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ConfigError(f"{key} must be a positive integer, got {v!r}")


def _length(values: list[Any], n: int, key: str) -> None:
    if len(values) != n:
        raise ConfigError(f"{key} must have {n} entries, got {len(values)}")


def _bounds(b: list[float], key: str) -> None:
    _length(b, 2, key)
    lo, hi = b
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ConfigError(f"{key} must be [lower, upper], finite, with lower < upper, got {b}")


def _one_of(value: str, allowed: tuple[str, ...], key: str) -> None:
    if value not in allowed:
        raise ConfigError(f"{key} must be one of {', '.join(allowed)}; got {value!r}")

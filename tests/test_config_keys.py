"""Every key of the configuration reference reaches what it configures, and a bad value is an
error naming it.

For each key, a file changing only that key must change what the spec builds (the plant, the
controllers' outputs and gains, the simulation, the swing-up and Monte Carlo settings) against
the same file without the change: a key that is accepted and then ignored fails here.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import riprs
from riprs.config import load_config

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

# The value each key is changed to, and (after it) base lines the change needs in order to
# matter, e.g. the compensation keys need a dead zone to compensate. A key of the reference
# not listed here takes the generic change (`_changed`).
CHANGES: dict[str, tuple[str, str]] = {
    "controllers": ('["LQR"]', ""),
    "plant.preset": ('"qube_servo2"', ""),
    "plant.Cr": ("0.002", ""),
    "plant.Cp": ("1e-5", ""),
    "plant.Vd": ("0.2", ""),
    "plant.arm_breakaway": ("0.01", ""),
    "plant.initial_state": ("[0.1, 0.0, 0.05, 0.0]", ""),
    "plant.fall_limit": ("1.2", ""),
    "sensor.encoder_counts": ("[1024, 2048]", ""),
    "mpc.input_target": ("[0.5]", "[mpc]\ninput_weights = [0.5]\n"),
    "mpc.input_bounds": ("[[-10.0, 10.0]]", ""),
    "mpc.output_bounds": ("[[-inf, inf], [-0.4, 0.4]]", ""),
    "mpc.solver": ('"clarabel"', ""),
    "mpc.max_iterations": ("1", ""),
    "mpc.control_horizon": ("2", ""),
    "lqr.integral_weight": ("1.0", ""),
    "lqr.disturbance_bandwidth": ("5.0", "[plant]\nVd = 0.3\n"),
    "compensation.enabled": ("false", "[plant]\nVd = 0.3\n"),
    "compensation.voltage_scale": ("0.1", "[plant]\nVd = 0.3\n"),
    "compensation.velocity_scale": ("0.1", "[plant]\nCr = 0.002\n"),
    "compensation.dead_zone": ("0.2", "[plant]\nVd = 0.3\n"),
    "compensation.arm_friction": ("0.001", "[plant]\nCr = 0.002\n"),
    "compensation.dead_zone_gain": ("1.2", "[plant]\nVd = 0.3\n"),
    "compensation.friction_gain": ("1.5", "[plant]\nCr = 0.002\n"),
    "kalman.input_disturbance": ("0.1", ""),
    "monte_carlo.parameters": ('["mr"]', ""),
    "monte_carlo.runs": ("3", ""),
    "swing_up.on_fall": ('"stop"', ""),
    "swing_up.method": ('"trajectory"', ""),
    "swing_up.max_voltage": ("10.0", ""),
}

# Keys the resolved file leaves out when unset (optional values).
OPTIONAL = ["plant.arm_breakaway", "compensation.dead_zone", "compensation.arm_friction"]


def _reference_keys() -> list[str]:
    keys = []
    for section, value in tomllib.loads(riprs.Spec().to_toml()).items():
        if isinstance(value, dict):
            keys += [f"{section}.{k}" for k in value]
        else:
            keys.append(section)
    return keys + OPTIONAL


def _changed(key: str, value: Any) -> str:
    if isinstance(value, bool):
        return "false" if value else "true"
    if isinstance(value, int):
        return str(value + 1)
    if isinstance(value, float):
        return repr(value * 0.9 if value else 1e-3)
    if isinstance(value, list) and value and isinstance(value[0], float):
        first = value[0] * 0.8 if value[0] else 0.1
        return "[" + ", ".join(repr(v) for v in [first, *value[1:]]) + "]"
    raise AssertionError(f"no generic change for {key} = {value!r}; add it to CHANGES")


def _toml(key: str, value: str) -> str:
    if "." not in key:
        return f"{key} = {value}\n"
    section, name = key.split(".", 1)
    return f"[{section}]\n{name} = {value}\n"


def _merge(*parts: str) -> str:
    # Two snippets may open the same section: keep one header per section.
    tables: dict[str, list[str]] = {"": []}
    current = ""
    for part in parts:
        for line in part.splitlines():
            if line.startswith("["):
                current = line.strip("[]")
                tables.setdefault(current, [])
            elif line:
                tables[current].append(line)
    out = tables.pop("")
    for name, lines in tables.items():
        out += [f"[{name}]", *lines]
    return "\n".join(out) + "\n"


def _reach(spec: riprs.Spec) -> dict[str, Any]:
    """What a spec configures, as comparable values."""
    out: dict[str, Any] = {}
    for start in ("up", "down"):
        out[f"sim_{start}"] = {k: repr(v) for k, v in spec.simulation_options(start).items()}
    plant = spec.build_plant()
    out["plant"] = (plant.params.to_dict(), plant.arm_breakaway)
    controllers = spec.build_controllers()
    out["controllers"] = list(controllers)
    for name, c in controllers.items():
        moves = []
        for k in range(150):
            y = [0.4 * np.sin(0.05 * k), 0.05 * np.cos(0.2 * k)]
            moves.append(np.asarray(c.step(y, [1.0, 0.0])).tobytes())
        # Near rest, where the compensation's sign ramps act (small voltages and rates).
        for k in range(100):
            y = [1e-3 * np.sin(0.3 * k), 1e-4 * np.cos(0.1 * k)]
            moves.append(np.asarray(c.step(y, [0.0, 0.0])).tobytes())
        attrs = {
            a: repr(getattr(c, a))
            for a in ("K", "L", "M", "integral_gain", "rate_cutoff", "u_min", "u_max")
            if hasattr(c, a)
        }
        attrs["compensation"] = repr(c.compensation)
        if name == "MPC":
            attrs["horizons"] = (c.prediction_horizon, c.control_horizon, c.solver)
            x0 = np.array([0.1, 0.0, 0.05, 0.0, 0.0])
            attrs["qp"] = [m.tobytes() for m in c.qp_matrices(x0, [0.5])]
        out[name] = (moves, attrs)
    out["swing_up"] = dict(spec.swing_up)
    mc = spec.monte_carlo
    out["monte_carlo"] = (mc.runs, mc.perturbation, list(mc.parameters))
    return out


def _defaults() -> dict[str, Any]:
    d = tomllib.loads(riprs.Spec().to_toml())
    flat: dict[str, Any] = {}
    for section, value in d.items():
        if isinstance(value, dict):
            flat.update({f"{section}.{k}": v for k, v in value.items()})
        else:
            flat[section] = value
    return flat


KEYS = _reference_keys()


def test_every_reference_key_is_covered() -> None:
    text = (Path(__file__).parents[1] / "docs" / "configuration.md").read_text()
    for key in KEYS:
        name = key.split(".")[-1]
        assert f"{name} =" in text or key in OPTIONAL, key
    assert len(KEYS) > 70


@pytest.mark.parametrize("key", KEYS)
def test_a_key_changed_in_a_file_changes_what_it_reaches(key: str, tmp_path: Path) -> None:
    value, base = CHANGES.get(key) or (_changed(key, _defaults()[key]), "")
    before, after = tmp_path / "before.toml", tmp_path / "after.toml"
    before.write_text(_merge(base))
    after.write_text(_merge(base, _toml(key, value)))
    a, b = _reach(load_config(before)), _reach(load_config(after))
    changed = [part for part in a if a[part] != b.get(part)]
    assert changed, f"{key} = {value} changes nothing the spec builds"


@pytest.mark.parametrize("key", KEYS)
def test_a_bad_value_names_its_key(key: str, tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(_toml(key, '{ bad = "value" }'))
    with pytest.raises(riprs.ConfigError) as info:
        load_config(f)
    assert f"{f}: {key}" in str(info.value), str(info.value)


def _change(key: str, value: str) -> dict[str, Any]:
    v = tomllib.loads(f"v = {value}")["v"]
    if "." not in key:
        return {key: v}
    section, name = key.split(".", 1)
    return {section: {name: v}}


@pytest.mark.parametrize("key", KEYS)
def test_an_update_is_the_file_with_the_change_and_prints_back(key: str, tmp_path: Path) -> None:
    # Spec.updated merges Python values into a spec as the file would hold them, and the
    # printed result (to_toml) loads back to the same spec.
    value, base = CHANGES.get(key) or (_changed(key, _defaults()[key]), "")
    before, after = tmp_path / "before.toml", tmp_path / "after.toml"
    before.write_text(_merge(base))
    after.write_text(_merge(base, _toml(key, value)))
    updated = load_config(before).updated(_change(key, value))
    assert updated == load_config(after), key
    printed = tmp_path / "printed.toml"
    printed.write_text(updated.to_toml())
    assert load_config(printed) == updated, key


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"mpc": {"horizon": 3}}, "mpc.horizon"),
        ({"mpc": {"prediction_horizon": "x"}}, "mpc.prediction_horizon"),
        ({"sensor": {"noise_std": [1e-3, object()]}}, "sensor.noise_std[1]"),
        ({"sensor": {"encoder_counts": [2048, 2**70]}}, "sensor.encoder_counts[1]"),
        ({"swing_up": {"max_voltage": True}}, "swing_up.max_voltage"),
        ({"lqr": {"Q": [1.0, 2.0, -3.0, 4.0]}}, "lqr.Q[2]"),
        ({"nonsense": {"a": 1}}, "nonsense"),
        ({"device": {"arm_counts_per_rev": 1024}}, "device.arm_counts_per_rev"),
    ],
)
def test_a_bad_update_names_its_key(change: dict[str, Any], key: str) -> None:
    spec = riprs.Spec()
    with pytest.raises(riprs.ConfigError) as info:
        spec.updated(change)
    assert str(info.value).startswith(f"{key}:"), str(info.value)
    assert spec == riprs.Spec()


def test_a_key_that_moved_names_its_new_key(tmp_path: Path) -> None:
    f = tmp_path / "old.toml"
    for n, key in enumerate(("arm_counts_per_rev", "pendulum_counts_per_rev")):
        f.write_text(f"[device]\n{key} = 1024\n")
        with pytest.raises(riprs.ConfigError) as info:
            load_config(f)
        assert str(info.value) == (
            f"{f}: device.{key}: moved to sensor.encoder_counts[{n}]: set it there"
        )


def test_an_update_is_checked_against_the_files_rig_sections(tmp_path: Path) -> None:
    # The file's own [safety] arm_limit bounds the arm step of every later update: the
    # relation is checked on the updated spec, as a file holding both would be.
    f = tmp_path / "rig.toml"
    f.write_text("[safety]\narm_limit = 1.2\n")
    spec = load_config(f)
    assert spec.updated({"reference": {"arm_step": 1.1}}) != spec
    with pytest.raises(riprs.ConfigError) as info:
        spec.updated({"reference": {"arm_step": 1.25}})
    assert str(info.value).startswith("reference.arm_step:"), str(info.value)
    assert "1.2" in str(info.value)
    assert spec == load_config(f)

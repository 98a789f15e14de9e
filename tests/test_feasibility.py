"""Swing-up feasibility: the trajectory optimisation's "not found" and its argument checks."""

from __future__ import annotations

import math

import numpy as np
import pytest

import riprs
from riprs.swingup import find_swing_up


def test_too_little_voltage_is_not_found_and_the_result_is_a_true_rollout() -> None:
    # 0.05 V on the paper preset: rip-core's energy balance proves it impossible
    # (rip-rt refuses it, crates/rip-rt/src/config.rs); the optimiser must not claim a find.
    params = riprs.FurutaParams.paper()
    r = find_swing_up(params, max_voltage=0.05, horizon=2.0, intervals=16, max_iter=20)
    assert not r.found
    assert r.x.shape == (17, 4) and r.u.shape == (16,) and r.t[-1] == pytest.approx(2.0)
    assert np.all(np.abs(r.u) <= 0.05)
    # The states reported are a rollout of the voltages reported, from hanging at rest.
    plant = riprs.Plant(params)
    roll = plant.integrate([0.0, 0.0, math.pi, 0.0], r.u, 2.0 / 16, 4)
    assert np.allclose(roll, r.x, atol=1e-9)
    assert abs(r.x[-1, 2] - math.pi) < 0.6  # still near hanging, nowhere near upright


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"max_voltage": 0.0}, "max_voltage"),
        ({"arm_limit": math.nan}, "arm_limit"),
        ({"horizon": -1.0}, "horizon"),
        ({"intervals": 1}, "intervals"),
    ],
)
def test_bad_arguments_are_named(kwargs: dict[str, float], name: str) -> None:
    with pytest.raises(ValueError, match=name):
        find_swing_up(riprs.FurutaParams.paper(), **kwargs)  # type: ignore[arg-type]


def test_riprs_tune_stores_the_verdict_that_rip_rt_then_reads(tmp_path) -> None:
    """The tuning record's ``[swing_up]`` table: its friction loss against the closed form
    ``L = 8 d_p sqrt(G/J_alpha) + 2 pi C_p`` from the file's parameters, and ``rip-rt run
    --swing-up`` on the tuned file taking the stored verdict instead of computing it."""
    import subprocess

    import tomllib

    from riprs._binaries import find_rip_rt
    from riprs.tune import tune

    rig = tmp_path / "rig.toml"
    rig.write_text('[plant]\npreset = "qube_servo2"\nDp = 2e-5\nCp = 1e-5\n')
    out = tmp_path / "tuned.toml"
    side = tune(rig, runs=0, progress=False, swing_up=False).write(out)
    stored = tomllib.loads(side.read_text())["swing_up"]
    assert stored["verdict"] == "not_excluded"
    assert stored["inputs"].startswith("fnv1a64:")
    p = riprs.Spec.from_toml(out.read_text()).plant.params
    ja = p.Jp + p.mp * p.Lp**2 / 4.0
    grav = p.mp * p.g * p.Lp / 2.0
    assert stored["gravity"] == pytest.approx(grav, rel=1e-12)
    loss = 8.0 * p.Dp * math.sqrt(grav / ja) + 2.0 * math.pi * p.Cp
    assert stored["loss"] == pytest.approx(loss, rel=1e-9)
    assert stored["gain"] > loss
    binary = find_rip_rt()
    if binary is None:
        pytest.skip("no rip-rt binary built")
    args = ["run", "--port", str(tmp_path / "none"), "--swing-up", "--controller", "lqr"]
    r = subprocess.run(
        [str(binary), *args, "--config", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode != 0  # no such port
    assert f"stored by riprs tune in {side}" in r.stderr, r.stderr

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

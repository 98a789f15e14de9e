"""The seeded rig generator: reproducible, inside the envelope of shared/DESIGN.md, and a
configuration that the spec reader takes back unchanged."""

from __future__ import annotations

import numpy as np
import pytest

import riprs

# The envelope as DESIGN.md states it ("Any rig, safely"), written here independently of the
# generator's own constants.
ENVELOPE = {
    "mp": (0.015, 0.08),
    "Lp": (0.08, 0.30),
    "Lr": (0.06, 0.15),
    "mr": (0.05, 0.15),
    "Rm": (2.0, 10.0),
    "kt": (0.02, 0.08),
    "Dr": (2e-4, 3e-3),
    "Dp": (1e-5, 2e-4),
    "Vd": (0.0, 1.0),
    "Cr": (0.0, 0.006),
    "Cp": (0.0, 5e-5),
}


def test_the_same_seed_draws_the_same_rig() -> None:
    assert riprs.random_rig(11) == riprs.random_rig(11)
    assert riprs.random_rig(11).params != riprs.random_rig(12).params


def test_rigs_lie_inside_the_envelope() -> None:
    for seed in range(300):
        rig = riprs.random_rig(seed)
        p = rig.params.to_dict()
        for name, (lo, hi) in ENVELOPE.items():
            assert lo <= p[name] <= hi, (seed, name, p[name])
        assert p["km"] == p["kt"]
        assert 0.5 <= p["Jr"] / (p["mr"] * p["Lr"] ** 2 / 12) <= 1.5
        assert 0.5 <= p["Jp"] / (p["mp"] * p["Lp"] ** 2 / 12) <= 1.5
        assert all(512 <= c <= 8192 for c in rig.encoder_counts)
        assert all(0.0 <= s <= 2e-3 for s in rig.noise_std)
        counts = np.array(rig.encoder_counts)
        assert rig.noise_counts() == pytest.approx(
            max(np.array(rig.noise_std) * counts / (2 * np.pi))
        )


def test_the_configuration_reads_back_as_the_rig() -> None:
    rig = riprs.random_rig(5)
    for spec in (riprs.Spec.from_toml(rig.to_toml()), riprs.Spec.from_dict(rig.to_config())):
        plant = spec.plant
        for name, value in rig.params.to_dict().items():
            if name != "g":
                assert getattr(plant, name) == value, name
        assert tuple(spec.sensor.encoder_counts) == rig.encoder_counts
        assert spec.build_plant().params == rig.params


def test_a_bad_seed_names_the_argument() -> None:
    with pytest.raises(riprs.InvalidParameterError, match="seed"):
        riprs.random_rig(-1)
    with pytest.raises(TypeError):
        riprs.random_rig(1.5)  # type: ignore[arg-type]

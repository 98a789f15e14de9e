"""The identified covariance (``[plant_covariance]``) as a perturbation source: ``riprs tune``'s
robustness check draws from it when the rig has one (else +-10 % per parameter), and a
``riprs campaign`` axis draws rigs from it. Checked against numpy's own statistics of the draws
and against the parameters the campaign's runs were given."""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pytest

import riprs
from riprs._riprs import tune_robustness
from riprs.campaign import CampaignError, chunk, load_spec
from riprs.identify import IdentifyError, read_plant_covariance

tune_module = importlib.import_module("riprs.tune")

QUBE = riprs.FurutaParams.qube_servo2()
#: A covariance of Dp and kt (SI units) with a correlation of 0.5.
NAMES = ["Dp", "kt"]
SD = np.array([0.2 * QUBE.Dp, 0.05 * QUBE.kt])
MATRIX = np.outer(SD, SD) * np.array([[1.0, 0.5], [0.5, 1.0]])


def _rig(tmp_path: Path, matrix: np.ndarray = MATRIX, names=NAMES) -> Path:
    """A rig file and the identification file ``riprs identify`` writes beside it."""
    rig = tmp_path / "rig.toml"
    rig.write_text('[plant]\npreset = "qube_servo2"\n')
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in matrix)
    (tmp_path / "rig.identification.toml").write_text(
        "[identification]\ntrusted = true\n\n[plant_covariance]\n"
        f"parameters = [{', '.join(repr(n).replace(chr(39), chr(34)) for n in names)}]\n"
        f"matrix = [{rows}]\nnot_determined = []\n"
    )
    return rig


def test_the_one_reader_finds_the_table_beside_the_rig_and_names_a_bad_one(tmp_path) -> None:
    rig = _rig(tmp_path)
    names, matrix = read_plant_covariance(rig)
    assert names == NAMES
    np.testing.assert_array_equal(matrix, MATRIX)
    (tmp_path / "short").mkdir()
    bad = _rig(tmp_path / "short", MATRIX[:1])
    with pytest.raises(IdentifyError, match=r"rig\.identification\.toml.*2 x 2"):
        read_plant_covariance(bad)
    plain = tmp_path / "plain.toml"
    plain.write_text('[plant]\npreset = "paper"\n')
    assert read_plant_covariance(plain) is None


def test_tune_draws_its_robustness_runs_from_the_identified_covariance(tmp_path) -> None:
    rig = _rig(tmp_path)
    spec = riprs.load_config(rig)
    names, log_cov = tune_module._covariance(rig, spec)
    # First order: the covariance of log p is C / (p p^T) at the file's values.
    values = np.array([QUBE.Dp, QUBE.kt])
    np.testing.assert_allclose(log_cov, MATRIX / np.outer(values, values), rtol=1e-12)
    assert names == NAMES
    got = tune_module.tune(rig, runs=2, progress=False, swing_up=False)
    assert got.perturbation == "identification covariance"
    alone = tmp_path / "alone"
    alone.mkdir()
    (alone / "rig.toml").write_text('[plant]\npreset = "qube_servo2"\n')
    alone_tuned = tune_module.tune(alone / "rig.toml", runs=2, progress=False, swing_up=False)
    assert alone_tuned.perturbation == "+-10% per parameter"


def test_tune_robustness_follows_the_covariance_it_is_given(tmp_path) -> None:
    """A covariance that makes the motor five times weaker or stronger (sd of log kt = 1)
    costs the fixed design runs that a tight one (0.1 %) does not."""
    spec = riprs.load_config(_rig(tmp_path))
    tight = tune_robustness(
        spec, 10, 0, 0.01, 0.1, ["kt"], np.array([[1e-6]])
    )
    wide = tune_robustness(spec, 10, 0, 0.01, 0.1, ["kt"], np.array([[1.0]]))
    assert all(frac == 1.0 for _, frac in tight), tight
    assert any(frac < 1.0 for _, frac in wide), wide


def _campaign(file: str, samples: int = 3, **extra) -> dict:
    return {
        "plant": {"preset": "qube_servo2"},
        "campaign": {
            "controllers": ["LQR"],
            "seeds": 1,
            "duration": 0.5,
            "axis": [{"name": "plant_covariance", "file": file, "samples": samples, **extra}],
        },
    }


def test_a_campaign_axis_draws_rigs_with_the_identified_covariance(tmp_path) -> None:
    rig = _rig(tmp_path)
    campaign = load_spec(_campaign(str(rig), samples=4000))
    (axis,) = campaign.axes
    assert axis.draw_names == tuple(NAMES) and axis.draws is not None
    assert axis.draws.shape == (4000, 2)
    np.testing.assert_allclose(axis.draws.mean(axis=0), [QUBE.Dp, QUBE.kt], rtol=0.02)
    np.testing.assert_allclose(np.cov(axis.draws.T), MATRIX, rtol=0.08)
    # The same spec draws the same rigs.
    again = load_spec(_campaign(str(rig), samples=4000))
    np.testing.assert_array_equal(again.axes[0].draws, axis.draws)


def test_the_campaign_runs_are_given_the_drawn_rigs(tmp_path, monkeypatch) -> None:
    rig = _rig(tmp_path)
    campaign = load_spec(_campaign(str(rig), samples=3))
    seen = []
    real = chunk._segment_metrics

    def spy(params, *args, **kwargs):
        seen.append((params.Dp, params.kt, params.mp))
        return real(params, *args, **kwargs)

    monkeypatch.setattr(chunk, "_segment_metrics", spy)
    table = chunk.compute_chunk(campaign, 0, campaign.runs)
    assert list(table["plant_covariance"]) == [0.0, 1.0, 2.0]
    draws = campaign.axes[0].draws
    assert draws is not None
    np.testing.assert_array_equal(np.array(seen)[:, :2], draws)
    assert all(mp == QUBE.mp for _, _, mp in seen)


def test_a_bad_covariance_axis_is_named(tmp_path) -> None:
    rig = _rig(tmp_path)
    with pytest.raises(CampaignError, match=r"campaign\.axis\[0\]\.file: .* does not exist"):
        load_spec(_campaign(str(tmp_path / "nope.toml")))
    plain = tmp_path / "plain.toml"
    plain.write_text('[plant]\npreset = "paper"\n')
    with pytest.raises(CampaignError, match="holds no \\[plant_covariance\\]"):
        load_spec(_campaign(str(plain)))
    with pytest.raises(CampaignError, match=r"campaign\.axis\[0\]\.scale"):
        load_spec(_campaign(str(rig), scale=[0.9, 1.1]))
    with pytest.raises(CampaignError, match="needs samples"):
        spec = _campaign(str(rig))
        del spec["campaign"]["axis"][0]["samples"]
        load_spec(spec)
    both = _campaign(str(rig))
    both["campaign"]["axis"].append({"name": "Dp", "scale": [0.9, 1.1], "points": 2})
    with pytest.raises(CampaignError, match="overlaps"):
        load_spec(both)
    with pytest.raises(CampaignError, match="file goes with"):
        load_spec(
            {"campaign": {"axis": [{"name": "mp", "scale": [1, 2], "points": 2, "file": "x"}]}}
        )

"""The swing-up's Monte Carlo from Python and the swing-up search of ``riprs tune``.

The interval is checked against the Wilson score formula written out here; the search's
file and record are read back as ``rip-rt run --swing-up`` reads them.
"""

from __future__ import annotations

import math

import pytest
import tomllib

import riprs

QUBE = '[plant]\npreset = "qube_servo2"\n'


def _wilson(k: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def test_the_study_counts_and_its_interval_is_wilsons() -> None:
    study = riprs.swing_up_monte_carlo(riprs.Spec.from_toml(QUBE), "lqr", runs=40, seed=7)
    assert isinstance(study, riprs.SwingUpStudy)
    assert study.controller == "LQR" and study.runs == 40 and study.excluded == 0
    assert study.held <= study.caught <= study.runs
    assert study.step_tracked <= study.held and study.caught_on_first <= study.caught
    assert study.at_most_two_over_tops <= study.runs
    lo, hi = _wilson(study.held, study.judged)
    assert study.interval == pytest.approx((lo, hi), abs=1e-12)
    assert study.success_rate == study.held / study.judged
    # The same draws again: the study is reproducible from its seed.
    again = riprs.swing_up_monte_carlo(riprs.Spec.from_toml(QUBE), "LQR", runs=40, seed=7)
    assert again == study


def test_a_rig_that_cannot_swing_up_is_excluded_not_failed() -> None:
    spec = riprs.Spec.from_toml(QUBE + "[swing_up]\nmax_voltage = 0.05\n")
    study = riprs.swing_up_monte_carlo(spec, "MPC", runs=6)
    assert (study.excluded, study.judged, study.held) == (6, 0, 0)
    assert all(math.isnan(v) for v in study.interval)
    assert math.isnan(study.success_rate)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"runs": 0}, "runs"),
        ({"runs": -3}, "runs"),
        ({"runs": 2.5}, "runs"),
        ({"runs": True}, "runs"),
        ({"seed": -1}, "seed"),
        ({"seed": 2**64}, "seed"),
        ({"spread": 1.0}, "spread"),
        ({"spread": float("nan")}, "spread"),
    ],
)
def test_bad_arguments_are_refused_by_name(kwargs: dict, name: str) -> None:
    with pytest.raises(riprs.ConfigError, match=name):
        riprs.swing_up_monte_carlo(riprs.Spec.from_toml(QUBE), "LQR", **kwargs)


def test_an_unknown_controller_is_refused() -> None:
    with pytest.raises(riprs.ConfigError, match="controller"):
        riprs.swing_up_monte_carlo(riprs.Spec.from_toml(QUBE), "PID")


def test_riprs_tune_writes_the_searched_swing_up_and_its_verdict(tmp_path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(QUBE)
    out = tmp_path / "tuned.toml"
    result = riprs.tune(rig, runs=0, progress=False)
    side = result.write(out)
    assert result.swing_up is not None and result.swing_up.verdict == "found"
    assert "swing-up: found" in result.report()
    tuned = tomllib.loads(out.read_text())
    record = tomllib.loads(side.read_text())
    search = record["swing_up_search"]
    assert search["verdict"] == "found"
    # What the record judged is what the file holds: the settings searched.
    for key, value in result.swing_up.settings.items():
        assert tuned["swing_up"][key] == pytest.approx(value), key
    assert tuned["swing_up"]["catch_prediction"] > 0
    assert tuned["swing_up"].get("method", "energy") == result.swing_up.method
    # The plan, kept by the search: its margins and rises in the record as in the result.
    assert search["method"] == result.swing_up.method == "trajectory"
    plan = result.swing_up.plan
    assert plan is not None and search["plan"] == pytest.approx(plan)
    assert plan["rises"] == 1 and plan["arm_left"] > 0 and plan["voltage_left"] > 0
    assert "1 rise(s) into the upper half" in result.report()
    for s in result.swing_up.confirmed:
        assert s.judged == 1000
        assert s.interval[0] >= 0.95, s
        assert search["confirmed"][s.controller]["held"] == s.held
    # Read back, the tuned file is the design the record's checksum is of.
    again = riprs.load_config(out)
    assert again.swing_up["catch_margin"] == pytest.approx(result.swing_up.settings["catch_margin"])

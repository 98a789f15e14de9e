"""`riprs compare` end to end: outputs exist and parse, RMSE recomputed independently, configs."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from riprs.cli import main
from riprs.compare import compare
from riprs.config import ConfigError, Spec, load_config

SHORT = """
[reference]
duration = 3.0
step_time = 0.5
"""

FIGURES = ("arm_angle", "pendulum_angle", "control_voltage")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "config.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def cli_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("compare")
    cfg = _write(tmp, SHORT)
    out = tmp / "out"
    code = main(["compare", "--config", str(cfg), "--out", str(out), "--seed", "3", "--quiet"])
    return code, out


def test_cli_writes_every_output(cli_run):
    code, out = cli_run
    assert code == 0
    for stem in FIGURES:
        for ext in ("png", "svg"):
            path = out / f"{stem}.{ext}"
            assert path.stat().st_size > 1000, path
    assert (out / "arm_angle.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (out / "arm_angle.svg").read_bytes()[:2000]


def _read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def test_summary_rmse_equals_numpy_recomputation(cli_run):
    _, out = cli_run
    summary = {row["controller"]: row for row in _read_csv(out / "summary.csv")}
    assert set(summary) == {"LQR", "LQG", "MPC"}
    rows = _read_csv(out / "trajectories.csv")
    assert len(rows) == 300  # 3 s at Ts = 0.01
    t = np.array([float(r["time"]) for r in rows])
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-12)
    for name, row in summary.items():
        key = name.lower()
        cols = {
            q: np.array([float(r[f"{key}_{q}"]) for r in rows if r[f"{key}_{q}"] != ""])
            for q in ("arm", "pendulum", "voltage", "reference")
        }
        expected = (
            math.sqrt(np.mean((cols["reference"] - cols["arm"]) ** 2)),
            math.sqrt(np.mean(cols["pendulum"] ** 2)),
            math.sqrt(np.mean(cols["voltage"] ** 2)),
        )
        got = (float(row["rmse_arm"]), float(row["rmse_pendulum"]), float(row["rmse_voltage"]))
        np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_reference_steps_as_configured(cli_run):
    _, out = cli_run
    rows = _read_csv(out / "trajectories.csv")
    ref = np.array([float(r["lqr_reference"]) for r in rows])
    t = np.array([float(r["time"]) for r in rows])
    assert np.all(ref[t < 0.5 - 1e-9] == 0.0) and np.all(ref[t >= 0.5 + 1e-9] == 1.0)


def test_default_run_balances_and_tracks():
    result = compare(seed=0, progress=False)
    for name, run in result.runs.items():
        assert not run.fell, name
        assert len(run.t) == 1000
        assert abs(run.x[-1, 0] - 1.0) < 0.1, name  # the arm reached the 1 rad step
        assert np.abs(run.x[:, 2]).max() < 0.3, name
        assert np.abs(run.u).max() <= 12.0 + 1e-12
    table = result.table()
    for name in ("LQR", "LQG", "MPC"):
        assert name in table


def test_seed_determinism():
    cfg = Spec.from_dict({"reference": {"duration": 1.0}})
    a = compare(cfg, seed=5, progress=False).summary
    b = compare(cfg, seed=5, progress=False).summary
    c = compare(cfg, seed=6, progress=False).summary
    assert a == b
    assert a != c


def test_monte_carlo_small(tmp_path):
    cfg = _write(tmp_path, SHORT + "\n[monte_carlo]\nperturbation = 0.05\n")
    out = tmp_path / "mc"
    code = main(
        ["compare", "--config", str(cfg), "--out", str(out), "--monte-carlo", "4", "--quiet"]
    )
    assert code == 0
    rows = _read_csv(out / "monte_carlo.csv")
    assert len(rows) == 3 * 4
    assert {r["controller"] for r in rows} == {"LQR", "LQG", "MPC"}
    for r in rows:
        assert r["fell"] in ("0", "1")
        if r["fell"] == "0":
            assert 0 < float(r["rmse_arm"]) < 1
    assert (out / "monte_carlo.png").stat().st_size > 1000


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[mpc]\nprediction_horizn = 10\n", "mpc.prediction_horizn"),
        ("[plant]\npreset = 'pendulum9000'\n", "plant.preset"),
        ("[mpc]\ncontrol_horizon = 80\n", "mpc.control_horizon"),
        ("[sensor]\nnoise_std = [0.001, -1.0]\n", "sensor.noise_std[1]"),
        ("[reference]\nduration = 'long'\n", "reference.duration"),
        ("[mpc]\noutput_bounds = [[-inf, inf], [0.5, -0.5]]\n", "mpc.output_bounds[1]"),
        ("controllers = ['LQR', 'PID']\n", "controllers[1]"),
        ("[reference\n", "invalid TOML"),
        ("[plant]\ninitial_state = [0.0, 0.0, nan, 0.0]\n", "plant.initial_state[2]"),
        ("[mpc]\ninput_bounds = [[-inf, inf]]\n", "mpc.input_bounds[0]"),
        ("[reference]\nduration = 0.001\n", "reference.duration"),
        ("[reference]\nduration = 1e6\n", "reference.duration"),
        ("[mpc]\nprediction_horizon = 100000\n", "mpc.prediction_horizon"),
        ("[mpc]\necr_weight = 0.0\n", "mpc.ecr_weight"),
        ("[kalman]\ndisturbance_gain = -0.01\n", "kalman.disturbance_gain"),
        ("[lqr]\nrate_cutoff = 0.0\n", "lqr.rate_cutoff"),
        ("[lqg]\nrate_cutoff = 10.0\n", "lqg"),
        # Values valid alone that fail in a design, and bounds of the simulation: all named
        # by their key before any run.
        ("[lqr]\nQ = [0, 0, 0, 0]\n", "lqr.Q"),
        ("[lqr]\nR = 1e308\n", "lqr.R"),
        ("[plant]\nsubsteps = 100001\n", "plant.substeps"),
        ("[plant]\ninitial_state = [0.0, 0.0, 2.0, 0.0]\n", "plant.initial_state[2]"),
        ("[mpc]\noutput_weights = [1e308, 1e308]\n", "mpc.output_weights"),
        ("[plant]\nJp = 0.0\n", "plant.Jp"),
        ("[sensor]\nencoder_counts = [0.5, 2048]\n", "sensor.encoder_counts[0]"),
        ("[reference]\narm_step = 1e300\n", "reference.arm_step"),
    ],
)
def test_bad_config_fails_clearly(tmp_path, capsys, text, needle):
    cfg = _write(tmp_path, text)
    with pytest.raises(ConfigError, match=__import__("re").escape(needle)):
        load_config(cfg)
    code = main(["compare", "--config", str(cfg), "--out", str(tmp_path / "o"), "--quiet"])
    assert code == 1
    assert needle in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # nothing written on a bad config


def test_errors_name_the_file_and_the_key(tmp_path, capsys):
    cfg = _write(tmp_path, "[mpc]\nprediction_horizon = 0\n")
    with pytest.raises(ConfigError) as info:
        load_config(cfg)
    assert str(info.value) == f"{cfg}: mpc.prediction_horizon: must be in 1..=10000, got 0"


def test_a_design_failure_is_found_before_any_simulation(tmp_path, monkeypatch, capsys):
    import riprs.compare as compare_module

    def refuse(*_args, **_kwargs):
        raise AssertionError("a simulation ran on a file whose designs fail")

    monkeypatch.setattr(compare_module, "simulate", refuse)
    cfg = _write(tmp_path, "[lqr]\nR = 1e308\n")
    code = main(["compare", "--config", str(cfg), "--out", str(tmp_path / "o"), "--quiet"])
    assert code == 1
    err = capsys.readouterr().err
    assert "lqr.R" in err and str(cfg) in err and "Traceback" not in err


def test_undecodable_config_is_a_config_error(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'[plant]\npreset = "\xff"\n')
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_config(path)


def test_a_bad_log_fails_before_the_runs(tmp_path, capsys):
    not_a_log = _write(tmp_path, "controller,rmse_arm\nLQR,0.1\n")
    out = tmp_path / "o"
    code = main(["compare", "--log", str(not_a_log), "--out", str(out), "--quiet"])
    assert code == 1
    err = capsys.readouterr().err
    assert "not a rip-rt log" in err and "Traceback" not in err
    assert not out.exists()


def test_compare_leaves_the_callers_config_alone():
    cfg = Spec.from_dict({"reference": {"duration": 0.5}})
    compare(cfg, monte_carlo=2, progress=False)
    assert cfg.monte_carlo.runs == 0
    assert cfg == Spec.from_dict({"reference": {"duration": 0.5}})


def test_lqr_rate_cutoff_reaches_the_controller():
    # A plain difference (no filter) passes the quantisation noise to the voltage.
    base = {"reference": {"duration": 3.0}, "controllers": ["LQR"]}
    filtered = compare(Spec.from_dict(base), progress=False).summary["LQR"]
    raw = compare(
        Spec.from_dict({**base, "lqr": {"rate_cutoff": float("inf")}}), progress=False
    ).summary["LQR"]
    assert raw[2] > 1.15 * filtered[2]

"""One experiment file for riprs and rip-rt: the same resolved sections, the same errors."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
import tomllib

import riprs
from riprs.cli import main, reference

ROOT = Path(__file__).resolve().parents[1]

RIG = """
controllers = ["MPC", "LQR"]
[plant]
preset = "qube_servo2"
Lp = 0.13
[lqr]
R = 0.2
[kalman]
disturbance_gain = 0.02
[mpc]
prediction_horizon = 30
solver = "clarabel"
[loop]
period_ms = 10
[safety]
voltage_limit = 10
"""


def _riprs_config(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["config", *args])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_both_tools_print_the_same_experiment_sections(tmp_path, capsys, rip_rt):
    path = tmp_path / "rig.toml"
    path.write_text(RIG)
    code, ours, _ = _riprs_config(capsys, str(path))
    assert code == 0
    rt = subprocess.run([str(rip_rt), "config", str(path)], capture_output=True, text=True)
    assert rt.returncode == 0, rt.stderr
    # Both print the experiment sections first, the same text; then rip-rt prints its own
    # sections resolved, riprs the ones the file sets, as it sets them (so that what riprs
    # prints or writes is still the rig).
    experiment = ours.split("\n[loop]")[0].split("\n[safety]")[0]
    assert rt.stdout.startswith(experiment)
    rest = rt.stdout[len(experiment) :]
    assert "[loop]" in rest and "[device]" in rest and "[safety]" in rest
    doc, rt_doc = tomllib.loads(ours), tomllib.loads(rt.stdout)
    assert doc["loop"] == {"period_ms": 10} and doc["safety"] == {"voltage_limit": 10}
    assert "device" not in doc
    for section in ("loop", "safety"):
        for key, value in doc[section].items():
            assert rt_doc[section][key] == value, (section, key)
    # Resolved: every default is there, and the given values.
    for needle in ('preset = "qube_servo2"', "Lp = 0.13", "Rm = 8.4", "R = 0.2", "ecr_weight"):
        assert needle in ours, needle
    # And it reads back to the same spec.
    assert riprs.Spec.from_toml(ours) == riprs.load_config(path)


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[mpc]\nprediction_horizn = 10\n", "mpc.prediction_horizn"),
        ("[mpc]\nprediction_horizon = 0\n", "mpc.prediction_horizon"),
        ("[plant]\npreset = 'qube'\n", "plant.preset"),
        ("[sensor]\nnoise_std = [0.001, -1.0]\n", "sensor.noise_std[1]"),
        ("[lqr]\nR = 1e308\n", "lqr.R"),
        ("[plant]\nsubsteps = 100001\n", "plant.substeps"),
        # rip-rt's sections are part of the one schema: riprs checks them too.
        ("loop = 3\n", "loop"),
        ("[device]\narm_sign = 0\n", "device.arm_sign"),
        ("[loop]\nperiod_ms = 'x'\n", "loop.period_ms"),
        ("[loop]\nperiod_ms = 1e308\n", "loop.period_ms"),
        ("[calibration]\nrest_window_s = 0.01\n", "calibration.rest_window_s"),
        # A file that sets the swing-up keeps it inside the safety limits, as the run needs.
        ("[swing_up]\nbalance_angle = 0.7\n", "swing_up.balance_angle"),
        ("[swing_up]\nmax_voltage = 13\n", "swing_up.max_voltage"),
        ("[swing_up]\narm_limit = 3.1\n", "swing_up.arm_limit"),
        ("[sefety]\n", "sefety"),
        # A default that follows from, or is checked against, a written key: the error names
        # the written key, never the default.
        ("[sensor]\nencoder_counts = [64, 64]\n", "sensor.encoder_counts[0]"),
        ("[plant]\nCr = 0.5\n", "plant.Cr"),
        ("[safety]\narm_limit = 0.8\n", "safety.arm_limit"),
        ("[safety]\narm_limit = 1.2\n[swing_up]\nmax_voltage = 6.0\n", "safety.arm_limit"),
        ("[mpc]\nprediction_horizon = 2\n", "mpc.prediction_horizon"),
    ],
)
def test_both_tools_give_the_same_message(tmp_path, capsys, rip_rt, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    code, _, err = _riprs_config(capsys, str(path))
    assert code == 1
    rt = subprocess.run([str(rip_rt), "config", str(path)], capture_output=True, text=True)
    assert rt.returncode != 0
    ours = err.strip().removeprefix("riprs: error: ")
    theirs = rt.stderr.strip().removeprefix("rip-rt: error: ")
    assert ours == theirs
    assert ours.startswith(f"{path}: {key}:"), ours


@pytest.mark.parametrize(
    "text",
    [
        "[calibration]\nrest_window_s = 5.0\n",
        "[safety]\npendulum_limit = 0.1\n",
        "[loop]\nperiod_ms = 2.0\n",
        "[sensor]\nencoder_counts = [128, 128]\n",
    ],
)
def test_a_key_written_alone_takes_the_defaults_that_follow_from_it(tmp_path, capsys, text):
    path = tmp_path / "ok.toml"
    path.write_text(text)
    code, _, err = _riprs_config(capsys, str(path))
    assert code == 0, err


def test_configuration_reference_is_generated_from_the_spec():
    # docs/configuration.md is `riprs config --reference`; regenerate it after changing the
    # spec.
    assert (ROOT / "docs" / "configuration.md").read_text() == reference()


def test_an_unknown_section_lists_the_rig_sections_too(tmp_path, capsys):
    path = tmp_path / "typo.toml"
    path.write_text("[sefety]\nvoltage_limit = 5\n")
    code, _, err = _riprs_config(capsys, str(path))
    assert code == 1
    for name in ("plant", "swing_up", "loop", "device", "safety", "calibration"):
        assert f"`{name}`" in err, err

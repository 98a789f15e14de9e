"""The pre-flight check (``rip_core::preflight``) through ``riprs.tune.preflight``.

``crates/rip-rt/tests/preflight.rs`` checks that ``rip-rt run`` refuses (exit 16) and that
``--force`` goes past it."""

from __future__ import annotations

import re

import riprs
from riprs.tune import preflight

WEAK = """[plant]
preset = "qube_servo2"
mp = 0.08
Lp = 0.3
Rm = 20.0
kt = 0.008
km = 0.008
initial_state = [0.0, 0.0, 0.1, 0.0]
"""


def _verdicts(findings):
    return {f.check: f for f in findings}


def test_a_rig_no_controller_can_balance_is_refused_with_the_voltage_it_needs(tmp_path) -> None:
    rig = tmp_path / "weak.toml"
    rig.write_text(WEAK)
    found = _verdicts(preflight(rig, "LQR"))
    assert found["voltage"].verdict == "refuse"
    need = float(re.search(r"would need at least ([0-9.]+) V", found["voltage"].message)[1])
    assert need > 12.0
    # Independently: LQRs of any weights fall on the rig's model at 12 V.
    spec = riprs.load_config(rig)
    plant = spec.build_plant()
    for R in (0.01, 0.1, 1.0, 10.0):
        lqr = spec.updated({"lqr": {"R": R}}).build_controllers(riprs.paper.TS)["LQR"]
        res = riprs.simulate(plant, lqr, 3.0, x0=[0.0, 0.0, 0.1, 0.0])
        assert res.fell, R
    # With the voltage it would need (and a margin) the voltage check passes.
    bound = need * 1.2
    roomy = tmp_path / "roomy.toml"
    roomy.write_text(WEAK + f"[mpc]\ninput_bounds = [[{-bound}, {bound}]]\n")
    assert _verdicts(preflight(roomy, "LQR"))["voltage"].verdict == "pass"


def test_an_untrusted_identification_is_refused(tmp_path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text('[plant]\npreset = "qube_servo2"\n')
    assert _verdicts(preflight(rig, "LQG"))["identification"].verdict == "pass"
    (tmp_path / "rig.identification.toml").write_text(
        '[identification]\ntrusted = false\nproblems = ["held-out fit 31 %"]\n'
    )
    found = _verdicts(preflight(rig, "LQG"))
    assert found["identification"].verdict == "refuse"
    assert "held-out fit 31 %" in found["identification"].message


def test_the_paper_rig_passes_and_the_prediction_is_a_simulation(tmp_path) -> None:
    rig = tmp_path / "paper.toml"
    rig.write_text("")
    for name in ("LQR", "LQG", "MPC"):
        found = _verdicts(preflight(rig, name, arm_limit=3.0))
        assert all(f.verdict == "pass" for f in found.values()), found
        # The runs start at plant.initial_state (0.05 rad) and the paper's controllers catch
        # the pendulum from there without it going much further.
        alpha = float(re.search(r"pendulum within ([0-9.]+) rad", found["prediction"].message)[1])
        assert 0.05 <= alpha < 0.2

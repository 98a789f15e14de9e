"""Every script in examples/ runs, in its small size, as the documentation site shows it.

The scripts assert what the pages say about their results (the paper's corrections, agreement
with scipy and python-control, MATLAB's published DARE example, balancing), so a change that
makes a page wrong fails here. Each runs in a fresh interpreter, as a reader would run it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
SITE_HOOK = ROOT / "docs" / "hooks" / "riprs_site.py"

# What each example must leave in --out: the figures the site links to.
WRITES = {
    "getting_started": ["arm_angle.svg", "pendulum_angle.svg", "control_voltage.svg"],
    "design_controllers": ["controllers.svg"],
    "paper_rig": ["paper_rig_map.svg"],
    "swing_up": ["swing_up.svg"],
    "rig_emulator": ["mpc.csv", "compare/arm_angle_with_logs.svg"],
    "rig_swing_up": ["swing_up.csv", "swing_up.svg"],
    "rig_excite": ["chirp.csv", "excite.svg", "rig.toml"],
    "campaign": ["fall_rate_map.svg", "rmse_pendulum_map.svg"],
}
# The rig scripts run the emulator in lockstep here, so what they assert about the log (a
# balance, an identified rig) does not depend on how loaded the machine is (the site runs them so
# too); crates/rip-rt/tests keeps the real-time runs that test timing.
LOCKSTEP = {"rig_emulator", "rig_swing_up", "rig_excite"}


def test_every_example_is_on_the_site() -> None:
    # The site's build hook runs a fixed list; an example missing from it would rot unseen.
    text = SITE_HOOK.read_text()
    missing = [p.stem for p in EXAMPLES if f'"{p.stem}"' not in text]
    assert EXAMPLES and not missing, missing


@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.stem)
def test_example_runs(script: Path, tmp_path: Path, rip_rt: Path) -> None:
    env = {**os.environ, "RIPRS_EXAMPLES_SMALL": "1", "MPLBACKEND": "Agg", "RIP_RT": str(rip_rt)}
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, str(script), "--out", str(out)]
        + (["--lockstep"] if script.stem in LOCKSTEP else []),
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, f"{script.name} failed:\n{proc.stdout}\n{proc.stderr}"
    assert proc.stdout.strip(), f"{script.name} printed nothing"
    for name in WRITES.get(script.stem, []):
        assert (out / name).is_file(), f"{script.name} did not write {name}"

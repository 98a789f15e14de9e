"""``riprs tune`` writes a file that ``rip-rt run --swing-up`` accepts as written: where a stop
during the file's swing-up could carry the arm past ``safety.arm_limit``, the tuned file's
``swing_up.arm_limit`` is the largest that ``rip-rt`` accepts (rip-core's one check,
``rip_core::preflight::motion``), judged here by ``rip-rt`` itself."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

import riprs
from riprs.tune import tune

# The paper's rig with a cable that allows 1.8 rad: a stop from the edge of the default
# 1.5 rad swing could not be braked inside it.
NARROW = '[plant]\npreset = "paper"\n[safety]\narm_limit = 1.8\n[swing_up]\narm_limit = 1.45\n'


def _swing_up_check(rip_rt: Path, config: Path) -> subprocess.CompletedProcess[str]:
    """``rip-rt run --swing-up`` on a port that does not exist: a configuration it refuses
    ends with exit 2 naming the key, one it accepts goes on to the port (exit 1)."""
    return subprocess.run(
        [str(rip_rt), "run", "--port", "/nonexistent/rip", "--controller", "lqr",
         "--swing-up", "--config", str(config)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip


def test_the_tuned_file_runs_the_swing_up_as_written(tmp_path: Path, rip_rt: Path) -> None:
    rig = tmp_path / "rig.toml"
    rig.write_text(NARROW)
    refused = _swing_up_check(rip_rt, rig)
    assert refused.returncode == 2, refused.stderr
    assert "swing_up.arm_limit: 1.45 rad" in refused.stderr
    named = float(refused.stderr.split("at most ")[1].split(" rad")[0])

    result = tune(rig, runs=0, progress=False, swing_up=False)
    assert result.spec.swing_up["arm_limit"] == pytest.approx(named, abs=1e-12)
    assert any("swing_up.arm_limit" in note for note in result.notes), result.notes
    out = tmp_path / "tuned.toml"
    result.write(out)
    accepted = _swing_up_check(rip_rt, out)
    assert accepted.returncode == 1, accepted.stderr
    assert "--port /nonexistent/rip" in accepted.stderr
    assert "swing_up.arm_limit" not in accepted.stderr
    # The file is the rig's: the safety limit it was tuned within is kept.
    assert "arm_limit = 1.8" in out.read_text()


def test_a_swing_up_no_arm_limit_can_stop_is_refused_by_tune(tmp_path: Path) -> None:
    rig = tmp_path / "rig.toml"
    # A cable of 1.3 rad: even the catch's own arm angle leaves a stop no room.
    rig.write_text('[plant]\npreset = "qube_servo2"\n[safety]\narm_limit = 1.3\n'
                   "[swing_up]\narm_limit = 1.2\n")  # fmt: skip
    with pytest.raises(riprs.ConfigError, match=r"raise safety\.arm_limit"):
        tune(rig, runs=0, progress=False, swing_up=False)
    assert not (tmp_path / "rig.tuned.toml").exists()

"""Every key of rip-rt's own sections ([loop], [device], [safety], [calibration]) reaches the
configuration rip-rt runs with, and a bad value is an error naming the key, from ``rip-rt
config`` and ``riprs config`` alike (the one validation both commands and every run use)."""

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from riprs.cli import main as riprs_main

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

RIG_SECTIONS = ("loop", "device", "safety", "calibration")

# Values a rig can hold where scaling the default is not one (a name, a sign, a zero default).
CHANGES = {
    "device.pendulum_zero": '"up"',
    "device.arm_sign": "-1.0",
    "device.pendulum_sign": "-1.0",
    "safety.wait_upright_s": "2.0",
}


def _config(rip_rt: Path, path: Path | None = None) -> subprocess.CompletedProcess[str]:
    args = [str(rip_rt), "config"] + ([str(path)] if path else [])
    return subprocess.run(args, capture_output=True, text=True, timeout=60, check=False)


def _defaults(rip_rt: Path) -> dict[str, Any]:
    doc = tomllib.loads(_config(rip_rt).stdout)
    return {f"{s}.{k}": v for s in RIG_SECTIONS for k, v in doc[s].items()}


def _changed(value: Any) -> str:
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value + 1)
    assert isinstance(value, float), value
    return repr(value * 0.9)


def test_every_rig_key_reaches_rip_rts_configuration(rip_rt: Path, tmp_path: Path) -> None:
    defaults = _defaults(rip_rt)
    assert len(defaults) == 21 and {k.split(".")[0] for k in defaults} == set(RIG_SECTIONS)
    for key, default in defaults.items():
        section, name = key.split(".")
        value = CHANGES.get(key) or _changed(default)
        f = tmp_path / "rig.toml"
        f.write_text(f"[{section}]\n{name} = {value}\n")
        done = _config(rip_rt, f)
        assert done.returncode == 0, (key, done.stderr)
        got = tomllib.loads(done.stdout)
        assert got[section][name] == tomllib.loads(f"v = {value}")["v"] != default, key
        others = {k: v for k, v in defaults.items() if k != key}
        assert all(got[k.split(".")[0]][k.split(".")[1]] == v for k, v in others.items()), key


@pytest.mark.parametrize("section", RIG_SECTIONS)
def test_a_bad_rig_value_names_its_key_in_both_commands(
    rip_rt: Path, tmp_path: Path, section: str, capsys: pytest.CaptureFixture[str]
) -> None:
    names = [k.split(".")[1] for k in _defaults(rip_rt) if k.startswith(f"{section}.")]
    for name in names:
        f = tmp_path / "bad.toml"
        f.write_text(f'[{section}]\n{name} = {{ bad = "value" }}\n')
        done = _config(rip_rt, f)
        assert done.returncode != 0, name
        assert riprs_main(["config", str(f)]) != 0, name
        for err in (done.stderr, capsys.readouterr().err):
            assert f"{f}: {section}.{name}:" in err, err
            assert "Traceback" not in err and len(err.splitlines()) == 1, err

"""A log's header settings become the identified rig file's ``[loop]``, ``[sensor]``,
``[device]`` and ``[safety]``: a header value the rig file's own rule refuses is refused by
identification, naming the header key and the log, before anything is fitted or written; a log
with a header and no rows is a clear error. The reference is ``rip-rt config``, which checks a
rig file as ``rip-rt run --config`` does."""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

import riprs
from riprs.cli import main
from riprs.identify import IdentifyError

TS = 0.01
COLUMNS = "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status"
#: The header rip-rt excite writes (a 2048-count rig at 10 ms, a 6 V motor).
GOOD = {
    "period_ms": "10",
    "arm_counts_per_rev": "2048",
    "pendulum_counts_per_rev": "2048",
    "pendulum_zero": "down",
    "arm_sign": "1",
    "pendulum_sign": "1",
    "voltage_limit": "6",
    "arm_limit": "1.2",
}


@pytest.fixture(scope="module")
def rows() -> list[str]:
    """Rows of a 12 s chirp run of the QUBE-Servo 2 from hanging at rest."""
    plant = riprs.Plant(riprs.FurutaParams.qube_servo2())
    e = riprs.excitation("chirp", dt=TS, duration=12.0, amplitude=2.5, seed=1)
    rng = np.random.default_rng(1)
    q = 2 * math.pi / 2048
    x = np.array([0.0, 0.0, math.pi, 0.0])
    out = []
    for k in range(len(e)):
        y = np.round(x[[0, 2]] / q) * q + rng.normal(0.0, 5e-4, 2)
        u = float(np.clip(e[k] - y[0], -10.0, 10.0))
        alpha = math.remainder(y[1], 2 * math.pi)
        out.append(f"{k * TS:.3f},{k},{y[0]:.17g},{alpha:.17g},0,{u:.17g},50,10,0")
        x = plant.step(x, u, TS, 10)
    return out


def write_log(path: Path, header: dict[str, str], rows: list[str]) -> Path:
    lines = ["# rip-rt excite log", *(f"# {k}: {v}" for k, v in header.items()), COLUMNS]
    path.write_text("\n".join(lines + rows) + "\n")
    return path


def rig_file_text(header: dict[str, str]) -> str:
    """The rig file's sections the header's settings give, as identification writes them."""
    counts = f"[{header['arm_counts_per_rev']}, {header['pendulum_counts_per_rev']}]"
    return (
        '[plant]\npreset = "qube_servo2"\n'
        f"[sensor]\nencoder_counts = {counts}\n"
        f"[loop]\nperiod_ms = {float(header['period_ms'])!r}\n"
        f'[device]\npendulum_zero = "{header["pendulum_zero"]}"\n'
        f"arm_sign = {float(header['arm_sign'])!r}\n"
        f"pendulum_sign = {float(header['pendulum_sign'])!r}\n"
        f"[safety]\nvoltage_limit = {float(header['voltage_limit'])!r}\n"
        f"arm_limit = {float(header['arm_limit'])!r}\n"
    )


#: Header values rip-rt run would refuse in the rig file (the issue's three first).
BAD = [
    ("arm_counts_per_rev", "0"),
    ("period_ms", "0"),
    ("period_ms", "nan"),
    ("pendulum_counts_per_rev", "8"),
    ("arm_sign", "2"),
    ("voltage_limit", "0"),
    ("arm_limit", "-1"),
]


@pytest.mark.parametrize(("key", "value"), [("lab.Rm", "0"), ("lab.arm_counts", "2.5")])
def test_a_lab_value_the_lab_file_refuses_is_refused_naming_the_log(tmp_path, rows, key, value):
    log = write_log(tmp_path / "chirp.csv", {**GOOD, key: value}, rows)
    with pytest.raises(IdentifyError, match=rf"chirp\.csv: header {key}: must be"):
        riprs.identify([log], max_iter=1)


@pytest.mark.parametrize(("key", "value"), BAD)
def test_rip_rt_refuses_the_rig_file_these_headers_would_give(tmp_path, rip_rt, key, value):
    # The independent reference: each bad value is one rip-rt's own check refuses.
    rig = tmp_path / "rig.toml"
    rig.write_text(rig_file_text({**GOOD, key: value}))
    checked = subprocess.run(
        [str(rip_rt), "config", str(rig)], capture_output=True, text=True, timeout=60
    )
    assert checked.returncode != 0, checked.stdout
    good = tmp_path / "good.toml"
    good.write_text(rig_file_text(GOOD))
    checked = subprocess.run(
        [str(rip_rt), "config", str(good)], capture_output=True, text=True, timeout=60
    )
    assert checked.returncode == 0, checked.stderr


@pytest.mark.parametrize(("key", "value"), BAD)
def test_a_header_value_the_rig_file_refuses_is_refused_naming_key_and_log(
    tmp_path, rows, capsys, key, value
):
    log = write_log(tmp_path / "chirp.csv", {**GOOD, key: value}, rows)
    pattern = rf"chirp\.csv: header {key}: .*{value if value != 'nan' else 'NaN|nan'}"
    with pytest.raises(IdentifyError, match=pattern):
        riprs.identify([log], max_iter=1)
    out = tmp_path / "rig.toml"
    assert main(["identify", str(log), "--out", str(out), "--no-plots", "--max-iter", "1"]) == 1
    err = capsys.readouterr().err
    assert f"header {key}" in err and "chirp.csv" in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob("rig*"))


def test_a_log_with_a_header_and_no_rows_is_a_clear_error(tmp_path, rows, capsys):
    empty = write_log(tmp_path / "empty.csv", GOOD, [])
    with pytest.raises(IdentifyError, match=r"empty: .*no samples"):
        riprs.identify([empty])
    full = write_log(tmp_path / "chirp.csv", GOOD, rows)
    with pytest.raises(IdentifyError, match=r"empty: .*no samples"):
        riprs.identify([full, empty])
    out = tmp_path / "rig.toml"
    assert main(["identify", str(empty), "--out", str(out), "--no-plots"]) == 1
    err = capsys.readouterr().err
    assert "no samples" in err and "Traceback" not in err
    assert not out.exists()


def test_the_rig_file_identification_writes_is_one_rip_rt_reads(tmp_path, rows, rip_rt):
    # Whatever identification writes (here --force, trusted or not) rip-rt's check accepts.
    log = write_log(tmp_path / "chirp.csv", GOOD, rows)
    out = tmp_path / "rig.toml"
    code = main(
        ["identify", str(log), "--out", str(out), "--no-plots", "--max-iter", "2", "--force"]
    )
    assert code == 0
    checked = subprocess.run(
        [str(rip_rt), "config", str(out)], capture_output=True, text=True, timeout=60
    )
    assert checked.returncode == 0, checked.stderr
    assert riprs.load_config(out).sensor.encoder_counts == [2048, 2048]

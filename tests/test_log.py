"""riprs.load_log: the CSV written by ``rip-rt run --log``."""

from __future__ import annotations

import pathlib
import signal
import subprocess

import numpy as np
import pytest

import riprs
from riprs.log import FLAG_NO_REPLY

ROOT = pathlib.Path(__file__).resolve().parents[1]

SAMPLE = """\
# rip-rt: 0.1.0
# protocol: 1
# controller: lqg
t,seq,theta,alpha,theta_ref,u,xhat_0,xhat_1,compute_us,jitter_us,status
0.0000,10,0.001000,0.050000,0.000000,1.5000,0.1,0.2,30.5,80.0,1
0.0100,11,0.002000,0.040000,0.000000,1.2500,0.3,0.4,31.0,75.5,1
0.0200,12,0.002000,0.040000,0.000000,1.2500,,,0.0,90.0,256
# stop: signal
# stop_message: stopped by SIGINT (2)
# exit_code: 130
"""


def test_parses_columns_estimates_and_metadata(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "run.csv"
    path.write_text(SAMPLE)
    log = riprs.load_log(path)
    np.testing.assert_array_equal(log.t, [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(log.seq, [10, 11, 12])
    assert log.seq.dtype == np.int64
    np.testing.assert_array_equal(log.u, [1.5, 1.25, 1.25])
    np.testing.assert_array_equal(log.y[:, 1], [0.05, 0.04, 0.04])
    assert log.xhat.shape == (3, 2)
    np.testing.assert_array_equal(log.xhat[1], [0.3, 0.4])
    assert np.isnan(log.xhat[2]).all()
    assert log.status[2] & FLAG_NO_REPLY
    assert log.meta["controller"] == "lqg"
    assert log.meta["exit_code"] == "130"
    assert log.stop_reason == "signal"


def test_without_estimates(tmp_path: pathlib.Path) -> None:
    lines = [ln for ln in SAMPLE.splitlines() if not ln.startswith("#")]
    header = "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status"
    rows = [",".join(r.split(",")[:6] + r.split(",")[8:]) for r in lines[1:]]
    path = tmp_path / "lqr.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    log = riprs.load_log(path)
    assert log.xhat.shape == (3, 0)
    assert log.stop_reason is None


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("a,b,c\n1,2,3\n", "missing columns"),
        ("# only comments\n", "no column row"),
        (SAMPLE.replace("30.5", "fast"), "column 'compute_us'"),
        (SAMPLE.replace("0.0100,11,", "0.0100,"), "line 6"),
    ],
)
def test_malformed_logs_name_the_problem(tmp_path: pathlib.Path, text: str, match: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        riprs.load_log(path)


def _binary() -> pathlib.Path | None:
    for profile in ("release", "debug"):
        exe = ROOT / "target" / profile / "rip-rt"
        if exe.exists():
            return exe
    return None


@pytest.mark.skipif(_binary() is None, reason="rip-rt is not built (cargo build -p rip-rt)")
def test_reads_a_log_written_by_rip_rt(tmp_path: pathlib.Path) -> None:
    exe = _binary()
    assert exe is not None
    emu = subprocess.Popen(
        [str(exe), "emulate", "--noise", "0.3"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert emu.stdout is not None
        device = emu.stdout.readline().strip().removeprefix("device: ")
        log_path = tmp_path / "lqg.csv"
        run = subprocess.run(
            [str(exe), "run", "--port", device, "--controller", "lqg",
             "--duration", "1.5", "--log", str(log_path), "--quiet"],
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert run.returncode == 0, run.stderr
    finally:
        emu.send_signal(signal.SIGTERM)
        emu.wait(timeout=10)
    log = riprs.load_log(log_path)
    assert log.meta["controller"] == "lqg"
    assert log.stop_reason == "finished"
    assert 140 <= len(log.t) <= 151
    assert np.all(np.diff(log.t) > 0)
    assert log.xhat.shape[1] == 5  # the LQG's augmented estimate
    assert np.abs(log.alpha).max() < 0.25
    assert np.abs(log.u).max() <= 12.0

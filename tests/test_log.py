"""riprs.load_log: the CSV written by ``rip-rt run --log``."""

from __future__ import annotations

import pathlib
import signal
import subprocess
import sys

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


SWING_UP = """\
# controller: lqr
# swing_up: true
t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status,phase
0.0000,1,0.000000,3.141593,0.000000,12.0000,5.0,80.0,1,swing_up
0.0100,2,0.010000,3.100000,0.000000,12.0000,5.0,80.0,1,swing_up
0.0200,3,0.020000,0.200000,0.000000,-3.0000,5.0,80.0,1,balance
0.0300,4,0.020000,0.100000,0.000000,-2.0000,0.0,80.0,256,balance
0.0400,5,0.020000,0.700000,0.000000,12.0000,5.0,80.0,1,swing_up
0.0500,6,0.020000,0.100000,0.000000,1.0000,5.0,80.0,1,balance
# stop: finished
# catch_s: 0.020
"""


def test_the_phase_of_every_row(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "swing.csv"
    path.write_text(SWING_UP)
    log = riprs.load_log(path)
    assert log.phase.tolist() == [
        "swing_up", "swing_up", "balance", "balance", "swing_up", "balance",
    ]
    # The first catch: the first balance row after swing-up rows.
    assert log.catch_index == 2
    assert log.t[log.catch_index] == pytest.approx(float(log.meta["catch_s"]))
    assert set(log.phase.tolist()) <= set(riprs.log.PHASES)


def test_logs_without_the_phase_column_are_balancing(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "old.csv"
    path.write_text(SAMPLE)
    log = riprs.load_log(path)
    assert log.phase.tolist() == ["balance"] * 3
    assert log.catch_index is None


@pytest.mark.parametrize(
    ("bad", "line"),
    [("swinging", 6), ("", 6), ("swing_up_and_away", 6)],
)
def test_an_unknown_phase_is_named_with_its_line(
    tmp_path: pathlib.Path, bad: str, line: int
) -> None:
    text = SWING_UP.replace("0.0200,3,0.020000,0.200000,0.000000,-3.0000,5.0,80.0,1,balance",
                            f"0.0200,3,0.020000,0.200000,0.000000,-3.0000,5.0,80.0,1,{bad}")
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(riprs.LogError, match=f"line {line}: column 'phase'"):
        riprs.load_log(path)
    # A bad number in a later row is still found, past rows with valid phases.
    path.write_text(SWING_UP.replace("0.0500,6,", "0.0500,six,"))
    with pytest.raises(riprs.LogError, match="line 9: column 'seq'"):
        riprs.load_log(path)


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


def test_reads_a_log_written_by_rip_rt(tmp_path: pathlib.Path, rip_rt: pathlib.Path) -> None:
    exe = rip_rt
    emu = subprocess.Popen(
        # In lockstep: the log's contents are the subject, not timing.
        [str(exe), "emulate", "--noise", "0.3", "--lockstep"],
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
             "--duration", "1.5", "--log", str(log_path), "--quiet", "--lockstep"],
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
    # A row per period, 0 to 1.49 s: in lockstep none is skipped.
    assert len(log.t) == 150
    assert log.t[-1] >= 1.45
    assert np.all(np.diff(log.t) > 0)
    assert log.xhat.shape[1] == 5  # the LQG's augmented estimate
    assert log.phase.tolist() == ["balance"] * len(log.t)
    assert np.abs(log.alpha).max() < 0.25
    assert np.abs(log.u).max() <= 12.0


def test_reads_the_phases_of_a_swing_up_written_by_rip_rt(
    tmp_path: pathlib.Path, rip_rt: pathlib.Path
) -> None:
    exe = rip_rt
    config = tmp_path / "rig.toml"
    config.write_text("[calibration]\nrest_window_s = 0.5\n")
    emu = subprocess.Popen(
        [str(exe), "emulate", "--start", "down", "--noise", "0.3", "--lockstep"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert emu.stdout is not None
        device = emu.stdout.readline().strip().removeprefix("device: ")
        log_path = tmp_path / "swing.csv"
        run = subprocess.run(
            [str(exe), "run", "--port", device, "--controller", "lqr", "--swing-up",
             "--config", str(config), "--duration", "1", "--log", str(log_path), "--quiet",
             "--lockstep"],
            capture_output=True,
            text=True,
            timeout=40,
        )
        assert run.returncode == 0, run.stderr
    finally:
        emu.send_signal(signal.SIGTERM)
        emu.wait(timeout=10)
    log = riprs.load_log(log_path)
    assert log.meta["swing_up"] == "true"
    # The sign check's pulse first, then the swing.
    assert log.phase[0] == "sign_check"
    swing = int(np.flatnonzero(log.phase != "sign_check")[0])
    assert log.phase[swing] == "swing_up"
    assert log.meta["sign_check"].startswith("passed")
    # Started hanging: α = ±π before the pulse moved it.
    assert np.pi - abs(log.alpha[0]) < 0.01
    k = log.catch_index
    assert k is not None
    assert k > swing
    assert set(log.phase[swing:k].tolist()) == {"swing_up"}
    assert log.t[k] == pytest.approx(float(log.meta["catch_s"]), abs=1e-3)
    # It ends balanced, near upright.
    assert log.phase[-1] == "balance"
    assert abs(log.alpha[-1]) < 0.3


def _write_bytes(tmp_path: pathlib.Path, data: bytes) -> pathlib.Path:
    path = tmp_path / "log.csv"
    path.write_bytes(data)
    return path


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ("xhat_1", "xhat_a", r"line 4: column 'xhat_a': state-estimate columns are named xhat_0"),
        ("xhat_1", "xhat_2", r"line 4: column 'xhat_2'"),
        (",u,", ",u,u,", r"line 4: column 'u' appears twice"),
        ("0.0100,11,", "0.0100,nan,", r"line 6: column 'seq': not an integer .*'nan'"),
        ("0.0100,11,", "0.0100,1e30,", r"line 6: column 'seq': not an integer .*'1e30'"),
        ("0.0100,11,", "0.0100,99999999999999999999,", r"line 6: column 'seq'"),
        ("75.5,1\n", "75.5,nan\n", r"line 6: column 'status': not an integer .*'nan'"),
        ("75.5,1\n", "75.5,1.0\n", r"line 6: column 'status'"),
        ("75.5,1\n", "75.5,\n", r"line 6: column 'status'"),
        ("0.3,0.4", "0.3,zero", r"line 6: column 'xhat_1': not a number: 'zero'"),
    ],
)
def test_bad_columns_and_cells_name_file_line_and_column(tmp_path, old, new, match) -> None:
    assert old in SAMPLE
    path = _write_bytes(tmp_path, SAMPLE.replace(old, new, 1).encode())
    with pytest.raises(riprs.LogError, match=match) as info:
        riprs.load_log(path)
    assert str(path) in str(info.value)


def test_a_byte_order_mark_and_crlf_line_ends_are_accepted(tmp_path) -> None:
    plain = riprs.load_log(_write_bytes(tmp_path, SAMPLE.encode()))
    text = b"\xef\xbb\xbf" + SAMPLE.replace("\n", "\r\n").encode()
    marked = riprs.load_log(_write_bytes(tmp_path, text))
    assert marked.meta == plain.meta and marked.meta["rip-rt"] == "0.1.0"
    for name in ("t", "seq", "theta", "u", "status"):
        np.testing.assert_array_equal(getattr(marked, name), getattr(plain, name))
    np.testing.assert_array_equal(marked.xhat, plain.xhat)


def _big_log(rows: int) -> bytes:
    """A log of `rows` rows with five estimate columns, written with numpy's formatter."""
    header = "# rip-rt: 0.1.0\nt,seq,theta,alpha,theta_ref,u,xhat_0,xhat_1,xhat_2,xhat_3,xhat_4,"
    header += "compute_us,jitter_us,status\n"
    k = np.arange(rows)
    table = np.column_stack(
        [k * 0.01, k, np.sin(k * 1e-3), 0.01 * np.cos(k * 1e-2), np.ones(rows), 0.5 * np.ones(rows)]
        + [np.full(rows, 0.125 * i) for i in range(5)]
        + [np.full(rows, 31.5), np.full(rows, 80.0), k % 4096]
    )
    import io

    buf = io.StringIO()
    fmt = ["%.4f", "%d"] + ["%.6f"] * 9 + ["%.1f", "%.1f", "%d"]
    np.savetxt(buf, table, fmt=fmt, delimiter=",")
    return (header + buf.getvalue() + "# stop: finished\n").encode()


def test_a_bad_row_deep_in_a_large_log_is_named_by_its_line(tmp_path) -> None:
    data = _big_log(50_000).splitlines(keepends=True)
    # Line 2 is the column row, so data row i is line i + 3.
    data[40_000 + 2] = data[40_000 + 2].replace(b",", b",x", 1)
    with pytest.raises(riprs.LogError, match=r"line 40003: column 'seq'"):
        riprs.load_log(_write_bytes(tmp_path, b"".join(data)))
    log = riprs.load_log(_write_bytes(tmp_path, _big_log(50_000)))
    assert len(log.t) == 50_000 and log.xhat.shape == (50_000, 5)
    np.testing.assert_array_equal(log.seq, np.arange(50_000))
    np.testing.assert_array_equal(log.status, np.arange(50_000) % 4096)
    np.testing.assert_array_equal(log.xhat[-1], [0.0, 0.125, 0.25, 0.375, 0.5])
    np.testing.assert_allclose(log.theta, np.round(np.sin(np.arange(50_000) * 1e-3), 6))
    assert log.meta["stop"] == "finished"


PEAK_SCRIPT = """
import resource, sys
import riprs
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
log = riprs.load_log(sys.argv[1])
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
arrays = sum(a.nbytes for a in (log.t, log.seq, log.theta, log.alpha, log.theta_ref, log.u,
                                 log.xhat, log.compute_us, log.jitter_us, log.status))
print(len(log.t), (after - before) * 1024, arrays)
"""


def test_a_large_log_loads_in_memory_close_to_its_arrays(tmp_path) -> None:
    path = _write_bytes(tmp_path, _big_log(300_000))
    done = subprocess.run(
        [sys.executable, "-c", PEAK_SCRIPT, str(path)], capture_output=True, text=True, check=True
    )
    rows, growth, arrays = map(int, done.stdout.split())
    assert rows == 300_000
    # Python floats per cell (the old reader) took about 30 times the arrays; the arrays, one
    # parsing block and the file's size in the counting pass are what may remain.
    assert growth < 2 * arrays + 32 * 2**20, (growth, arrays)

"""riprs.excitation against independent references: scipy's chirp, m-sequence facts, and the
documented step and kick shapes."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

import riprs


@pytest.mark.parametrize(("sweep", "method"), [("log", "logarithmic"), ("linear", "linear")])
def test_chirp_matches_scipy(sweep: str, method: str) -> None:
    dt, duration = 0.01, 12.0
    u = riprs.excitation(
        "chirp", dt=dt, duration=duration, amplitude=1.5, f_start=0.3, f_end=7.0, sweep=sweep
    )
    t = np.arange(u.size) * dt
    assert u.size == 1200
    # scipy's chirp is a cosine; phi = -90 degrees makes it the sine that starts at 0 V.
    ref = 1.5 * scipy.signal.chirp(t, f0=0.3, t1=duration, f1=7.0, method=method, phi=-90)
    np.testing.assert_allclose(u, ref, atol=1e-9)


def test_prbs_is_an_m_sequence() -> None:
    bits = 8
    n = 2**bits - 1
    u = riprs.excitation(
        "prbs", prbs_bits=bits, prbs_clock=0.01, amplitude=2.0, duration=2 * n * 0.01
    )
    assert u.size == 2 * n
    assert set(np.unique(u)) == {-2.0, 2.0}
    np.testing.assert_array_equal(u[:n], u[n:])
    # One more +A than -A per period; circular autocorrelation -A^2 at every non-zero lag.
    assert u[:n].sum() == pytest.approx(2.0)
    spectrum = np.abs(np.fft.fft(u[:n])) ** 2
    autocorrelation = np.fft.ifft(spectrum).real
    np.testing.assert_allclose(autocorrelation[1:], -4.0, atol=1e-9)
    # Its longest run is bits ones (an m-sequence property), never longer.
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, u[:n] > 0, 0])))[::2]
    assert runs.max() == bits


def test_prbs_seed_is_reproducible_and_times_may_be_given() -> None:
    a = riprs.excitation("prbs", seed=7)
    np.testing.assert_array_equal(a, riprs.excitation("prbs", seed=7))
    assert not np.array_equal(a, riprs.excitation("prbs", seed=8))
    t = np.arange(a.size) * 0.01
    rng = np.random.default_rng(0)
    order = rng.permutation(a.size)
    np.testing.assert_array_equal(riprs.excitation("prbs", seed=7, t=t[order]), a[order])


def test_steps_and_free_swing_shapes() -> None:
    u = riprs.excitation("steps", amplitude=2.0, step_hold=0.25, duration=4.5)
    levels = 2.0 * np.array([1, 0, -1, 0, 0.5, 0, -0.5, 0])
    expected = np.repeat(np.tile(levels, 3), 25)[: u.size]
    np.testing.assert_array_equal(u, expected)
    u = riprs.excitation("free-swing", amplitude=4.0, kick=0.1, duration=2.0)
    np.testing.assert_array_equal(u[:10], 4.0)
    np.testing.assert_array_equal(u[10:20], -4.0)
    np.testing.assert_array_equal(u[20:], 0.0)


def test_defaults_are_the_documented_ones() -> None:
    d = riprs.excitation_defaults("chirp")
    assert (d["amplitude"], d["duration"], d["f_start"], d["f_end"], d["sweep"]) == (
        2.0,
        30.0,
        0.2,
        10.0,
        "log",
    )
    assert (d["centering"], d["damping"]) == (1.0, 0.2)
    u = riprs.excitation("chirp")
    assert u.size == 3000
    assert np.abs(u).max() <= 2.0


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"signal": "sine"}, "signal"),
        ({"signal": "chirp", "f_end": 80.0}, "f_end"),
        ({"signal": "chirp", "amplitude": -1.0}, "amplitude"),
        ({"signal": "chirp", "sweep": "cubic"}, "sweep"),
        ({"signal": "prbs", "prbs_bits": 40}, "prbs_bits"),
        ({"signal": "prbs", "prbs_bits": -1}, "prbs_bits"),
        ({"signal": "prbs", "seed": -3}, "seed"),
        ({"signal": "steps", "step_hold": 0.0}, "step_hold"),
        ({"signal": "free-swing", "kick": 20.0}, "kick"),
        ({"signal": "chirp", "dt": 1e-9}, "dt"),
        ({"signal": "chirp", "duration": float("nan")}, "duration"),
    ],
)
def test_bad_settings_name_the_keyword(kwargs: dict, name: str) -> None:
    with pytest.raises(riprs.InvalidParameterError, match=name):
        riprs.excitation(**kwargs)


def test_bad_times_are_refused() -> None:
    with pytest.raises(riprs.NonFiniteError, match="t"):
        riprs.excitation("chirp", t=[0.0, float("nan")])
    with pytest.raises(riprs.ShapeError, match="t"):
        riprs.excitation("chirp", t=np.zeros((2, 2)))


def test_an_excitation_log_reads_with_load_log(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """The format of ``rip-rt excite --log`` (docs/rip-rt.md): run's columns without
    estimates, and a last ``phase`` column."""
    path = tmp_path / "excite.csv"
    rows = [
        "0.0000,0,0.000000,3.141593,0.000000,2.0000,3.1,68.0,1,sign_check",
        "0.6000,60,0.120000,3.100000,0.000000,0.0000,3.0,50.0,1,chirp",
        "0.6100,61,0.121000,3.099000,0.000000,0.0021,3.0,50.0,1,chirp",
    ]
    path.write_text(
        "# mode: excite\n# signal: chirp\n"
        "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status,phase\n"
        + "\n".join(rows)
        + "\n# stop: finished\n"
    )
    log = riprs.load_log(path)
    np.testing.assert_array_equal(log.u, [2.0, 0.0, 0.0021])
    np.testing.assert_array_equal(log.theta, [0.0, 0.12, 0.121])
    assert log.xhat.shape == (3, 0)
    assert log.meta["signal"] == "chirp"
    assert log.stop_reason == "finished"
    assert list(log.phase) == ["sign_check", "chirp", "chirp"]
    assert log.catch_index is None

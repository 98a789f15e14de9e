"""Identification against hidden rigs: logs simulated here from plants drawn away from both
presets (Coulomb friction, dead zone, 2048-count encoders, noise) under riprs.excitation inputs;
the truth is the hidden plant's own linearisation, and the identified file must drive designs
that balance the hidden plant."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import riprs
from riprs.cli import main
from riprs.identify import IdentifyError, IdentifyWarning

TS = 0.01
HIDDEN = riprs.FurutaParams(
    Rm=6.1,
    kt=0.051,
    km=0.051,
    mr=0.11,
    Lr=0.097,
    Jr=1.1e-4,
    mp=0.031,
    Lp=0.152,
    Jp=6.5e-5,
    Dr=9e-4,
    Dp=2.4e-5,
    Cr=2.5e-3,
    Cp=1.5e-5,
    Vd=0.35,
)
COLUMNS = "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status"


def excitation_run(
    params: riprs.FurutaParams,
    signal: str,
    duration: float,
    seed: int,
    *,
    amplitude: float = 2.5,
    alpha0: float = math.pi,
) -> np.ndarray:
    """Rows of a rip-rt log: the hidden plant from rest under the excitation with a weak
    arm-centring pull (1 V/rad), angles through 2048-count encoders plus 0.5 mrad noise,
    alpha wrapped to (-pi, pi] as an encoder-based log would show it."""
    plant = riprs.Plant(params)
    rng = np.random.default_rng(seed)
    coast = signal == "coast"
    if coast:  # motor off throughout: u = 0, no centring
        e = np.zeros(round(duration / TS))
    else:
        e = riprs.excitation(signal, dt=TS, duration=duration, amplitude=amplitude, seed=seed)
    q = 2 * math.pi / 2048
    x = np.array([0.0, 0.0, alpha0, 0.0])
    rows = []
    for k in range(len(e)):
        meas = np.round(x[[0, 2]] / q) * q + rng.normal(0.0, 5e-4, 2)
        u = 0.0 if coast else float(np.clip(e[k] - meas[0], -10.0, 10.0))
        alpha = math.remainder(meas[1], 2 * math.pi)
        rows.append((k * TS, k, meas[0], alpha, 0.0, u, 50.0, 10.0, 0))
        x = plant.step(x, u, TS, 10)
    return np.array(rows)


def write_log(path: Path, rows: np.ndarray) -> Path:
    lines = ["# rip-rt excite log", COLUMNS]
    for r in rows:
        lines.append(
            f"{r[0]:.3f},{int(r[1])},{r[2]:.17g},{r[3]:.17g},{r[4]:.17g},{r[5]:.17g},"
            f"{r[6]:.0f},{r[7]:.0f},{int(r[8])}"
        )
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def hidden_logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    d = tmp_path_factory.mktemp("hidden")
    return [
        write_log(d / "chirp.csv", excitation_run(HIDDEN, "chirp", 30.0, 1)),
        write_log(d / "prbs.csv", excitation_run(HIDDEN, "prbs", 30.0, 2)),
    ]


def entries_that_matter(ad: np.ndarray, bd: np.ndarray) -> np.ndarray:
    """Entries of [A_d - I, B_d] at least 5 % of the largest in their row."""
    m = np.hstack([ad - np.eye(4), bd])
    return np.abs(m) >= 0.05 * np.abs(m).max(axis=1, keepdims=True)


@pytest.fixture(scope="module")
def identified(hidden_logs: list[Path]) -> riprs.IdentifyResult:
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always", IdentifyWarning)
        result = riprs.identify(hidden_logs, start="qube_servo2")
    # The hidden arm is lighter than the QUBE's for its inertia: only mr may be adjusted.
    assert [str(w.message)[:3] for w in record] in ([], ["mr "]), [str(w.message) for w in record]
    return result


def test_recovers_the_hidden_linearisation_and_fits_held_out_data(identified, capsys):
    ad, bd = riprs.Plant(HIDDEN).linearize_discrete(TS)
    got = np.hstack([identified.Ad, identified.Bd])
    true = np.hstack([ad, bd])
    rel = np.abs(got - true) / np.maximum(np.abs(true), 1e-300)
    with capsys.disabled():
        print("\nrelative error of every entry of [A_d B_d]:\n", np.array2string(rel, precision=4))
        print(identified.report())
    mask = entries_that_matter(ad, bd)
    assert rel[mask].max() < 0.05, rel
    assert (identified.fit_percent >= 90.0).all(), identified.fit_percent
    assert identified.not_identifiable == ()
    # The dead zone is scale-free and must come back as it is.
    assert identified.params.Vd == pytest.approx(HIDDEN.Vd, rel=0.1)
    assert identified.simulations > 0 and identified.converged


def test_another_start_reaches_the_same_model(hidden_logs, identified):
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always", IdentifyWarning)
        other = riprs.identify(hidden_logs, start="paper")
    assert other.converged
    np.testing.assert_allclose(other.Ad, identified.Ad, rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(other.Bd, identified.Bd, rtol=1e-4)


def test_the_written_file_designs_controllers_that_balance_the_hidden_plant(
    hidden_logs, tmp_path, capsys
):
    out = tmp_path / "rig.toml"
    code = main(["identify", *map(str, hidden_logs), "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0
    assert "held-out" in printed and "NOT IDENTIFIABLE" not in printed
    assert (tmp_path / "rig-chirp.png").stat().st_size > 0
    assert (tmp_path / "rig-prbs.png").stat().st_size > 0
    spec = riprs.load_config(out)
    hidden = riprs.Plant(HIDDEN)
    for name, controller in spec.build_controllers().items():
        res = riprs.simulate(
            hidden,
            controller,
            10.0,
            x0=[0.0, 0.0, 0.05, 0.0],
            reference=1.0,
            reference_time=1.0,
            encoder_counts=[2048, 2048],
            noise_std=1e-3,
        )
        assert not res.fell, name
        assert abs(res.y[-100:, 0].mean() - 1.0) < 0.1, name
    # riprs compare accepts it as its configuration.
    assert main(["compare", "--config", str(out), "--out", str(tmp_path / "cmp"), "--no-plots",
                 "--quiet"]) == 0


def write_rows(tmp_path: Path, name: str, rows: np.ndarray) -> Path:
    return write_log(tmp_path / f"{name}.csv", rows)


def test_bad_logs_get_a_clear_error_naming_the_log(tmp_path):
    good = excitation_run(HIDDEN, "chirp", 4.0, 3)
    short = write_rows(tmp_path, "short", good[:120])
    with pytest.raises(IdentifyError, match=r"short: too short"):
        riprs.identify([short])
    nan = good.copy()
    nan[40, 2] = np.nan
    with pytest.raises(IdentifyError, match=r"nan: column 'theta' is not a number.*row 40"):
        riprs.identify([write_rows(tmp_path, "nan", nan)])
    still = good.copy()
    still[:, 2] = 0.0
    still[:, 3] = math.pi
    still[:, 5] = 0.0
    with pytest.raises(IdentifyError, match=r"still: no excitation"):
        riprs.identify([write_rows(tmp_path, "still", still)])
    # A balancing run: the pendulum near upright, small motions.
    balancing = good.copy()
    balancing[:, 3] = 0.01 * np.sin(np.arange(len(good)) * 0.3)
    with pytest.raises(IdentifyError, match=r"balancing: .*balancing run"):
        riprs.identify([write_rows(tmp_path, "balancing", balancing)])
    wrong = tmp_path / "wrong.csv"
    wrong.write_text("t,theta,alpha,voltage\n0,0,3.14,0\n")
    with pytest.raises(riprs.LogError, match="missing columns"):
        riprs.identify([wrong])


def test_saturated_and_unexcited_logs_warn_and_name_what_is_not_identifiable(tmp_path):
    saturated = excitation_run(HIDDEN, "chirp", 12.0, 4)
    saturated[: len(saturated) // 5, 8] = riprs.log.FLAG_CLAMPED
    with pytest.warns(IdentifyWarning, match=r"saturated: the voltage is saturated in 20 %"):
        riprs.identify([write_rows(tmp_path, "saturated", saturated)], max_iter=5)
    # A free swing with the motor off: the pendulum moves, the motor never acts, so the
    # motor constant, arm friction and dead zone cannot be determined.
    coast = excitation_run(HIDDEN, "coast", 12.0, 5, alpha0=math.pi - 0.6)
    with pytest.warns(IdentifyWarning) as record:
        result = riprs.identify([write_rows(tmp_path, "coast", coast)], max_iter=10)
    messages = " ".join(str(w.message) for w in record)
    assert "coast: the voltage is constant" in messages
    assert "not identifiable from these logs" in messages
    assert {"kt", "Vd"} <= set(result.not_identifiable) | set(result.at_bounds)


def test_rip_rt_run_and_emulate_accept_the_written_file(identified, tmp_path, rip_rt):
    import subprocess

    rig = tmp_path / "rig.toml"
    rig.write_text(identified.to_toml("chirp.csv, prbs.csv"))
    # `rip-rt config` checks the file as `rip-rt run --config` does (designs included).
    checked = subprocess.run(
        [str(rip_rt), "config", str(rig)], capture_output=True, text=True, timeout=60
    )
    assert checked.returncode == 0, checked.stderr
    assert f"Vd = {identified.params.Vd!r}" in checked.stdout
    # The emulator simulates it (friction and dead zone included) and exits on its own.
    emulated = subprocess.run(
        [str(rip_rt), "emulate", "--config", str(rig), "--duration", "0.3"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert emulated.returncode == 0, emulated.stderr


@pytest.mark.slow
def test_hidden_rig_chain_excite_identify_run(tmp_path, rip_rt):
    """`rip-rt emulate --config hidden.toml` is the rig; `rip-rt excite` logs a chirp, a PRBS
    run and a free swing; `riprs identify` writes rig.toml; `rip-rt run --config rig.toml`
    balances the hidden emulator with LQR, LQG and MPC designed on it."""
    import signal
    import subprocess

    hidden = tmp_path / "hidden.toml"
    hidden.write_text(
        '[plant]\npreset = "qube_servo2"\n'
        + "".join(f"{k} = {v!r}\n" for k, v in HIDDEN.to_dict().items() if k != "g")
    )

    def on_emulator(args: list[str], *command: str) -> subprocess.CompletedProcess:
        emulator = subprocess.Popen(
            [str(rip_rt), "emulate", "--config", str(hidden), "--noise", "0.3", *args],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            device = emulator.stdout.readline().strip().removeprefix("device: ")
            return subprocess.run(
                [str(rip_rt), *command, "--port", device],
                capture_output=True,
                text=True,
                timeout=120,
            )
        finally:
            emulator.send_signal(signal.SIGTERM)
            emulator.wait(timeout=10)

    def retried(args: list[str], *command: str) -> subprocess.CompletedProcess:
        # A run stopped by a CPU stall of the loaded machine (4, 5, 10, and 15: the witness
        # judging a period the stall stretched) is run again, once.
        done = on_emulator(args, *command)
        if done.returncode in (4, 5, 10, 15):
            done = on_emulator(args, *command)
        assert done.returncode == 0, done.stdout + done.stderr
        return done

    logs = []
    # The excitations of the rig path (docs/identification.md), the free swing included: the
    # pendulum's damping is not determined without it. In lockstep with the emulator, so that
    # its 60 s cost no wall time and the logs do not depend on the machine's load; so are the
    # runs below, whose subject is the identified design, not the loop's timing (the real-time
    # group times the loop).
    for signal_name, seed, seconds in (("chirp", "3", "20"), ("prbs", "4", "20"),
                                       ("free-swing", "6", "60")):
        log = tmp_path / f"{signal_name}.csv"
        retried(
            ["--start", "down", "--seed", seed, "--lockstep"],
            "excite", "--signal", signal_name, "--duration", seconds, "--log", str(log),
            "--quiet", "--lockstep",
        )  # fmt: skip
        logs.append(log)
    rig = tmp_path / "rig.toml"
    assert main(["identify", *map(str, logs), "--out", str(rig), "--no-plots"]) == 0
    result = riprs.load_config(rig)
    ad, bd = riprs.Plant(HIDDEN).linearize_discrete(TS)
    got_ad, got_bd = riprs.Plant(result.params).linearize_discrete(TS)
    true = np.hstack([ad, bd])
    rel = np.abs(np.hstack([got_ad, got_bd]) - true) / np.maximum(np.abs(true), 1e-300)
    mask = entries_that_matter(ad, bd)
    assert rel[mask].max() < 0.05, rel
    for controller in ("lqr", "lqg", "mpc"):
        retried(
            ["--seed", "5", "--lockstep"],
            "run", "--config", str(rig), "--controller", controller, "--duration", "4",
            "--lockstep",
        )  # fmt: skip

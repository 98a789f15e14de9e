"""Identification that cannot fail silently: logs with wrong units or signs are refused naming
the log and the column; a fit that cannot be trusted ends ``riprs identify`` non-zero without a
rig file; a lab file of measured masses, lengths and resistance makes rigs across the envelope
identifiable. Logs are made by rip-core's simulator (``riprs.Plant.step``, with encoder
quantisation and noise) under ``riprs.excitation`` inputs, not by the fit's own segment model;
the truth is the simulated plant's own linearisation. Rigs across the envelope of
shared/DESIGN.md are drawn here by a seeded generator (uniform in each range)."""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import riprs
from riprs.cli import main
from riprs.identify import IdentifyError, UntrustedIdentification, identification_path, read_lab

TS = 0.01
COLUMNS = "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status"
QUBE = riprs.FurutaParams.qube_servo2()
#: The issue's rig far from the start set: a heavy, long pendulum, a large dead zone and arm
#: Coulomb friction.
HEAVY = riprs.FurutaParams(
    **{
        **QUBE.to_dict(),
        "mp": 0.06,
        "Lp": 0.25,
        "Jp": 0.06 * 0.25**2 / 12,
        "Vd": 0.6,
        "Cr": 0.006,
    }
)
#: Kick (V) of the free-swing runs (rip-rt excite's default).
FREE_AMPLITUDE = 3.0
LAB_KEYS = ("mp", "Lp", "mr", "Lr", "Rm", "km")


def envelope_rig(seed: int) -> tuple[riprs.FurutaParams, int, float]:
    """A rig drawn uniformly across the envelope, with its encoder counts and noise (rad)."""
    r = np.random.default_rng(seed)

    def u(a: float, b: float) -> float:
        return float(r.uniform(a, b))

    mp, lp, mr, lr, k = u(0.015, 0.08), u(0.08, 0.30), u(0.05, 0.15), u(0.06, 0.15), u(0.02, 0.08)
    params = riprs.FurutaParams(
        mp=mp,
        Lp=lp,
        mr=mr,
        Lr=lr,
        Jr=mr * lr**2 / 12 * u(0.5, 1.5),
        Jp=mp * lp**2 / 12 * u(0.5, 1.5),
        Rm=u(2.0, 10.0),
        kt=k,
        km=k,
        Dr=u(2e-4, 3e-3),
        Dp=u(1e-5, 2e-4),
        Vd=u(0.0, 1.0),
        Cr=u(0.0, 0.006),
        Cp=u(0.0, 5e-5),
    )
    return params, int(r.choice([512, 1024, 2048, 4096, 8192])), u(0.0, 2e-3)


def excitation_run(
    params: riprs.FurutaParams,
    signal: str,
    seed: int,
    *,
    duration: float = 30.0,
    counts: int = 2048,
    noise: float = 5e-4,
) -> tuple[np.ndarray, ...]:
    """``(t, theta, alpha, u)`` of an excitation run from hanging at rest, as rip-rt excite
    drives it (the signal through a 1 V/rad arm-centring pull on the measured arm angle; a
    free swing's kick and coast without it), through ``counts``-count encoders plus Gaussian
    noise, alpha wrapped to (-pi, pi]."""
    plant = riprs.Plant(params)
    rng = np.random.default_rng(seed)
    free = signal == "free-swing"
    if free:
        e = riprs.excitation(signal, dt=TS, duration=20.0, amplitude=FREE_AMPLITUDE)
    else:
        e = riprs.excitation(signal, dt=TS, duration=duration, amplitude=2.5, seed=seed)
    q = 2 * math.pi / counts
    x = np.array([0.0, 0.0, math.pi, 0.0])
    y = np.empty((len(e), 2))
    u = np.empty(len(e))
    for k in range(len(e)):
        y[k] = np.round(x[[0, 2]] / q) * q + rng.normal(0.0, noise, 2)
        u[k] = float(e[k] if free else np.clip(e[k] - y[k, 0], -10.0, 10.0))
        x = plant.step(x, u[k], TS, 10)
    alpha = np.remainder(y[:, 1] + math.pi, 2 * math.pi) - math.pi
    return np.arange(len(e)) * TS, y[:, 0], alpha, u


def write_log(path: Path, run: tuple[np.ndarray, ...], *, period_ms: int | None = 10) -> Path:
    t, theta, alpha, u = run
    lines = ["# rip-rt excite log"]
    if period_ms is not None:
        lines.append(f"# period_ms: {period_ms}")
    lines.append(COLUMNS)
    lines += [
        f"{t[k]:.3f},{k},{theta[k]:.17g},{alpha[k]:.17g},0,{u[k]:.17g},50,10,0"
        for k in range(len(t))
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def logs_of(d: Path, name: str, params: riprs.FurutaParams, seed: int = 1, **kw) -> list[Path]:
    return [
        write_log(d / f"{name}-{signal}.csv", excitation_run(params, signal, seed + i, **kw))
        for i, signal in enumerate(("chirp", "prbs", "free-swing"))
    ]


def lab_of(params: riprs.FurutaParams) -> dict[str, float]:
    return {k: getattr(params, k) for k in LAB_KEYS}


#: Bound on the relative error of the pendulum-damping entries A[1,3], A[3,3] (see
#: linearisation_error): quantisation and noise bias the split of a small pendulum friction
#: into viscous Dp and Coulomb Cp by up to about 15 % on some rigs (without them it is 0.2 %).
DAMPING_BOUND = 0.25


def linearisation_error(
    params: riprs.FurutaParams, truth: riprs.FurutaParams
) -> tuple[float, float, float]:
    """Largest relative error over the entries of the continuous upright [A B] that are not
    structural zeros, except the pendulum-damping column (A[1,3], A[3,3], set by Dp alone);
    the relative error of the unstable eigenvalue; the largest of the damping column."""
    up = [0.0, 0.0, 0.0, 0.0]
    a, b = riprs.Plant(params).linearize(up, 0.0)
    a0, b0 = riprs.Plant(truth).linearize(up, 0.0)
    got = np.hstack([a, np.reshape(b, (4, 1))])
    true = np.hstack([a0, np.reshape(b0, (4, 1))])
    rel = np.abs(got - true) / np.maximum(np.abs(true), 1e-300)
    mask = np.abs(true) > 1e-12
    damping = float(max(rel[1, 3], rel[3, 3]))
    mask[[1, 3], 3] = False
    lam, lam0 = np.linalg.eigvals(a).real.max(), np.linalg.eigvals(a0).real.max()
    return float(rel[mask].max()), abs(lam - lam0) / lam0, damping


def quiet_identify(*args, **kw) -> riprs.IdentifyResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return riprs.identify(*args, **kw)


# --- input sanity: refused before the fit, naming the log and the column ---------------------


@pytest.fixture(scope="module")
def chirp_run() -> tuple[np.ndarray, ...]:
    return excitation_run(QUBE, "chirp", 1, duration=12.0)


@pytest.mark.parametrize(
    ("case", "pattern"),
    [
        ("degrees", r"degrees: column 'theta' .* looks like degrees"),
        ("negated_voltage", r"negated_voltage: columns 'u' and 'theta' have opposite signs"),
        ("reversed_arm", r"reversed_arm: columns 'u' and 'theta' have opposite signs"),
        ("milliseconds", r"milliseconds: column 't' .*period_ms: 10.*milliseconds"),
        ("milliseconds_no_header", r"milliseconds_no_header: column 't' .*milliseconds"),
        ("wild", r"wild: column 'theta' has a wild sample at row 300 \(1e\+308"),
        ("wild_voltage", r"wild_voltage: column 'u' is 1e\+308 V at row 50"),
    ],
)
def test_wrong_units_and_signs_are_refused_naming_the_log_and_column(
    chirp_run, tmp_path, case, pattern
):
    t, theta, alpha, u = (c.copy() for c in chirp_run)
    header = 10
    if case == "degrees":
        theta, alpha = np.degrees(theta), np.degrees(alpha)
    elif case == "negated_voltage":
        u = -u
    elif case == "reversed_arm":
        theta = -theta
    elif case == "milliseconds":
        t = t * 1000
    elif case == "milliseconds_no_header":
        t, header = t * 1000, None
    elif case == "wild":
        theta[300] = 1e308
    elif case == "wild_voltage":
        u[50] = 1e308
    path = write_log(tmp_path / f"{case}.csv", (t, theta, alpha, u), period_ms=header)
    with pytest.raises(IdentifyError, match=pattern):
        riprs.identify([path])
    out = tmp_path / "rig.toml"
    assert main(["identify", str(path), "--out", str(out), "--no-plots"]) == 1
    assert not out.exists()


def test_the_unmodified_log_passes_the_checks(chirp_run, tmp_path):
    # The reference for the cases above: the same log as recorded is fitted.
    result = quiet_identify([write_log(tmp_path / "ok.csv", chirp_run)], max_iter=2)
    assert result.iterations > 0


def test_a_log_over_the_row_limit_is_refused_from_its_size_before_it_is_read(tmp_path):
    big = tmp_path / "huge.csv"
    row = "0.010,1,0.001,3.14,0,0.5,50,10,0\n"
    rows = riprs._riprs.IDENTIFY_MAX_SAMPLES + 100_000
    with big.open("w") as fh:
        fh.write(f"# rip-rt excite log\n# period_ms: 10\n{COLUMNS}\n")
        block = row * 100_000
        for _ in range(rows // 100_000):
            fh.write(block)
    started = time.perf_counter()
    with pytest.raises(IdentifyError, match=r"huge: the logs hold about \d+ samples"):
        riprs.identify([big])
    assert time.perf_counter() - started < 0.5


# --- held-out fit means something -----------------------------------------------------------


def test_a_held_out_part_without_motion_is_not_measurable(chirp_run, tmp_path):
    t, theta, alpha, u = (c.copy() for c in chirp_run)
    rest = len(t) * 3 // 4
    rng = np.random.default_rng(9)
    # The last quarter: the pendulum and arm at rest (encoder noise only), motor off.
    theta[rest:] = theta[rest] + rng.normal(0, 5e-4, len(t) - rest)
    alpha[rest:] = math.pi - 1e-3 + rng.normal(0, 5e-4, len(t) - rest)
    u[rest:] = 0.0
    result = quiet_identify([write_log(tmp_path / "rest.csv", (t, theta, alpha, u))], max_iter=3)
    assert np.isnan(result.fit_percent).all()
    assert (result.held_out_motion < 0.02).all()
    assert "not measurable" in result.report()
    assert "not measurable" in result.to_toml()
    assert "e+" not in result.to_toml().split("[plant]")[0]


# --- a bad fit is an error ------------------------------------------------------------------


@pytest.fixture(scope="module")
def heavy_logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    return logs_of(tmp_path_factory.mktemp("heavy"), "heavy", HEAVY)


def test_the_heavy_rig_from_the_default_start_is_refused_naming_what_to_measure(
    heavy_logs, tmp_path, capsys
):
    out = tmp_path / "rig.toml"
    code = main(["identify", *map(str, heavy_logs), "--out", str(out), "--no-plots"])
    captured = capsys.readouterr()
    assert code == 1
    assert not out.exists() and not identification_path(out).exists()
    names = "heavy-chirp.csv, heavy-prbs.csv, heavy-free-swing.csv"
    assert f"{names}: the identified model cannot be trusted" in captured.err
    assert "NOT TRUSTED" in captured.out
    assert "measure mp and Lp" in captured.out or "lab file" in captured.out
    # As data, and as an exception on request.
    result = quiet_identify(heavy_logs)
    assert not result.trusted and result.problems
    with pytest.raises(UntrustedIdentification) as info:
        quiet_identify(heavy_logs, strict=True)
    assert info.value.result.problems == result.problems
    # --force writes it, marked.
    forced = ["identify", *map(str, heavy_logs), "--out", str(out), "--no-plots", "--force"]
    assert main(forced) == 0
    assert "# UNTRUSTED" in out.read_text()
    side = tomllib.loads(identification_path(out).read_text())
    assert side["identification"]["trusted"] is False
    assert side["identification"]["problems"] == list(result.problems)


# --- the lab file ---------------------------------------------------------------------------


def write_lab(path: Path, values: dict[str, float]) -> Path:
    path.write_text("[lab]\n" + "".join(f"{k} = {v!r}\n" for k, v in values.items()))
    return path


def test_lab_file_errors_name_the_file_and_key(tmp_path):
    with pytest.raises(IdentifyError, match=r"lab.toml: lab.mass: unknown key"):
        read_lab(write_lab(tmp_path / "lab.toml", {"mass": 0.1}))
    with pytest.raises(IdentifyError, match=r"lab.toml: lab.Rm: must be a positive number"):
        read_lab(write_lab(tmp_path / "lab.toml", {"Rm": -8.4}))
    with pytest.raises(IdentifyError, match=r"lab.toml: lab.arm_counts: must be an integer"):
        read_lab(write_lab(tmp_path / "lab.toml", {"arm_counts": 20.5}))
    (tmp_path / "plain.toml").write_text("mp = 0.1\n")
    with pytest.raises(IdentifyError, match=r"plain.toml: a lab file holds one \[lab\] table"):
        read_lab(tmp_path / "plain.toml")


def test_the_heavy_rig_from_its_lab_file_is_identified_and_the_files_carry_it(
    heavy_logs, tmp_path
):
    lab = write_lab(tmp_path / "lab.toml", {**lab_of(HEAVY), "arm_counts": 2048})
    out = tmp_path / "rig.toml"
    assert main(["identify", *map(str, heavy_logs), "--out", str(out), "--no-plots",
                 "--lab", str(lab)]) == 0  # fmt: skip
    spec = riprs.load_config(out)
    entries, eig, damping = linearisation_error(spec.params, HEAVY)
    assert entries < 0.02 and eig < 0.01 and damping < DAMPING_BOUND, (entries, eig, damping)
    # The rig's own measured values, not the start set's.
    for key in LAB_KEYS:
        assert getattr(spec.params, key) == pytest.approx(getattr(HEAVY, key), rel=1e-12)
    assert spec.params.Vd == pytest.approx(HEAVY.Vd, rel=0.05)
    side = tomllib.loads(identification_path(out).read_text())
    assert side["identification"]["trusted"] is True
    assert side["lab"]["mp"] == HEAVY.mp and side["lab"]["arm_counts"] == 2048
    cov = np.array(side["covariance"]["log_covariance"])
    assert cov.shape == (9, 9) and np.allclose(cov, cov.T)
    assert side["covariance"]["parameters"][:3] == ["Lr", "J0", "Jalpha"]
    j_alpha = HEAVY.Jp + HEAVY.mp * HEAVY.Lp**2 / 4
    assert side["covariance"]["values"][2] == pytest.approx(j_alpha, rel=0.02)


def test_the_heavy_rig_is_recovered_over_noise_seeds(tmp_path):
    for seed in (11, 12, 13):
        logs = logs_of(tmp_path, f"heavy{seed}", HEAVY, seed=seed)
        result = quiet_identify(logs, lab=lab_of(HEAVY))
        entries, eig, damping = linearisation_error(result.params, HEAVY)
        assert result.trusted, (seed, result.problems)
        assert entries < 0.02 and eig < 0.01 and damping < DAMPING_BOUND, (seed, entries, eig)


ENVELOPE_SEEDS = (1, 2, 3, 4, 5, 6, 7, 8)


@pytest.mark.parametrize("seed", ENVELOPE_SEEDS)
def test_rigs_across_the_envelope_from_the_lab_file_and_from_the_default_start(
    tmp_path, seed, capsys
):
    params, counts, noise = envelope_rig(seed)
    logs = logs_of(tmp_path, f"rig{seed}", params, seed=seed, counts=counts, noise=noise)
    result = quiet_identify(logs, lab=lab_of(params))
    entries, eig, damping = linearisation_error(result.params, params)
    ad, bd = riprs.Plant(params).linearize_discrete(TS)
    worst_d = float(
        np.max(
            np.abs(np.hstack([result.Ad, result.Bd]) - np.hstack([ad, bd]))
            / np.maximum(np.abs(np.hstack([ad, bd])), 1e-12)
            * (np.abs(np.hstack([ad, bd])) > 1e-12)
        )
    )
    with capsys.disabled():
        print(
            f"\nrig {seed} ({counts} counts, {1e3 * noise:.2f} mrad): lab: [A B] "
            f"{100 * entries:.3f} %, damping column {100 * damping:.2f} %, eigenvalue "
            f"{100 * eig:.3f} %, [A_d B_d] {100 * worst_d:.3f} %"
        )
    assert result.trusted, result.problems
    assert entries < 0.02 and eig < 0.01 and damping < DAMPING_BOUND, (entries, eig, damping)
    # Without the lab file: the same bar, or a refusal.
    default = quiet_identify(logs)
    entries, eig, damping = linearisation_error(default.params, params)
    with capsys.disabled():
        print(
            f"rig {seed}: default start: {'trusted' if default.trusted else 'refused'}, "
            f"[A B] {100 * entries:.3f} %"
        )
    assert not default.trusted or (entries < 0.02 and eig < 0.01 and damping < DAMPING_BOUND), (
        entries,
        eig,
        damping,
    )

"""Monte Carlo studies that keep per-run metrics, not trajectories: every metric against the full
record of the same run (recomputed here with numpy), determinism per run index, argument errors,
and the memory of ``riprs compare --monte-carlo`` growing with the metrics only."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

import riprs
from riprs import Lqg, Lqr, Plant, simulate, simulate_metrics

OPTIONS = dict(
    reference=1.0,
    reference_time=0.5,
    x0=[0.0, 0.0, 0.05, 0.0],
    encoder_counts=2048,
    noise_std=2e-3,
)


def _settle_time(res: riprs.SimResult, band: float) -> float:
    """Earliest sample from which the arm error stays in the band, by brute force."""
    inside = np.abs(res.x[:, 0] - res.r[:, 0]) <= band
    if res.fell or not inside[-1]:
        return float("nan")
    outside = np.flatnonzero(~inside)
    first = 0 if len(outside) == 0 else outside[-1] + 1
    return float(res.t[first])


@pytest.mark.parametrize("make", [Lqr.paper, Lqg.paper])
def test_metrics_equal_those_of_the_full_records(make) -> None:
    plant, controller = Plant.paper(), make()
    m = simulate_metrics(plant, controller, 5, 3.0, seed=40, settle_band=0.05, **OPTIONS)
    assert len(m) == 5 and m.rmse.shape == (5, 3)
    assert list(m.run) == [0, 1, 2, 3, 4] and list(m.seed) == [40, 41, 42, 43, 44]
    for i in range(5):
        res = simulate(plant, controller, 3.0, seed=40 + i, **OPTIONS)
        # Independent recomputation of the Tab. 1 indices (measured angles) from the record.
        e_arm = res.y[:, 0] - res.r[:, 0]
        e_pend = res.y[:, 1] - res.r[:, 1]
        expected = [np.sqrt(np.mean(e**2)) for e in (e_arm, e_pend, res.u)]
        np.testing.assert_allclose(m.rmse[i], expected, rtol=1e-12)
        assert m.fell[i] == res.fell
        assert m.samples[i] == len(res.t)
        assert m.peak_voltage[i] == np.max(np.abs(res.u))
        assert m.fallbacks[i] == res.fallbacks
        np.testing.assert_equal(m.settle_time[i], _settle_time(res, 0.05))
        np.testing.assert_equal(m.fall_time[i], np.nan if res.fall_time is None else res.fall_time)
    assert np.isfinite(m.settle_time).any()


def test_a_fall_is_reported_with_its_time() -> None:
    weak = Lqr(np.zeros((1, 4)), 0.01)
    m = simulate_metrics(Plant.paper(), weak, 2, 5.0, x0=[0, 0, 0.1, 0])
    res = simulate(Plant.paper(), weak, 5.0, x0=[0, 0, 0.1, 0])
    assert m.fell.all() and res.fell
    assert m.fall_time[0] == res.fall_time and np.isnan(m.settle_time).all()
    assert m.samples[0] == len(res.t) < 500


def test_a_run_depends_on_its_index_only() -> None:
    kw = dict(seed=3, perturbation=0.1, parameters=["mr", "Lr", "Jp", "Dr"], **OPTIONS)
    whole = simulate_metrics(Plant.paper(), Lqg.paper(), 7, 2.0, **kw)
    head = simulate_metrics(Plant.paper(), Lqg.paper(), 3, 2.0, **kw)
    tail = simulate_metrics(Plant.paper(), Lqg.paper(), 4, 2.0, first_run=3, **kw)
    for field in ("run", "seed", "rmse", "fell", "peak_voltage", "settle_time", "samples"):
        np.testing.assert_array_equal(
            getattr(whole, field), np.concatenate([getattr(head, field), getattr(tail, field)])
        )
    # The perturbation changes the plant: a run differs from the nominal run with its seed.
    nominal = simulate_metrics(Plant.paper(), Lqg.paper(), 7, 2.0, seed=3, **OPTIONS)
    assert not np.array_equal(whole.rmse, nominal.rmse)


def test_progress_is_reported_and_the_controller_is_untouched() -> None:
    mpc = riprs.Mpc.paper(solver="active_set")
    before = mpc.x_hat.copy()
    calls: list[tuple[int, int]] = []
    simulate_metrics(Plant.paper(), mpc, 4, 1.0, progress=lambda d, n: calls.append((d, n)))
    np.testing.assert_array_equal(mpc.x_hat, before)
    assert all(n == 4 and 0 <= d <= 4 for d, n in calls)


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"runs": 0}, "runs"),
        ({"perturbation": 1.0}, "perturbation"),
        ({"parameters": ["mass"]}, "parameters"),
        ({"settle_band": 0.0}, "settle_band"),
        ({"substeps": 0}, "substeps"),
        ({"first_run": -1}, "first_run"),
        # The end of the range would wrap; the same rule as rip-core's batch::run_range.
        ({"first_run": 2**64 - 1}, "first_run"),
        # Only what [monte_carlo] may perturb: g is not a plant uncertainty.
        ({"parameters": ["g"]}, "parameters"),
    ],
)
def test_bad_arguments_name_themselves(kwargs, needle) -> None:
    args = {"runs": 2, **kwargs}
    with pytest.raises(riprs.RiprsError, match=needle):
        simulate_metrics(Plant.paper(), Lqr.paper(), args.pop("runs"), 1.0, **args)


MEMORY_SCRIPT = textwrap.dedent(
    """
    import resource, sys, tempfile, pathlib
    from riprs.cli import main
    tmp = pathlib.Path(tempfile.mkdtemp())
    cfg = tmp / "c.toml"
    cfg.write_text('controllers = ["LQR"]\\n')
    code = main(["compare", "--config", str(cfg), "--out", str(tmp / "out"),
                 "--monte-carlo", sys.argv[1], "--no-plots", "--quiet"])
    assert code == 0
    rows = (tmp / "out" / "monte_carlo.csv").read_text().count("\\n") - 1
    print(rows, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
    """
)


def _peak_rss_kib(runs: int) -> int:
    out = subprocess.run(
        [sys.executable, "-c", MEMORY_SCRIPT, str(runs)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()[-2:]
    assert int(out[0]) == runs
    return int(out[1])


@pytest.mark.slow
def test_monte_carlo_memory_grows_with_the_metrics_only() -> None:
    # Keeping each 10 s LQR record (about 0.18 MB) added some 550 MB between these two studies;
    # the metrics of 3 000 runs are well under 1 MB.
    small, large = _peak_rss_kib(100), _peak_rss_kib(3100)
    assert large - small < 100 * 1024, (small, large)

"""`riprs campaign`: run mapping, metrics, resume, refusal of a changed spec, bad specs, and a
real Dask cluster (a scheduler and two workers as processes) that loses a worker mid-way."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

# The test extra installs the campaign extra (pyarrow, distributed): a broken install must fail
# here, not skip.
import distributed  # noqa: F401
import numpy as np
import pyarrow  # noqa: F401
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import riprs
import riprs.config
from riprs import campaign
from riprs.compare import build_controllers

_experiment = riprs.config.Spec.from_dict

SMALL = """
[campaign]
controllers = ["LQR", "MPC"]
seeds = 2
duration = 3.0
seed = 7
chunk_size = 5

[[campaign.axis]]
name = "mp"
scale = [0.6, 1.4]
points = 3

[[campaign.axis]]
name = "noise_std"
values = [0.001, 0.004]

[[campaign.axis]]
name = "lqr.R"
range = [0.05, 0.2]
points = 2

[sensor]
encoder_counts = [4096, 4096]
"""


def _spec(tmp_path: Path, text: str, name: str = "spec.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _column(table, name):
    return table.column(name).to_numpy(zero_copy_only=False)


def _settle_time(t, theta, ref, band):
    """Independent reference: walk back from the end while the arm is inside the band."""
    k = len(t)
    while k > 0 and abs(theta[k - 1] - ref[k - 1]) <= band:
        k -= 1
    return None if k == len(t) else t[k]


def test_example_spec_is_the_papers_question(capsys):
    from riprs.cli import main

    assert main(["campaign", "--example"]) == 0
    printed = capsys.readouterr().out
    assert printed == campaign.EXAMPLE_SPEC
    # One definition: the modules that use it import it from spec.py.
    from riprs.campaign import chunk, engine, spec, store

    assert [m.__name__ for m in (chunk, engine, store) if "EXAMPLE_SPEC" in vars(m)] == []
    assert spec.EXAMPLE_SPEC is campaign.EXAMPLE_SPEC
    c = campaign.load_spec(tomllib.loads(printed))
    assert c.controllers == ["LQR", "LQG", "MPC"]
    assert [a.parameter for a in c.axes] == ["mp", "Lr"]
    np.testing.assert_allclose(c.axes[0].values, np.linspace(0.7, 1.3, 13))
    assert c.runs == 3 * 13 * 9 * 20


def test_each_run_is_the_simulation_its_index_names():
    """Rows against riprs.simulate with the inputs decoded by hand from the module's rule
    run = (c * P + p) * S + s, noise seed = seed + p * S + s."""
    c = campaign.load_spec(tomllib.loads(SMALL))
    assert c.runs == 2 * 12 * 2
    cols = campaign.compute_chunk(c, 0, c.runs)
    mp0 = riprs.FurutaParams.paper().mp
    for run in (0, 5, 17, 26, 47):
        ctrl, rest = divmod(run, 24)
        point, s = divmod(rest, 2)
        i_mp, i_noise, i_r = np.unravel_index(point, (3, 2, 2))
        mp = [0.6, 1.0, 1.4][i_mp]
        noise = [0.001, 0.004][i_noise]
        R = [0.05, 0.2][i_r]
        name = ["LQR", "MPC"][ctrl]
        cfg = _experiment(
            {
                "controllers": [name],
                "sensor": {"encoder_counts": [4096, 4096], "noise_std": [noise, noise]},
                "lqr": {"R": R},
            }
        )
        controller = build_controllers(cfg)[name]
        ref = riprs.simulate(
            riprs.FurutaParams.paper().replace(mp=mp0 * mp),
            controller,
            3.0,
            reference=1.0,
            reference_time=1.0,
            encoder_counts=4096,
            noise_std=noise,
            x0=[0.0, 0.0, 0.05, 0.0],
            seed=7 + point * 2 + s,
        )
        assert cols["controller"][run] == name
        assert (cols["mp"][run], cols["noise_std"][run], cols["lqr.R"][run]) == (mp, noise, R)
        assert cols["noise_seed"][run] == 7 + point * 2 + s
        np.testing.assert_array_equal(
            [cols["rmse_arm"][run], cols["rmse_pendulum"][run], cols["rmse_voltage"][run]],
            ref.rmse,
        )
        assert cols["fell"][run] == ref.fell
        assert cols["diverged"][run] == ref.diverged
        assert cols["peak_voltage"][run] == np.max(np.abs(ref.u))
        expected = _settle_time(ref.t, ref.x[:, 0], ref.r[:, 0], 0.02)
        if ref.fell or expected is None:
            assert np.isnan(cols["settle_time"][run])
        else:
            assert cols["settle_time"][run] == pytest.approx(expected, abs=1e-12)
    # The LQR design sees lqr.R: the two weights give different runs on equal inputs.
    assert cols["rmse_voltage"][0] != cols["rmse_voltage"][2]


def test_plant_axes_scale_the_base_plant_and_leave_the_design_alone():
    c = campaign.load_spec(
        tomllib.loads(
            """
[campaign]
controllers = ["LQG"]
duration = 2.0
[[campaign.axis]]
name = "mp"
scale = [0.5, 1.5]
points = 2
[plant]
preset = "qube_servo2"
mp = 0.03
"""
        )
    )
    cols = campaign.compute_chunk(c, 0, 2)
    spec = _experiment({"controllers": ["LQG"], "plant": {"preset": "qube_servo2", "mp": 0.03}})
    controller = build_controllers(spec)["LQG"]
    for run, factor in ((0, 0.5), (1, 1.5)):
        ref = riprs.simulate(
            riprs.FurutaParams.qube_servo2().replace(mp=0.03 * factor),
            controller,
            2.0,
            reference=1.0,
            reference_time=1.0,
            encoder_counts=2048,
            noise_std=1e-3,
            x0=[0.0, 0.0, 0.05, 0.0],
            seed=run,
        )
        assert cols["mp"][run] == factor
        np.testing.assert_array_equal(
            [cols["rmse_arm"][run], cols["rmse_pendulum"][run], cols["rmse_voltage"][run]],
            ref.rmse,
        )


def test_chunking_and_engine_order_do_not_change_results(tmp_path):
    c = campaign.load_spec(tomllib.loads(SMALL))
    whole = campaign.compute_chunk(c, 0, c.runs)
    res = campaign.run(c, chunk_size=7, progress=False, plots=False)
    assert res.chunk_size == 7 and c.chunk_size == 5
    assert _column(res.table, "run").tolist() == list(range(c.runs))
    for name in ("rmse_arm", "rmse_pendulum", "rmse_voltage", "peak_voltage", "fell"):
        np.testing.assert_array_equal(_column(res.table, name), whole[name])


def test_automatic_chunks_are_large_yet_four_per_worker_thread():
    from riprs.campaign.engine import _auto_chunk_size

    assert _auto_chunk_size(7020, 1) == 256
    assert _auto_chunk_size(400, 2) == 50
    assert _auto_chunk_size(10, 8) == 16
    c = campaign.load_spec(tomllib.loads(SMALL.replace("chunk_size = 5", "")))
    assert c.chunk_size is None
    threads = max(2, os.cpu_count() or 1)
    assert campaign.run(c, progress=False, plots=False).chunk_size == max(
        16, -(-48 // (4 * threads))
    )


def _run_cli(args, **kwargs):
    return subprocess.Popen(
        [sys.executable, "-m", "riprs.cli", "campaign", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kwargs,
    )


def test_ctrl_c_keeps_finished_chunks_and_the_same_command_resumes(tmp_path):
    spec = _spec(
        tmp_path,
        """
[campaign]
controllers = ["LQR", "LQG"]
seeds = 40
duration = 2.0
chunk_size = 20

[[campaign.axis]]
name = "Lr"
scale = [0.9, 1.1]
points = 50
""",
    )
    out = tmp_path / "out"
    proc = _run_cli([str(spec), "--out", str(out), "--quiet", "--no-plots"])
    try:
        deadline = time.monotonic() + 120
        while not list((out / "runs").glob("part-*.parquet")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk written in 120 s"
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    partial = campaign.load(out)
    c = campaign.load_spec(spec)
    assert 0 < partial.num_rows < c.runs
    assert not [p for p in (out / "runs").iterdir() if not p.name.startswith("part-")]

    # As a process killed mid-write (SIGKILL) would leave it: ignored, then removed.
    stale = out / "runs" / ".part-0000000000-0000000020.parquet.1.tmp"
    stale.write_bytes(b"PAR1 half a file")
    result = campaign.run(spec, out, progress=False, plots=False)
    assert not stale.exists()
    runs = _column(result.table, "run")
    assert runs.tolist() == list(range(c.runs))
    assert 0 < result.chunks < -(-c.runs // 20)  # only the missing chunks ran
    # Rows written before the interrupt equal a fresh computation of the same runs.
    first = int(_column(partial, "run")[0])
    fresh = campaign.compute_chunk(c, first, first + 20)
    np.testing.assert_array_equal(_column(partial, "rmse_arm")[:20], fresh["rmse_arm"])


@pytest.mark.slow
def test_ctrl_c_stops_long_chunks_on_pool_threads_promptly(tmp_path):
    # Hour-long runs: every chunk is still inside its native batch when SIGINT arrives, on a
    # pool thread that never sees the signal itself. Uninterrupted, this takes minutes.
    spec = _spec(
        tmp_path,
        """
[campaign]
controllers = ["LQR"]
seeds = 240
duration = 3600.0
chunk_size = 12
""",
    )
    out = tmp_path / "out"
    proc = _run_cli([str(spec), "--out", str(out), "--quiet", "--no-plots"])
    try:
        deadline = time.monotonic() + 300
        while not list((out / "runs").glob("part-*.parquet")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no chunk written in 300 s"
            time.sleep(0.05)
        before = len(list((out / "runs").glob("part-*.parquet")))
        proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            pytest.fail("Ctrl-C did not end the campaign within 10 s")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "Traceback" not in err
    parts = list((out / "runs").glob("part-*.parquet"))
    assert len(parts) >= before
    assert 0 < campaign.load(out).num_rows < 240
    assert not [p for p in (out / "runs").iterdir() if not p.name.startswith("part-")]


def _interrupted_after_two_chunks(tmp_path):
    """SMALL run into ``tmp_path/out`` and interrupted (KeyboardInterrupt from ``on_chunk``)
    once two of its 5-run chunks are on disk."""
    c = campaign.load_spec(tomllib.loads(SMALL))
    out = tmp_path / "out"

    def stop_after_two(done, total):
        if done >= 10:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        campaign.run(c, out, progress=False, plots=False, on_chunk=stop_after_two)
    return c, out


def test_interrupt_from_python_then_resume_equals_one_uninterrupted_run(tmp_path):
    c, out = _interrupted_after_two_chunks(tmp_path)
    assert 0 < campaign.load(out).num_rows < c.runs
    with pytest.raises(campaign.CampaignError, match="'Lr' is not an axis"):
        campaign.run(c, out, map_axes=("mp", "Lr"))
    resumed = campaign.run(c, out, progress=False, plots=True, map_axes=("noise_std", "mp"))
    assert resumed.chunks < -(-c.runs // c.chunk_size)
    reference = campaign.run(c, progress=False, plots=False)
    assert resumed.table.equals(reference.table)
    names = {p.name for p in resumed.files}
    for stem in ("fall_rate_map", "rmse_pendulum_map", "marginals"):
        assert {f"{stem}.png", f"{stem}.svg"} <= names


def _brute_means(rows, controllers, group, metric):
    """Per controller and combination of the values of ``group``, the mean by hand: the fall
    rate over every run, an RMSE over the runs that neither fell nor diverged."""
    cells: dict = {}
    for r in rows:
        key = (r["controller"], *(r[n] for n in group))
        if metric == "fall_rate":
            cells.setdefault(key, []).append(float(r["fell"]))
        elif not (r["fell"] or r["diverged"]):
            cells.setdefault(key, []).append(r[metric])
    values = [sorted({r[n] for r in rows}) for n in group]
    shape = (len(controllers), *(len(v) for v in values))
    mean = np.full(shape, np.nan)
    for key, xs in cells.items():
        along = (v.index(x) for v, x in zip(values, key[1:], strict=True))
        mean[(controllers.index(key[0]), *along)] = sum(xs) / len(xs)
    return values, mean


def test_a_resumed_campaign_is_summarised_chunk_by_chunk_without_loading_every_row(
    tmp_path, monkeypatch
):
    from riprs.campaign import engine as campaign_engine

    c, out = _interrupted_after_two_chunks(tmp_path)

    def load_every_row(*args, **kwargs):
        raise AssertionError("run() read every row into one table")

    monkeypatch.setattr(campaign_engine, "load", load_every_row)
    resumed = campaign.run(c, out, progress=False, plots=True)
    monkeypatch.undo()
    assert resumed.aggregates.runs == c.runs and len(resumed.files) == 6
    rows = campaign.load(out).to_pylist()
    for group in [(), ("mp",), ("noise_std",), ("lqr.R",), ("mp", "noise_std")]:
        for metric in ("fall_rate", "rmse_arm", "rmse_pendulum", "rmse_voltage"):
            names, values, mean = resumed.aggregates.aggregate(group, metric)
            want_values, want = _brute_means(rows, ["LQR", "MPC"], group, metric)
            assert names == ["LQR", "MPC"]
            for v, w in zip(values, want_values, strict=True):
                np.testing.assert_array_equal(v, w)
            np.testing.assert_allclose(mean, want, rtol=1e-12, equal_nan=True)
    assert campaign.summary(resumed.aggregates) == campaign.summary(campaign.load(out))
    assert resumed.table.num_rows == c.runs  # read from disk only when asked for


def test_a_resume_records_each_session_and_refuses_another_riprs_version(tmp_path):
    c = campaign.load_spec(tomllib.loads(SMALL))
    out = tmp_path / "out"
    path = out / "manifest.json"
    campaign.run(c, out, progress=False, plots=False)
    first = json.loads(path.read_text())
    assert first["versions"]["riprs"] == riprs.__version__
    assert [s["engine"] for s in first["sessions"]] == ["in-process"]
    # Other packages may change between sessions: each session's versions are kept.
    first["versions"]["numpy"] = first["sessions"][0]["versions"]["numpy"] = "0.0-old"
    path.write_text(json.dumps(first))
    campaign.run(c, out, progress=False, plots=False)
    second = json.loads(path.read_text())
    assert second["versions"]["numpy"] == "0.0-old"
    assert [s["versions"]["numpy"] for s in second["sessions"]] == ["0.0-old", np.__version__]
    # Another riprs computed the runs on disk: refused, both versions named, nothing touched.
    second["versions"]["riprs"] = "0.0.1-old"
    path.write_text(json.dumps(second))
    before = (path.read_bytes(), sorted(os.listdir(out / "runs")))
    with pytest.raises(campaign.CampaignError) as info:
        campaign.run(c, out, progress=False, plots=False)
    message = str(info.value)
    assert "riprs 0.0.1-old" in message and f"riprs {riprs.__version__}" in message
    assert "another --out" in message and str(out) in message
    assert (path.read_bytes(), sorted(os.listdir(out / "runs"))) == before


def test_dask_holds_a_bounded_window_of_chunks_in_flight():
    from distributed import Client, LocalCluster

    from riprs.campaign.engine import _on_dask
    from riprs.campaign.store import _pending

    c = campaign.load_spec(tomllib.loads(SMALL))
    # Chunks are generated as they are taken, never listed: 10**15 one-run chunks cost nothing.
    assert next(_pending([(0, 3)], 10**15, 1)) == (3, 4)
    chunks = list(_pending([], c.runs, 2))
    assert len(chunks) == 24
    got: dict = {}
    most = 0
    with (
        LocalCluster(
            n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0"
        ) as cluster,
        Client(cluster, set_as_default=False) as client,
    ):
        submitted = []
        submit = client.submit

        def counting_submit(*args, **kwargs):
            submitted.append(args[2:4])
            return submit(*args, **kwargs)

        client.submit = counting_submit
        for chunk, columns in _on_dask(c, chunks, client, 3):
            # In flight: submitted, not finished (this one has).
            most = max(most, len(submitted) - len(got) - 1)
            got[chunk] = columns
    assert 1 < most <= 3
    assert sorted(got) == chunks and sorted(submitted) == chunks
    whole = campaign.compute_chunk(c, 0, c.runs)
    for (a, b), columns in got.items():
        np.testing.assert_array_equal(columns["rmse_pendulum"], whole["rmse_pendulum"][a:b])


def test_map_cells_average_the_runs_they_hold():
    from riprs.campaign.plots import aggregate

    c = campaign.load_spec(tomllib.loads(SMALL))
    table = campaign.run(c, progress=False, plots=False).table
    rows = table.to_pylist()
    names, (mp, noise), fall = aggregate(table, ("mp", "noise_std"), "fall_rate")
    _, _, pend = aggregate(table, ("mp", "noise_std"), "rmse_pendulum")
    assert names == ["LQR", "MPC"]
    for k, name in enumerate(names):
        for i, m in enumerate(mp):
            for j, n in enumerate(noise):
                key = (name, m, n)
                cell = [r for r in rows if (r["controller"], r["mp"], r["noise_std"]) == key]
                assert len(cell) == 4  # two seeds x two lqr.R values
                assert fall[k, i, j] == sum(r["fell"] for r in cell) / 4
                up = [r["rmse_pendulum"] for r in cell if not r["fell"]]
                if up:
                    assert pend[k, i, j] == pytest.approx(sum(up) / len(up), rel=1e-12)
                else:
                    assert np.isnan(pend[k, i, j])


def test_a_changed_spec_is_refused_and_nothing_is_touched(tmp_path):
    spec = _spec(tmp_path, SMALL)
    out = tmp_path / "out"
    campaign.run(spec, out, progress=False, plots=False)
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
    changed = _spec(tmp_path, SMALL.replace("seeds = 2", "seeds = 3"), "changed.toml")
    with pytest.raises(campaign.CampaignError, match="another spec"):
        campaign.run(changed, out, progress=False)
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == before
    # A second process writing the same directory is refused while the first holds it.
    from riprs.campaign.store import _exclusive

    with _exclusive(out), pytest.raises(campaign.CampaignError, match="another riprs campaign"):
        campaign.run(spec, out, progress=False)
    # The chunk size is not part of the spec's identity: a new one resumes (nothing to do).
    rechunked = _spec(tmp_path, SMALL.replace("chunk_size = 5", "chunk_size = 9"), "r.toml")
    assert campaign.run(rechunked, out, progress=False, plots=False).chunks == 0


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[campaign]\nseeds = 0\n", "campaign.seeds"),
        ("[campaign]\nseed = 9223372036854775807\n", "campaign.seed"),
        ("[campaign]\nsneeds = 2\n", "campaign.sneeds"),
        ('[campaign]\ncontrollers = ["LQR", "PID"]\n', "campaign.controllers[1]"),
        ("[campaign]\nduration = -1.0\n", "campaign.duration"),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mpp"\nscale = [0.9, 1.1]\npoints = 3\n',
            "campaign.axis[0].name",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mp"\nscale = [0.9, 1.1]\npoint = 3\n',
            "campaign.axis[0].point",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mp"\nscale = [1.1, 0.9]\npoints = 3\n',
            "campaign.axis[0].scale",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mp"\nscale = [0.9, 1.1]\npoints = 0\n',
            "campaign.axis[0].points",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mp"\nscale = [-1.0, 1.1]\npoints = 3\n',
            "campaign.axis[0].scale",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mp"\nvalues = [1.0]\n'
            '[[campaign.axis]]\nname = "mp"\nvalues = [2.0]\n',
            "campaign.axis[1].name",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mpc.solver"\nvalues = [1.0]\n',
            "campaign.axis[0].name",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mpc.prediction_horizon"\nvalues = [0, 10]\n',
            "mpc.prediction_horizon",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "mpc.control_horizon"\nvalues = [3, 60]\n',
            "mpc.control_horizon",
        ),
        ("[campaign]\n[mpc]\nprediction_horizn = 10\n", "mpc.prediction_horizn"),
        ("[mpc]\nprediction_horizon = 10\n", "[campaign]"),
        (
            '[campaign]\n[[campaign.axis]]\nname = "sensor.encoder_counts"\n'
            "values = [512, 4096.5]\n",
            "campaign.axis[0].values",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "Dp"\nrange = [-1.0, 0.0]\npoints = 2\n',
            "campaign.axis[0]",
        ),
        # Axes over one setting (a list and its entry, an alias and the list it indexes).
        (
            '[campaign]\n[[campaign.axis]]\nname = "sensor.noise_std"\nscale = [0.5, 2.0]\n'
            'points = 2\n[[campaign.axis]]\nname = "sensor.noise_std[0]"\nvalues = [0.0, 0.01]\n',
            "campaign.axis[1].name",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "initial_tilt"\nvalues = [0.05, 0.1]\n'
            '[[campaign.axis]]\nname = "plant.initial_state"\nscale = [0.5, 2.0]\npoints = 2\n',
            "campaign.axis[1].name",
        ),
        (
            '[campaign]\n[[campaign.axis]]\nname = "plant.initial_state[2]"\nvalues = [0.05]\n'
            '[[campaign.axis]]\nname = "initial_tilt"\nvalues = [0.1]\n',
            "campaign.axis[1].name",
        ),
        # Settings the runs never read.
        (
            '[campaign]\n[[campaign.axis]]\nname = "reference.duration"\nvalues = [5.0, 10.0]\n',
            "campaign.duration",
        ),
        ('controllers = ["LQR"]\n[campaign]\n', "campaign.controllers"),
        ("[campaign]\n[monte_carlo]\nruns = 10\n", "'monte_carlo'"),
    ],
)
def test_bad_specs_name_the_key(tmp_path, text, key):
    spec = _spec(tmp_path, text)
    with pytest.raises(riprs.RiprsError) as info:
        campaign.run(spec, tmp_path / "out", progress=False)
    assert key in str(info.value)
    assert str(spec) in str(info.value)
    assert not (tmp_path / "out").exists()


def test_integer_settings_and_random_axes_follow_the_spec():
    c = campaign.load_spec(
        tomllib.loads(
            """
[campaign]
seed = 3
[[campaign.axis]]
name = "mpc.prediction_horizon"
scale = [0.4, 1.0]
points = 3
[[campaign.axis]]
name = "initial_tilt"
range = [0.0, 0.2]
samples = 4
"""
        )
    )
    horizon, tilt = c.axes
    # Factors on the base horizon (50) that land on whole steps: 20, 35, 50.
    np.testing.assert_allclose(horizon.values * 50, [20, 35, 50])
    assert c.config_for((1, 0)).mpc.prediction_horizon == 35
    expected = np.sort(np.random.default_rng([3, 1]).uniform(0.0, 0.2, 4))
    np.testing.assert_array_equal(tilt.values, expected)
    assert c.config_for((0, 2)).plant.initial_state[2] == expected[2]


def test_missing_extra_is_one_line_saying_what_to_install(tmp_path, monkeypatch):
    spec = _spec(tmp_path, SMALL)
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(campaign.CampaignError) as info:
        campaign.run(spec, tmp_path / "a", workers=2, progress=False)
    assert "pip install 'riprs[campaign]'" in str(info.value) and "\n" not in str(info.value)
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    with pytest.raises(campaign.CampaignError, match=r"pip install 'riprs\[campaign\]'"):
        campaign.run(spec, tmp_path / "b", progress=False)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_local_dask_cluster_gives_the_in_process_results(tmp_path):
    c = campaign.load_spec(tomllib.loads(SMALL))
    on_cluster = campaign.run(c, tmp_path / "out", workers=2, progress=False, plots=False)
    assert on_cluster.engine == "dask local cluster, 2 workers"
    manifest = (tmp_path / "out" / "manifest.json").read_text()
    assert '"distributed"' in manifest and c.spec_hash in manifest
    assert on_cluster.table.equals(campaign.run(c, progress=False, plots=False).table)


def test_an_unreachable_scheduler_fails_before_any_work(tmp_path):
    spec = _spec(tmp_path, SMALL)
    address = f"tcp://127.0.0.1:{_free_port()}"
    with pytest.raises(campaign.CampaignError, match="cannot reach the Dask scheduler"):
        campaign.run(spec, tmp_path / "out", scheduler=address, connect_timeout=2)
    assert not (tmp_path / "out").exists()
    with pytest.raises(campaign.CampaignError, match="tcp://HOST:PORT"):
        campaign.run(spec, tmp_path / "out", scheduler="127.0.0.1:8786")


@pytest.mark.parametrize(
    "address",
    [
        "tcp://127.0.0.1",
        "tcp://127.0.0.1:notaport",
        "tcp://127.0.0.1:0",
        "tcp://127.0.0.1:65536",
        "tcp://:8786",
        "http://127.0.0.1:8786",
    ],
)
def test_a_malformed_scheduler_address_is_named_before_any_work(tmp_path, address):
    spec = _spec(tmp_path, SMALL)
    with pytest.raises(campaign.CampaignError, match="tcp://HOST:PORT") as info:
        campaign.run(spec, tmp_path / "out", scheduler=address)
    assert repr(address) in str(info.value)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("address", "expected"),
    [
        ("tcp://127.0.0.1", "--scheduler must be an address like tcp://HOST:PORT"),
        ("tcp://127.0.0.1:notaport", "--scheduler must be an address like tcp://HOST:PORT"),
        (None, "cannot reach the Dask scheduler"),
    ],
)
def test_the_cli_names_a_bad_scheduler_and_exits_cleanly(tmp_path, address, expected):
    """One line, no traceback from a half-built client at exit (None: a closed local port)."""
    address = address or f"tcp://127.0.0.1:{_free_port()}"
    spec = _spec(tmp_path, SMALL)
    proc = _run_cli([str(spec), "--out", str(tmp_path / "out"), "--scheduler", address])
    _, err = proc.communicate(timeout=300)
    assert proc.returncode != 0
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert expected in lines[0] and address in lines[0]
    assert not (tmp_path / "out").exists()


@contextlib.contextmanager
def _not_a_scheduler(answer: bytes | None):
    """A local TCP port that accepts connections and writes ``answer`` on each (None: says
    nothing); yields its address and the list of accepted connections."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.1)
    accepted: list[socket.socket] = []
    stop = threading.Event()

    def serve():
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                continue
            accepted.append(conn)
            if answer is not None:
                with contextlib.suppress(OSError):
                    conn.sendall(answer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}", accepted
    finally:
        stop.set()
        thread.join()
        for conn in accepted:
            conn.close()
        server.close()


@pytest.mark.slow
@pytest.mark.parametrize(
    "answer",
    [
        # The length of a Dask message (64 kB) and then only part of it.
        (65536).to_bytes(8, "little") + b"\x00" * 100,
        b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n" + bytes(range(256)) * 8,
        None,
    ],
    ids=["truncated-frame", "http", "silent"],
)
def test_a_port_that_is_not_a_scheduler_is_one_line_in_bounded_time(tmp_path, answer):
    spec = _spec(tmp_path, SMALL)
    with _not_a_scheduler(answer) as (address, _):
        proc = _run_cli([str(spec), "--out", str(tmp_path / "out"), "--scheduler", address])
        try:
            # The default connection timeout is 10 s; a hang fails here, not the whole run.
            _, err = proc.communicate(timeout=120)
        finally:
            proc.kill()
    assert proc.returncode not in (0, None)
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert "cannot reach the Dask scheduler" in lines[0] and address in lines[0]
    assert not (tmp_path / "out").exists()


def test_ctrl_c_ends_the_wait_for_a_scheduler_that_never_answers(tmp_path):
    spec = _spec(tmp_path, SMALL)
    with _not_a_scheduler(None) as (address, accepted):
        proc = _run_cli([str(spec), "--out", str(tmp_path / "out"), "--scheduler", address])
        try:
            deadline = time.monotonic() + 120
            # The plain connection check, then the handshake that gets no answer.
            while len(accepted) < 2:
                assert proc.poll() is None and time.monotonic() < deadline, proc.stderr
                time.sleep(0.05)
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=60)
        finally:
            proc.kill()
    # 130: ended by the interrupt, not by the 10 s connection timeout (exit 1, "cannot reach").
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "cannot reach" not in err, err


DASK_SPEC = """
[campaign]
controllers = ["LQR", "LQG"]
seeds = 30
duration = 1.5
chunk_size = 40

[[campaign.axis]]
name = "mp"
scale = [0.6, 1.4]
points = 9

[[campaign.axis]]
name = "Lr"
scale = [0.85, 1.15]
points = 5
"""


@pytest.fixture
def dask_cluster(tmp_path):
    """A `dask scheduler` and two `dask worker` processes on 127.0.0.1 (no nanny, so killing a
    worker's process is losing the worker); every process is ended on any outcome."""
    dask = [sys.executable, "-m", "dask", "scheduler"]
    worker_cmd = [sys.executable, "-m", "dask", "worker"]
    scheduler_file = tmp_path / "scheduler.json"
    env = {**os.environ, "RAYON_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    procs: list[subprocess.Popen] = []
    logs = []

    def start(cmd, name):
        log = open(tmp_path / f"{name}.log", "w")
        logs.append(log)
        procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env))
        return procs[-1]

    try:
        start(
            [
                *dask,
                "--host",
                "127.0.0.1",
                "--port",
                str(_free_port()),
                "--no-dashboard",
                "--scheduler-file",
                str(scheduler_file),
            ],
            "scheduler",
        )
        deadline = time.monotonic() + 90
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            assert procs[0].poll() is None, (tmp_path / "scheduler.log").read_text()
            assert time.monotonic() < deadline, "scheduler did not start in 90 s"
            time.sleep(0.1)
        import json

        address = json.loads(scheduler_file.read_text())["address"]
        workers = [
            start(
                [
                    *worker_cmd,
                    address,
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    "--no-dashboard",
                    "--memory-limit",
                    "0",
                    "--name",
                    f"w{i}",
                    "--host",
                    "127.0.0.1",
                ],
                f"worker{i}",
            )
            for i in range(2)
        ]
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=90)
        yield address, workers
    finally:
        for p in reversed(procs):
            with contextlib.suppress(ProcessLookupError):
                p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=20)
        for log in logs:
            log.close()


def test_a_worker_killed_mid_campaign_costs_no_run(tmp_path, dask_cluster):
    address, workers = dask_cluster
    spec = _spec(tmp_path, DASK_SPEC)
    c = campaign.load_spec(spec)
    assert c.runs == 2 * 45 * 30
    killed_at: list[int] = []

    def kill_one_worker(done, total):
        if not killed_at and done >= 6 * 40:
            workers[1].kill()
            workers[1].wait(timeout=30)
            killed_at.append(done)

    out = tmp_path / "out"

    def hung(signum, frame):
        raise TimeoutError("the campaign did not end within 600 s of a worker's death")

    # A hang must fail this test, not stall the whole run (the handler runs on this thread).
    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(600)
    try:
        result = campaign.run(
            spec, out, scheduler=address, progress=False, plots=False, on_chunk=kill_one_worker
        )
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    assert killed_at and killed_at[0] < c.runs, "the worker was not killed mid-way"
    assert workers[1].returncode is not None
    table = campaign.load(out)
    runs = _column(table, "run")
    assert len(runs) == c.runs and np.array_equal(np.sort(runs), np.arange(c.runs))
    in_process = campaign.run(spec, progress=False, plots=False)
    assert table.equals(in_process.table)
    assert result.table.equals(table)
    assert "dask" in result.engine


def test_a_setting_that_cannot_be_designed_fails_before_any_run_naming_axis_and_value(tmp_path):
    spec = _spec(
        tmp_path,
        """
[campaign]
controllers = ["MPC"]
seeds = 10
duration = 1.0
chunk_size = 10

[[campaign.axis]]
name = "mpc.output_weights"
values = [25.0, 1e300]
""",
    )
    out = tmp_path / "out"
    with pytest.raises(campaign.CampaignError, match=r"mpc\.output_weights = 1e\+?300"):
        campaign.run(spec, out, progress=False, plots=False)
    assert not list(out.glob("runs/part-*"))


def test_a_huge_grid_is_refused_with_its_true_run_count():
    axes = [{"name": n, "range": [0.1, 0.2], "points": 65536} for n in ("lqr.R", "noise_std")]
    axes += [{"name": n, "scale": [0.9, 1.1], "points": 65536} for n in ("mp", "Lr")]
    spec = {"campaign": {"controllers": ["LQR"], "seeds": 1, "duration": 1.0, "axis": axes}}
    with pytest.raises(campaign.CampaignError, match=f"has {65536**4} runs"):
        campaign.load_spec(spec)


def test_a_spec_file_that_is_not_utf8_is_one_named_error(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'[campaign]\ncontrollers = ["LQR"] # \xe9\n')
    with pytest.raises(campaign.CampaignError, match="invalid TOML"):
        campaign.run(path, tmp_path / "out", progress=False, plots=False)


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--chunk-size", "0"], "--chunk-size"),
        (["--workers", "0"], "--workers"),
        (["--map", "mp"], "--map"),
    ],
)
def test_cli_errors_name_the_option(tmp_path, args, flag):
    spec = _spec(tmp_path, SMALL)
    proc = _run_cli([str(spec), "--out", str(tmp_path / "out"), "--quiet", *args])
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, err
    assert err.startswith(f"riprs: error: {flag} ") and "Traceback" not in err, err

"""Campaign throughput: runs/s per core in process vs. through a local Dask cluster, for LQR and
MPC, and the overhead of one chunk through the cluster.

    python benches/campaign_bench.py [--repeats 3] [--runs 400] [--chunk-size N]

Each figure is the median of ``--repeats`` repetitions. Chunks are sized as ``riprs campaign``
sizes them (automatic: large, yet four per worker thread) unless ``--chunk-size`` is given. A
run is the paper's 10 s experiment (the nominal design on a plant whose pendulum mass is off by
up to +-30 %). The cluster is a ``LocalCluster`` of one worker process per core, one thread
each, started once and reused, so its start-up is not counted. Overhead per chunk is the
median round trip of a one-run chunk through the cluster minus the same chunk computed in
process.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import riprs
from riprs import campaign
from riprs.campaign.chunk import _run_payload_chunk


def spec(controller: str, runs: int, chunk_size: int | None) -> dict:
    section = {
        "controllers": [controller],
        "seeds": 10,
        "duration": 10.0,
        "axis": [{"name": "mp", "scale": [0.7, 1.3], "points": max(1, runs // 10)}],
    }
    if chunk_size is not None:
        section["chunk_size"] = chunk_size
    return {"campaign": section}


def timed(fn, repeats: int):
    """The median time of ``repeats`` calls and the last call's result."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--runs", type=int, default=400, help="runs per measurement")
    parser.add_argument("--chunk-size", type=int, default=None, help="default: automatic")
    args = parser.parse_args()

    from distributed import Client, LocalCluster

    cores = os.cpu_count() or 1
    cluster = LocalCluster(
        n_workers=cores,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # its HTTP server on a free port, never a taken one
        env={"RAYON_NUM_THREADS": "1"},
    )
    address = cluster.scheduler_address
    rows = []
    try:
        for controller in ("LQR", "MPC"):
            c = campaign.load_spec(spec(controller, args.runs, args.chunk_size))
            local, res = timed(
                lambda c=c: campaign.run(c, progress=False, plots=False), args.repeats
            )
            dask, res_dask = timed(
                lambda c=c: campaign.run(c, scheduler=address, progress=False, plots=False),
                args.repeats,
            )
            rows.append(
                (
                    controller,
                    c.runs,
                    f"{res.chunks} x {res.chunk_size}",
                    f"{res_dask.chunks} x {res_dask.chunk_size}",
                    c.runs / local / cores,
                    c.runs / dask / cores,
                )
            )

        one = campaign.load_spec(spec("LQR", 1, 1))
        payload = {"spec": one.data, "hash": one.spec_hash, "version": riprs.__version__}
        with Client(address, set_as_default=False) as client:
            client.submit(_run_payload_chunk, payload, 0, 1, pure=False).result()  # warm up
            trips = []
            for _ in range(max(10, 5 * args.repeats)):
                t0 = time.perf_counter()
                client.submit(_run_payload_chunk, payload, 0, 1, pure=False).result()
                trips.append(time.perf_counter() - t0)
        inproc = []
        for _ in range(max(10, 5 * args.repeats)):
            t0 = time.perf_counter()
            campaign.compute_chunk(one, 0, 1)
            inproc.append(time.perf_counter() - t0)
        overhead = statistics.median(trips) - statistics.median(inproc)
    finally:
        cluster.close()

    sizing = "automatic" if args.chunk_size is None else str(args.chunk_size)
    print(f"{cores} cores; medians of {args.repeats}; chunk size {sizing}")
    print(
        "| controller | runs | chunks x runs (in process / cluster) | in process, runs/s per "
        "core | local Dask cluster, runs/s per core | cluster / in process |"
    )
    print("| --- | ---: | ---: | ---: | ---: | ---: |")
    for controller, runs, local_chunks, dask_chunks, local, dask in rows:
        print(
            f"| {controller} | {runs} | {local_chunks} / {dask_chunks} | {local:.0f} | "
            f"{dask:.0f} | {dask / local:.2f} |"
        )
    print(
        f"overhead per chunk through the cluster: {overhead * 1e3:.1f} ms "
        f"(round trip {statistics.median(trips) * 1e3:.1f} ms, "
        f"in process {statistics.median(inproc) * 1e3:.1f} ms)"
    )


if __name__ == "__main__":
    main()

"""Engines (in process, Dask) and :func:`run`."""

from __future__ import annotations

import concurrent.futures
import contextlib
import logging
import os
import re
import socket
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

from riprs import __version__
from riprs import _progress as _bars
from riprs.campaign.chunk import _run_payload_chunk, compute_chunk
from riprs.campaign.plots import Aggregates
from riprs.campaign.spec import DEFAULT_CHUNK_SIZE, Campaign, CampaignError, _int, load_spec
from riprs.campaign.store import (
    _EXTRA,
    _check_out,
    _done_ranges,
    _exclusive,
    _pending,
    _read_chunk,
    _require_arrow,
    _to_table,
    _write_chunk,
    _write_manifest,
    load,
)

__all__ = ["CampaignResult", "run", "summary"]

PathLike = Union[str, "os.PathLike[str]"]



# -- engines ------------------------------------------------------------------------------------


@dataclass
class CampaignResult:
    """What :func:`run` produced.

    Attributes
    ----------
    campaign : Campaign
    aggregates : Aggregates
        Fall rates and mean RMSEs per controller, per axis value and over the map's two axes:
        what :func:`summary` and the figures show, summed chunk by chunk (bounded memory).
    out : Path or None
    engine : str
    files : list of Path
        Figures written.
    chunks : int
        Chunks computed by this call (not those found on disk).
    chunk_size : int
        Runs per chunk in this call.
    """

    campaign: Campaign
    aggregates: Aggregates
    out: Path | None
    engine: str
    files: list[Path] = field(default_factory=list)
    chunks: int = 0
    chunk_size: int = 0
    _table: Any = field(default=None, repr=False)

    @property
    def table(self) -> Any:
        """Every run as one ``pyarrow.Table`` sorted by ``run`` (read from ``out`` on first
        use: all rows in memory, unlike :attr:`aggregates`)."""
        if self._table is None and self.out is not None:
            self._table = load(self.out)
        return self._table


ChunkResult = tuple[tuple[int, int], dict[str, Any]]


def _local_threads() -> int:
    """Threads of the in-process engine: one per core (at least two). A chunk's native calls
    release the GIL and spread their seeds over the cores; several threads keep the cores busy
    when a grid point has few seeds, and overlap one chunk's Python with another's runs."""
    return max(2, os.cpu_count() or 1)


def _in_process(campaign: Campaign, chunks: Iterable[tuple[int, int]]) -> Iterator[ChunkResult]:
    """Chunks on a local thread pool, each through the Rust batch API.

    Signals reach only the main thread, so it waits here in short slices; on Ctrl-C it sets
    the chunks' cancel event (their native batches stop within a control sample), yields the
    chunks that finished meanwhile so they are written, and re-raises.
    """
    import threading
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    threads = _local_threads()
    cancel = threading.Event()
    pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="riprs-campaign")
    todo = iter(chunks)
    running: dict[Any, tuple[int, int]] = {}
    interrupted: KeyboardInterrupt | None = None
    try:
        while True:
            while len(running) < threads and (c := next(todo, None)) is not None:
                running[pool.submit(compute_chunk, campaign, *c, cancel)] = c
            if not running:
                break
            try:
                done, _ = wait(list(running), timeout=0.2, return_when=FIRST_COMPLETED)
            except KeyboardInterrupt as exc:
                interrupted = exc
                break
            for fut in done:
                c = running.pop(fut)
                yield c, fut.result()
    finally:
        # Ctrl-C or an error: queued chunks never start, running ones stop within a sample.
        cancel.set()
        pool.shutdown(wait=True, cancel_futures=True)
    if interrupted is not None:
        for fut, c in running.items():
            if not fut.cancelled() and fut.exception() is None:
                yield c, fut.result()
        raise interrupted


_ADDRESS = re.compile(r"^(tcp|tls)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):(\d{1,5})$")


def _scheduler_address(scheduler: str) -> tuple[str, int]:
    """Host and port of a ``tcp://HOST:PORT`` (or ``tls://``) scheduler address; refuses any
    other form."""
    m = _ADDRESS.match(scheduler) if isinstance(scheduler, str) else None
    if m is None or not 1 <= int(m.group(3)) <= 65535:
        raise CampaignError(
            f"scheduler must be an address like tcp://HOST:PORT (port 1..65535), "
            f"got {scheduler!r}",
            key="scheduler",
        )
    return m.group(2).strip("[]"), int(m.group(3))


def _client_class(client: type) -> type:
    """``distributed.Client`` that, when it fails to connect, shuts itself down at once: a
    half-started client otherwise waits 2 x timeout in its finaliser and prints a traceback."""

    class _Client(client):  # type: ignore[misc, valid-type]
        def start(self, **kwargs: Any) -> Any:
            try:
                return super().start(**kwargs)
            except BaseException:
                with contextlib.suppress(Exception):
                    self.close(timeout=1)
                self.status = "closed"  # leaves the finaliser nothing to wait for
                with contextlib.suppress(Exception):
                    self._loop_runner.stop()
                raise

    return _Client


def _probe_scheduler(scheduler: str, timeout: float) -> None:
    """Refuses, in one line and within ``timeout`` s, a peer that accepts connections but does
    not answer Dask's handshake and ``identity`` call as a scheduler does (junk, or silence).

    distributed's own connect waits for the peer's handshake without a time limit, and a
    client's start-up cannot be interrupted, so the exchange runs on a daemon thread while
    this thread waits in short slices: Ctrl-C ends the wait at once, and a peer that never
    answers is left behind with the thread.
    """
    import asyncio
    import threading
    import time

    from distributed.comm import connect
    from distributed.security import Security

    outcome: list[Any] = []

    async def identity() -> Any:
        args = Security().get_connection_args("client")
        comm = await connect(scheduler, timeout=timeout, **args)
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    def exchange() -> None:
        try:
            outcome.append(asyncio.run(asyncio.wait_for(identity(), timeout)))
        except BaseException as exc:  # whatever the peer caused; reported below
            outcome.append(exc)

    thread = threading.Thread(target=exchange, name="riprs-scheduler-probe", daemon=True)
    thread.start()
    deadline = time.monotonic() + timeout
    while thread.is_alive() and time.monotonic() < deadline:
        thread.join(0.1)
    answer = outcome[0] if outcome else None
    if isinstance(answer, dict) and answer.get("type") == "Scheduler":
        return
    if answer is None or isinstance(answer, (TimeoutError, asyncio.TimeoutError)):
        reason = f"no answer as a Dask scheduler within {timeout:g} s"
    elif isinstance(answer, BaseException):
        reason = f"it does not answer as a Dask scheduler ({type(answer).__name__})"
    else:
        reason = "it does not answer as a Dask scheduler"
    raise CampaignError(f"cannot reach the Dask scheduler at {scheduler}: {reason}")


def _connect(scheduler: str | None, workers: int | None, timeout: float) -> tuple[Any, Any]:
    """A Dask client (and the local cluster it owns, if any); errors before any work."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise CampaignError(
            f"running on a Dask cluster needs dask.distributed, which is not installed: {_EXTRA}"
        ) from None
    if scheduler is not None:
        host, port = _scheduler_address(scheduler)
        # A bounded plain connection first: a Client that fails to connect stalls in its
        # finaliser and prints a traceback at exit, so it is only built for a listening port.
        try:
            socket.create_connection((host, port), timeout=timeout).close()
        except OSError as exc:
            reason = "timed out" if isinstance(exc, TimeoutError) else str(exc)
            raise CampaignError(
                f"cannot reach the Dask scheduler at {scheduler}: {reason}"
            ) from None
        _probe_scheduler(scheduler, timeout)
        try:
            client = _client_class(Client)(scheduler, timeout=timeout, set_as_default=False)
        except Exception as exc:  # whatever the peer sent: it is not a usable scheduler
            reason = (
                str(exc)
                if isinstance(exc, (OSError, ValueError))
                else f"it does not answer as a Dask scheduler ({type(exc).__name__})"
            )
            raise CampaignError(
                f"cannot reach the Dask scheduler at {scheduler}: {reason}"
            ) from None
        try:
            client.wait_for_workers(1, timeout=timeout)
        except (OSError, TimeoutError) as exc:
            client.close()
            raise CampaignError(
                f"the Dask scheduler at {scheduler} has no workers ({exc}); start some with "
                f"`dask worker {scheduler}`"
            ) from None
        return client, None
    assert workers is not None
    cores = os.cpu_count() or 1
    # Each worker process has its own rayon pool; share the cores instead of oversubscribing.
    threads = str(max(1, cores // workers))
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # its HTTP server on a free port, never a taken one
        env={"RAYON_NUM_THREADS": threads},
        # Its workers' warnings about tasks cancelled by Ctrl-C are not the user's concern.
        silence_logs=logging.ERROR,
    )
    return Client(cluster, set_as_default=False), cluster


def _on_dask(
    campaign: Campaign, chunks: Iterable[tuple[int, int]], client: Any, window: int
) -> Iterator[ChunkResult]:
    """Chunks as Dask tasks; a worker that dies has its tasks recomputed elsewhere by the
    scheduler, and every result comes back here to be written.

    At most ``window`` chunks are submitted at a time, another one as each finishes: a
    campaign of millions of chunks never holds millions of futures (nor the scheduler as many
    tasks), while the workers always have the next chunks queued.
    """
    from distributed import as_completed

    payload = {"spec": campaign.data, "hash": campaign.spec_hash, "version": __version__}
    todo = iter(chunks)
    futures: dict[str, tuple[Any, tuple[int, int]]] = {}

    def submit() -> Any:
        c = next(todo, None)
        if c is None:
            return None
        fut = client.submit(
            _run_payload_chunk,
            payload,
            *c,
            key=f"riprs-campaign-{campaign.spec_hash[:16]}-{c[0]}-{c[1]}",
            retries=2,
        )
        futures[fut.key] = (fut, c)
        return fut

    first = [f for f in (submit() for _ in range(max(1, window))) if f is not None]
    finished = as_completed(first, loop=client.loop)
    try:
        for fut in finished:
            _, c = futures.pop(fut.key)
            try:
                result = fut.result()
            except (concurrent.futures.CancelledError, OSError, TimeoutError) as exc:
                # The scheduler (or the connection to it) went away: Dask cancels every
                # future. The chunks written so far stay; a rerun resumes after them.
                futures.clear()
                cause = str(exc).strip().splitlines()
                raise CampaignError(
                    f"the Dask scheduler stopped mid-run ({type(exc).__name__}"
                    f"{': ' + cause[0] if cause else ''}); the finished chunks are kept and "
                    "the same command resumes after them"
                ) from None
            fut.release()
            nxt = submit()
            if nxt is not None:
                finished.add(nxt)
            yield c, result
    finally:
        if futures:
            with contextlib.suppress(Exception):
                client.cancel([f for f, _ in futures.values()])


def _dask_window(slots: int) -> int:
    """Chunks in flight on a cluster of ``slots`` worker threads: four each, so that a worker
    finishing a chunk finds the next one queued while its result travels back."""
    return 4 * max(slots, 1)


def _auto_chunk_size(runs: int, slots: int) -> int:
    """Chunks large enough that a chunk's scheduling (tens of ms through Dask) stays a few
    percent of its work, yet at least four per worker thread so that none waits at the end."""
    return max(16, min(DEFAULT_CHUNK_SIZE, -(-runs // (4 * max(slots, 1)))))


def run(
    spec: PathLike | Mapping[str, Any] | Campaign,
    out: PathLike | None = None,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    chunk_size: int | None = None,
    progress: bool = True,
    plots: bool = True,
    map_axes: Sequence[str] | None = None,
    connect_timeout: float = 10.0,
    on_chunk: Callable[[int, int], None] | None = None,
) -> CampaignResult:
    """Run a campaign, resuming whatever ``out`` already holds.

    Parameters
    ----------
    spec : path to a TOML file, its parsed tables, or a Campaign
    out : path, optional
        Results directory (created); without it, results are kept in memory only.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://HOST:PORT``): chunks become its tasks.
    workers : int, optional
        Start a local Dask cluster of that many worker processes.
    chunk_size : int, optional
        Runs per chunk; results do not depend on it. Default: ``[campaign] chunk_size``, or
        :data:`DEFAULT_CHUNK_SIZE` runs, fewer when needed for four chunks per worker thread.
    progress : bool
        Show a progress bar (runs done, runs/s, time left) on standard error, when it is a
        terminal.
    plots : bool
        Write the robustness maps and marginal plots into ``out``.
    map_axes : pair of axis names, optional
        The axes of the maps (default: the spec's first two).
    connect_timeout : float
        Seconds to wait for the scheduler and its first worker.
    on_chunk : callable, optional
        Called as ``on_chunk(done_runs, total_runs)`` after each chunk is on disk.

    Returns
    -------
    CampaignResult

    Raises
    ------
    CampaignError
        Bad spec, ``out`` holding another campaign, an unreachable scheduler or a missing
        optional dependency; raised before any run.
    KeyboardInterrupt
        Re-raised after every finished chunk is written; run again to finish.
    """
    spec_text = None
    if isinstance(spec, Campaign):
        campaign = spec
    else:
        # Parsed first: load_spec names a file that is not UTF-8 TOML in one line.
        campaign = load_spec(spec)
        if not isinstance(spec, Mapping):
            spec_text = Path(spec).read_text(encoding="utf-8")
    size = _int(chunk_size, "chunk_size", 1) if chunk_size is not None else campaign.chunk_size
    if scheduler is not None and workers is not None:
        raise CampaignError("give scheduler or workers, not both")
    if scheduler is not None:
        _scheduler_address(scheduler)
    if workers is not None:
        _int(workers, "workers", 1)
    pair: tuple[str, str] | None = None
    if map_axes is not None:
        names = [a.name for a in campaign.axes]
        if len(map_axes) != 2 or len(set(map_axes)) != 2:
            raise CampaignError(
                f"map_axes must name two different axes, got {list(map_axes)}", key="map_axes"
            )
        for name in map_axes:
            if name not in names:
                raise CampaignError(
                    f"map_axes: {name!r} is not an axis ({', '.join(names)})", key="map_axes"
                )
        pair = (map_axes[0], map_axes[1])
    engine = (
        f"dask {scheduler}"
        if scheduler
        else f"dask local cluster, {workers} workers"
        if workers
        else "in-process"
    )
    _require_arrow()

    out_path = Path(out) if out is not None else None
    results: dict[tuple[int, int], dict[str, Any]] = {}
    done: list[tuple[int, int]] = []
    if out_path is not None:
        _check_out(campaign, out_path)
        done = _done_ranges(out_path / "runs", campaign.runs)
    missing = campaign.runs - sum(b - a for a, b in done)

    # Everything that can fail before the runs does so before anything is written.
    if missing:
        campaign.design_all()
    client = cluster = None
    if missing and engine != "in-process":
        client, cluster = _connect(scheduler, workers, connect_timeout)
    slots = _local_threads()
    if client is not None:
        slots = sum(w["nthreads"] for w in client.scheduler_info()["workers"].values())
    if size is None:
        size = _auto_chunk_size(missing, slots)
    chunks = _pending(done, campaign.runs, size)
    names = [a.name for a in campaign.axes]
    if pair is None and len(names) >= 2:
        pair = (names[0], names[1])
    aggregates = Aggregates(campaign, [(), *((n,) for n in names), *([pair] if pair else [])])
    bar = None
    computed = 0
    try:
        with _exclusive(out_path) if out_path is not None else contextlib.nullcontext():
            if out_path is not None:
                # Read again under the lock: another process may have finished chunks since.
                previous = _check_out(campaign, out_path)
                _write_manifest(campaign, out_path, engine, spec_text, previous)
                done = _done_ranges(out_path / "runs", campaign.runs)
                chunks = _pending(done, campaign.runs, size)
            done_runs = sum(b - a for a, b in done)
            if done_runs < campaign.runs:
                bar = _bars.bar(
                    progress,
                    total=campaign.runs,
                    initial=done_runs,
                    unit="run",
                    desc="campaign",
                    smoothing=0.05,
                    dynamic_ncols=True,
                )
            stream = (
                _in_process(campaign, chunks)
                if client is None
                else _on_dask(campaign, chunks, client, _dask_window(slots))
            )
            for (start, stop), columns in stream:
                if out_path is not None:
                    _write_chunk(out_path / "runs", start, stop, columns)
                else:
                    results[(start, stop)] = columns
                aggregates.add(columns)
                computed += 1
                done_runs += stop - start
                if bar is not None:
                    bar.update(stop - start)
                if on_chunk is not None:
                    on_chunk(done_runs, campaign.runs)
    finally:
        if bar is not None:
            bar.close()
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()

    table = None
    if out_path is not None:
        # The chunks found on disk, one file at a time: memory stays that of one chunk.
        for start, stop in done:
            aggregates.add(_read_chunk(out_path / "runs", start, stop))
    elif results:
        pa = _require_arrow()
        table = pa.concat_tables([_to_table(results[c]) for c in sorted(results)])
    result = CampaignResult(
        campaign, aggregates, out_path, engine, chunks=computed, chunk_size=size, _table=table
    )
    if plots and out_path is not None and aggregates.runs:
        from riprs.campaign import plots as campaign_plots

        result.files = campaign_plots.plot_campaign(campaign, aggregates, out_path, pair)
    return result


def summary(results: Any) -> str:
    """Per controller: runs, fall rate and the mean of each RMSE over the runs that stayed up.

    ``results`` is a table of runs (:func:`load`) or a campaign's :class:`Aggregates`.
    """
    import numpy as np

    from riprs.campaign.plots import aggregate

    names = ("rmse_arm", "rmse_pendulum", "rmse_voltage")
    controllers, _, falls = aggregate(results, (), "fall_rate")
    means = [aggregate(results, (), m)[2] for m in names]
    if isinstance(results, Aggregates):
        counts = dict(zip(controllers, results.run_counts(), strict=True))
    else:
        column = np.asarray(results.column("controller").to_numpy(zero_copy_only=False))
        counts = {c: int(np.count_nonzero(column == c)) for c in controllers}
    lines = [
        f"{'controller':<11}{'runs':>9}{'falls':>8}{'arm [rad]':>12}{'pendulum [rad]':>16}"
        f"{'voltage [V]':>13}   (RMSE: mean over the runs that stayed up)"
    ]
    for k, name in enumerate(controllers):
        lines.append(
            f"{name:<11}{counts[name]:>9}{100 * falls[k]:>7.1f}%{means[0][k]:>12.4f}"
            f"{means[1][k]:>16.5f}{means[2][k]:>13.3f}"
        )
    return "\n".join(lines)

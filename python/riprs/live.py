"""Watch a run as it happens: the live stream of ``rip-rt`` and its viewer (``riprs watch``).

``rip-rt run``, ``excite`` and ``emulate`` with ``--live PORT`` (or ``[loop] live_port``) send
one UDP datagram per period to ``127.0.0.1:PORT`` (rip-rt's ``live`` module; the layout is
``docs/live.md``). :func:`watch` receives them and draws them with the Rerun viewer: scopes of
the arm, the pendulum and the voltage with their limits, the loop's timing, the events (phase
changes, fallbacks, stops) and a drawing of the rig, measured and, from the emulator, true.
:func:`show_log`, :func:`show_simulation` and :func:`show_comparison` draw the same panels
after the fact, from a ``rip-rt`` log, a :func:`riprs.simulate` result, or both aligned as
``riprs compare --log`` aligns them.

The viewer is the ``live`` extra (``pip install "riprs[live]"``, the ``rerun-sdk`` wheel: its
viewer runs offline, and a recording saved with ``save=`` opens later with ``rerun FILE.rrd``).
The datagram's layout comes from the extension (``riprs._riprs.live_frame_layout``), rip-rt's
one definition of it.
"""

from __future__ import annotations

import dataclasses
import json
import os
import queue
import socket
import struct
import threading
import time
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Tuple, Union

import numpy as np

from riprs._riprs import live_frame_layout
from riprs.config import ConfigError

if TYPE_CHECKING:
    from riprs.log import RtLog
    from riprs.sim import SimResult

PathLike = Union[str, "os.PathLike[str]"]

#: The port ``riprs watch`` listens on and the docs use with ``--live``.
DEFAULT_PORT = 9870

#: Frame kinds (rip-rt's ``live::Kind``).
PERIOD, TRUTH, STOP = 1, 2, 3

# The log's status bits above the device's (rip-rt's step.rs).
_FLAG_NO_REPLY = 1 << 8
_FLAG_FALLBACK = 1 << 9
_FLAG_DEADLINE_MISS = 1 << 11

# Lengths drawn for the rig (m): the QUBE-Servo 2's arm and pendulum, a drawing's scale only.
_ARM_LENGTH = 0.085
_PENDULUM_LENGTH = 0.129

_MEASURED = [31, 119, 180]
_TRUE = [44, 160, 44]
_SIM = [214, 39, 40]
_LIMIT = [127, 127, 127]


class _Layout:
    """The datagram layout: rip-rt's field table and the ``struct`` format built from it."""

    def __init__(self) -> None:
        fields, fmt, version = live_frame_layout()
        self.struct = struct.Struct(fmt)
        self.version = version
        # (name, first value index, count, is_bytes)
        self.slices: List[Tuple[str, int, int, bool]] = []
        at = 0
        for name, code, count, _doc in fields:
            is_bytes = code == "s"
            self.slices.append((name, at, count, is_bytes))
            at += 1 if is_bytes else count

    def decode(self, data: bytes) -> Dict[str, Any] | None:
        if len(data) != self.struct.size:
            return None
        values = self.struct.unpack(data)
        frame: Dict[str, Any] = {}
        for name, at, count, is_bytes in self.slices:
            if is_bytes:
                frame[name] = values[at].rstrip(b"\0")
            elif count == 1:
                frame[name] = values[at]
            else:
                frame[name] = values[at : at + count]
        if frame["magic"] != b"RIPL" or frame["version"] != self.version:
            return None
        frame["phase"] = frame["phase"].decode("ascii", "replace")
        return frame


_LAYOUT: _Layout | None = None


def decode_frame(data: bytes) -> Dict[str, Any] | None:
    """One datagram of the live stream as a dict of its fields (``docs/live.md``).

    Parameters
    ----------
    data : bytes
        The datagram.

    Returns
    -------
    dict or None
        The fields by name (``estimate`` a tuple of four floats, ``phase`` a str), or ``None``
        for a datagram of another size, magic or version.
    """
    global _LAYOUT
    if _LAYOUT is None:
        _LAYOUT = _Layout()
    return _LAYOUT.decode(data)


def _rerun() -> Any:
    try:
        import rerun
    except ImportError as e:
        raise ImportError(
            "the live view needs the live extra: pip install 'riprs[live]' (rerun-sdk)"
        ) from e
    return rerun


def _rig_strips(theta: float, alpha: float) -> List[List[List[float]]]:
    """The arm (from the motor's axis) and the pendulum (from the arm's tip), α from upright."""
    tip = [_ARM_LENGTH * np.cos(theta), _ARM_LENGTH * np.sin(theta), 0.0]
    # The pendulum swings in the plane normal to the arm.
    tangent = [-np.sin(theta), np.cos(theta)]
    end = [
        tip[0] + _PENDULUM_LENGTH * np.sin(alpha) * tangent[0],
        tip[1] + _PENDULUM_LENGTH * np.sin(alpha) * tangent[1],
        _PENDULUM_LENGTH * np.cos(alpha),
    ]
    return [[[0.0, 0.0, 0.0], tip], [tip, end]]


class Viewer:
    """The panels of a run in a Rerun recording: scopes, events and the rig.

    Parameters
    ----------
    save : path, optional
        Write the recording to this ``.rrd`` file (no window).
    spawn : bool
        Open the Rerun viewer (a local process; no network beyond loopback) and stream to it.
    name : str
        The recording's name in the viewer.

    Raises
    ------
    ImportError
        The ``live`` extra is not installed.
    """

    def __init__(self, *, save: PathLike | None = None, spawn: bool = True, name: str = "riprs"):
        rr = _rerun()
        self.rr = rr
        self.rec = rr.RecordingStream("riprs")
        self.rec.send_recording_name(name)
        blueprint = _blueprint(rr)
        if save is not None:
            self.rec.save(os.fspath(save), default_blueprint=blueprint)
        elif spawn:
            self.rec.spawn(default_blueprint=blueprint)
        self._series_named: set[str] = set()

    def series(self, path: str, names: List[str], colors: List[List[int]]) -> None:
        """Names and colours of the scalars at ``path`` (once)."""
        if path in self._series_named:
            return
        self._series_named.add(path)
        rr = self.rr
        self.rec.log(path, rr.SeriesLines(names=names, colors=colors), static=True)

    def scalars(self, path: str, values: List[float]) -> None:
        """One sample of each series at ``path`` at the current time."""
        self.rec.log(path, self.rr.Scalars(values))

    def event(self, text: str, level: str = "INFO") -> None:
        """A line in the events panel at the current time."""
        self.rec.log("events", self.rr.TextLog(text, level=level))

    def rig(self, which: str, theta: float, alpha: float, color: List[int]) -> None:
        """The rig drawn at angles ``theta`` and ``alpha`` (rad) as ``rig/which``."""
        if not (np.isfinite(theta) and np.isfinite(alpha)):
            return
        self.rec.log(
            f"rig/{which}",
            self.rr.LineStrips3D(_rig_strips(theta, alpha), colors=[color], radii=[0.004]),
        )

    def time(self, timeline: str, seconds: float) -> None:
        """Sets the current time on ``timeline``."""
        self.rec.set_time(timeline, duration=seconds)

    def columns(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        """A whole series at once: ``values`` of shape (n,) or (n, k) on the ``time`` axis."""
        rr = self.rr
        v = np.asarray(values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        self.rec.send_columns(
            path,
            indexes=[rr.TimeColumn("time", duration=np.asarray(t, dtype=float))],
            columns=rr.Scalars.columns(scalars=v),
        )

    def close(self) -> None:
        """Flush and close the recording (the ``.rrd`` file is complete after it)."""
        self.rec.flush()
        self.rec.disconnect()


def _blueprint(rr: Any) -> Any:
    rrb = rr.blueprint
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/scopes/arm", name="arm θ (rad)"),
                rrb.TimeSeriesView(origin="/scopes/pendulum", name="pendulum α (rad)"),
                rrb.TimeSeriesView(origin="/scopes/voltage", name="voltage (V)"),
                rrb.TimeSeriesView(origin="/scopes/timing", name="timing (µs)"),
            ),
            rrb.Vertical(
                rrb.Spatial3DView(origin="/rig", name="rig"),
                rrb.TextLogView(origin="/events", name="events"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def _name_run_series(v: Viewer, who: str, color: List[int]) -> None:
    lim = _LIMIT
    v.series(
        f"scopes/arm/{who}",
        [f"θ {who}", f"θ reference ({who})", f"θ estimate ({who})", "arm limit", "-arm limit"],
        [color, [255, 127, 14], [148, 103, 189], lim, lim],
    )
    v.series(
        f"scopes/pendulum/{who}",
        [f"α {who}", f"α estimate ({who})", "pendulum limit", "-pendulum limit"],
        [color, [148, 103, 189], lim, lim],
    )
    v.series(
        f"scopes/voltage/{who}",
        [f"planned ({who})", f"written ({who})", "voltage bound", "-voltage bound"],
        [[255, 127, 14], color, lim, lim],
    )


@dataclasses.dataclass
class WatchStats:
    """What :func:`watch` received.

    Attributes
    ----------
    frames : dict of str to int
        Frames received by kind (``period``, ``truth``, ``stop``).
    expected : dict of str to int
        Frames sent by kind, from the senders' counters (first to last received).
    lag_ms : list of float
        Time from the send to the frame handed to the viewer's recording, per period frame (ms).
    exit_codes : list of int
        The exit codes of the stop frames received.
    bad : int
        Datagrams that were not frames of this layout.
    """

    frames: Dict[str, int] = dataclasses.field(
        default_factory=lambda: {"period": 0, "truth": 0, "stop": 0}
    )
    expected: Dict[str, int] = dataclasses.field(default_factory=dict)
    lag_ms: List[float] = dataclasses.field(default_factory=list)
    exit_codes: List[int] = dataclasses.field(default_factory=list)
    bad: int = 0

    def summary(self) -> Dict[str, Any]:
        """The figures as a JSON-ready dict (``lag_ms`` as p50/p99/max)."""
        lag = np.asarray(self.lag_ms)
        pct = (
            {"p50": float(np.percentile(lag, 50)), "p99": float(np.percentile(lag, 99))}
            if lag.size
            else {"p50": None, "p99": None}
        )
        return {
            "frames": dict(self.frames),
            "expected": dict(self.expected),
            "lag_ms": {**pct, "max": float(lag.max()) if lag.size else None},
            "exit_codes": list(self.exit_codes),
            "bad": self.bad,
        }


_KIND_NAMES = {PERIOD: "period", TRUTH: "truth", STOP: "stop"}


class _Live:
    """Draws the frames of the stream as they arrive."""

    def __init__(self, viewer: Viewer) -> None:
        self.v = viewer
        self.stats = WatchStats()
        self.t0_ns: int | None = None
        self.phase: Dict[Any, str] = {}
        # Per sender: (first counter, last counter) by kind.
        self.counters: Dict[Tuple[Any, int], Tuple[int, int]] = {}
        _name_run_series(viewer, "measured", _MEASURED)
        viewer.series("scopes/arm/true", ["θ true"], [_TRUE])
        viewer.series("scopes/pendulum/true", ["α true"], [_TRUE])
        viewer.series("scopes/voltage/true", ["across the motor (true)"], [_TRUE])
        viewer.series("scopes/timing/run", ["jitter", "compute"], [[31, 119, 180], [255, 127, 14]])

    def frame(self, f: Dict[str, Any], sender: Any) -> None:
        kind = f["kind"]
        name = _KIND_NAMES.get(kind)
        if name is None:
            self.stats.bad += 1
            return
        self.stats.frames[name] += 1
        key = (sender, kind)
        first, _ = self.counters.get(key, (f["counter"], f["counter"]))
        self.counters[key] = (first, f["counter"])
        if self.t0_ns is None:
            self.t0_ns = f["sent_ns"]
        v = self.v
        v.time("time", (f["sent_ns"] - self.t0_ns) * 1e-9)
        if kind == PERIOD:
            self._period(f, sender)
            self.stats.lag_ms.append((time.monotonic_ns() - f["sent_ns"]) * 1e-6)
        elif kind == TRUTH:
            v.scalars("scopes/arm/true", [f["theta"]])
            v.scalars("scopes/pendulum/true", [f["alpha"]])
            v.scalars("scopes/voltage/true", [f["u_written"]])
            v.rig("true", f["theta"], f["alpha"], _TRUE)
        else:
            self.stats.exit_codes.append(int(f["exit_code"]))
            level = "INFO" if f["exit_code"] == 0 else "WARN"
            v.event(f"stop: {f['phase']} (exit {f['exit_code']})", level)
            self.phase.pop(sender, None)

    def _period(self, f: Dict[str, Any], sender: Any) -> None:
        v = self.v
        v.time("run_time", f["t"])
        est = f["estimate"]
        a, p, u = f["arm_limit"], f["pendulum_limit"], f["voltage_limit"]
        v.scalars("scopes/arm/measured", [f["theta"], f["theta_ref"], est[0], a, -a])
        v.scalars("scopes/pendulum/measured", [f["alpha"], est[2], p, -p])
        v.scalars("scopes/voltage/measured", [f["u_planned"], f["u_written"], u, -u])
        v.scalars("scopes/timing/run", [f["jitter_us"], f["compute_us"]])
        v.rig("measured", f["theta"], f["alpha"], _MEASURED)
        if self.phase.get(sender) != f["phase"]:
            self.phase[sender] = f["phase"]
            v.event(f"t = {f['t']:.2f} s: phase {f['phase']}")
        status = f["status"]
        if status & _FLAG_FALLBACK:
            v.event(f"t = {f['t']:.2f} s: controller fallback", "WARN")
        if status & _FLAG_NO_REPLY:
            v.event(f"t = {f['t']:.2f} s: no measurement, command held", "WARN")
        if status & _FLAG_DEADLINE_MISS:
            v.event(f"t = {f['t']:.2f} s: deadline missed", "WARN")

    def finish(self) -> WatchStats:
        expected: Dict[str, int] = {}
        for (_, kind), (first, last) in self.counters.items():
            name = _KIND_NAMES[kind]
            expected[name] = expected.get(name, 0) + ((last - first) & 0xFFFFFFFF) + 1
        self.stats.expected = expected
        return self.stats


def _positive(name: str, value: float | None) -> None:
    if value is not None and not (np.isfinite(value) and value > 0):
        raise ConfigError(f"{name} must be a positive number of seconds, got {value!r}")


def watch(
    port: int = DEFAULT_PORT,
    *,
    save: PathLike | None = None,
    spawn: bool = True,
    once: bool = False,
    idle: float | None = None,
    stats: PathLike | None = None,
    ready: PathLike | None = None,
) -> WatchStats:
    """Receive the live stream on ``127.0.0.1:port`` and draw it until stopped.

    Parameters
    ----------
    port : int
        The UDP port ``rip-rt ... --live PORT`` sends to.
    save : path, optional
        Write the recording to this ``.rrd`` file instead of opening a window.
    spawn : bool
        Open the viewer (ignored with ``save``).
    once : bool
        End after the first stop frame (a run's end).
    idle : float, optional
        End after this many seconds without a frame (once one arrived, or from the start).
    stats : path, optional
        Write :meth:`WatchStats.summary` to this JSON file at the end.
    ready : path, optional
        Create this file once the port is bound (a script's signal that it can start the run).

    Returns
    -------
    WatchStats

    Raises
    ------
    riprs.ConfigError
        A port outside 1-65535 or a non-positive ``idle``.
    OSError
        The port cannot be bound (another viewer holds it).
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
        raise ConfigError(f"port must be in 1..65535, got {port!r}")
    _positive("idle", idle)
    layout = _Layout()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    received: queue.SimpleQueue[Tuple[bytes, Any]] = queue.SimpleQueue()
    done = threading.Event()

    def read() -> None:
        # The socket is drained by its own thread, so that drawing a burst (a lockstep run
        # sends hundreds of periods a second) queues frames here instead of the kernel's
        # buffer, which would drop them.
        while not done.is_set():
            try:
                received.put(sock.recvfrom(4096))
            except TimeoutError:
                continue
            except OSError:
                break

    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        try:
            sock.bind(("127.0.0.1", port))
        except OSError as e:
            raise OSError(e.errno, f"port {port}: {e.strerror}") from None
        sock.settimeout(0.05)
        viewer = Viewer(save=save, spawn=spawn, name=f"rip-rt live on port {port}")
        live = _Live(viewer)
        reader = threading.Thread(target=read, name="riprs-watch", daemon=True)
        reader.start()
        if ready is not None:
            with open(ready, "w"):
                pass
        last = time.monotonic()
        try:
            while True:
                try:
                    # Woken by the next frame, not by polling: an idle viewer takes no CPU.
                    data, sender = received.get(timeout=0.1)
                except queue.Empty:
                    if idle is not None and time.monotonic() - last >= idle:
                        break
                    continue
                last = time.monotonic()
                f = layout.decode(data)
                if f is None:
                    live.stats.bad += 1
                    continue
                live.frame(f, sender)
                if once and f["kind"] == STOP:
                    break
        except KeyboardInterrupt:
            pass
        finally:
            done.set()
            reader.join()
        result = live.finish()
        viewer.close()
    finally:
        sock.close()
    if stats is not None:
        with open(stats, "w") as fh:
            json.dump(result.summary(), fh, indent=1)
    return result


def _series_of_log(v: Viewer, who: str, log: RtLog, t: np.ndarray, sl: slice) -> None:
    n = len(t)
    nan = np.full(n, np.nan)
    xhat = np.asarray(log.xhat)[sl]
    est = (lambda i: xhat[:, i]) if xhat.ndim == 2 and xhat.shape[1] >= 4 else (lambda i: nan)
    # The header's limits (rip-rt run writes all three, excite the first two).
    u_lim = float(log.meta.get("voltage_limit", "nan"))
    arm_lim = float(log.meta.get("arm_limit", "nan"))
    pend_lim = float(log.meta.get("pendulum_limit", "nan"))
    ones = np.ones(n)
    theta, alpha, u = (np.asarray(x)[sl] for x in (log.theta, log.alpha, log.u))
    v.columns(
        f"scopes/arm/{who}",
        t,
        np.column_stack(
            [theta, np.asarray(log.theta_ref)[sl], est(0), arm_lim * ones, -arm_lim * ones]
        ),
    )
    v.columns(
        f"scopes/pendulum/{who}",
        t,
        np.column_stack([alpha, est(2), pend_lim * ones, -pend_lim * ones]),
    )
    v.columns(f"scopes/voltage/{who}", t, np.column_stack([nan, u, u_lim * ones, -u_lim * ones]))
    v.columns(
        "scopes/timing/run",
        t,
        np.column_stack([np.asarray(log.jitter_us)[sl], np.asarray(log.compute_us)[sl]]),
    )
    _rig_columns(v, who, t, theta, alpha, _MEASURED)
    phase = np.asarray(log.phase)[sl]
    status = np.asarray(log.status)[sl]
    changes = np.flatnonzero(np.r_[True, phase[1:] != phase[:-1]]) if n else []
    for i in changes:
        v.time("time", float(t[i]))
        v.event(f"t = {t[i]:.2f} s: phase {phase[i]}")
    for i in np.flatnonzero(status & _FLAG_FALLBACK):
        v.time("time", float(t[i]))
        v.event(f"t = {t[i]:.2f} s: controller fallback", "WARN")
    if log.stop_reason is not None and n:
        v.time("time", float(t[-1]))
        v.event(f"stop: {log.stop_reason}", "INFO" if log.stop_reason == "finished" else "WARN")


def _rig_columns(
    v: Viewer, who: str, t: np.ndarray, theta: np.ndarray, alpha: np.ndarray, color: List[int]
) -> None:
    # A drawing every 20 ms is enough to scrub through, and keeps a long log's file small.
    step = max(1, round(0.02 / max(float(np.median(np.diff(t))), 1e-6))) if len(t) > 1 else 1
    for i in range(0, len(t), step):
        v.time("time", float(t[i]))
        v.rig(who, float(theta[i]), float(alpha[i]), color)


def _series_of_sim(v: Viewer, who: str, t: np.ndarray, result: Any, sl: slice) -> None:
    y = np.asarray(result.y)[sl]
    from riprs.compare import wrap_angle

    alpha = wrap_angle(y[:, 1])
    xhat = getattr(result, "x_hat", None)
    nan = np.full(len(t), np.nan)
    est = np.asarray(xhat)[sl] if xhat is not None and np.ndim(xhat) == 2 else None
    v.series(
        f"scopes/arm/{who}",
        [f"θ {who}", f"θ reference ({who})", f"θ estimate ({who})"],
        [_SIM, [255, 187, 120], [197, 176, 213]],
    )
    v.series(f"scopes/pendulum/{who}", [f"α {who}", f"α estimate ({who})"], [_SIM, [197, 176, 213]])
    v.series(f"scopes/voltage/{who}", [f"voltage ({who})"], [_SIM])
    v.columns(
        f"scopes/arm/{who}",
        t,
        np.column_stack(
            [y[:, 0], np.asarray(result.r)[sl][:, 0], est[:, 0] if est is not None else nan]
        ),
    )
    v.columns(
        f"scopes/pendulum/{who}",
        t,
        np.column_stack([alpha, wrap_angle(est[:, 2]) if est is not None else nan]),
    )
    v.columns(f"scopes/voltage/{who}", t, np.asarray(result.u)[sl].reshape(len(t), -1)[:, 0])
    _rig_columns(v, who, t, y[:, 0], alpha, _SIM)


def show_log(
    log: Union[RtLog, PathLike], *, save: PathLike | None = None, spawn: bool = True
) -> Viewer:
    """Draw a ``rip-rt`` log in the live view's panels.

    Parameters
    ----------
    log : riprs.RtLog or path
        The log, or its file.
    save : path, optional
        Write the recording to this ``.rrd`` file instead of opening a window.
    spawn : bool
        Open the viewer (ignored with ``save``).

    Returns
    -------
    Viewer
        The recording, closed.
    """
    from riprs.log import load_log

    rt = load_log(log) if isinstance(log, (str, os.PathLike)) else log
    v = Viewer(save=save, spawn=spawn, name="rip-rt log")
    _name_run_series(v, "measured", _MEASURED)
    v.series("scopes/timing/run", ["jitter", "compute"], [[31, 119, 180], [255, 127, 14]])
    t = np.asarray(rt.t, dtype=float)
    _series_of_log(v, "measured", rt, t, slice(None))
    v.close()
    return v


def show_simulation(
    result: SimResult, *, save: PathLike | None = None, spawn: bool = True
) -> Viewer:
    """Draw a :func:`riprs.simulate` result in the live view's panels.

    Parameters
    ----------
    result : riprs.SimResult
        The simulation.
    save : path, optional
        Write the recording to this ``.rrd`` file instead of opening a window.
    spawn : bool
        Open the viewer (ignored with ``save``).

    Returns
    -------
    Viewer
        The recording, closed.
    """
    v = Viewer(save=save, spawn=spawn, name="riprs simulation")
    t = np.asarray(result.t, dtype=float)
    _series_of_sim(v, "simulated", t, result, slice(None))
    v.close()
    return v


def show_comparison(
    log: Union[RtLog, PathLike],
    config: Any = None,
    *,
    controller: str | None = None,
    seed: int = 0,
    save: PathLike | None = None,
    spawn: bool = True,
) -> Viewer:
    """Draw a ``rip-rt`` log and its simulation in the same panels, aligned as
    ``riprs compare --log`` aligns them (a swing-up from the start of its swing).

    Parameters
    ----------
    log : riprs.RtLog or path
        The log, or its file.
    config : riprs.config.Spec or path, optional
        The experiment the log ran (default: the paper's).
    controller : str, optional
        The controller to simulate, ``lqr``, ``lqg`` or ``mpc`` (default: the log's header).
    seed : int
        The simulation's noise seed.
    save : path, optional
        Write the recording to this ``.rrd`` file instead of opening a window.
    spawn : bool
        Open the viewer (ignored with ``save``).

    Returns
    -------
    Viewer
        The recording, closed.

    Raises
    ------
    riprs.ConfigError
        No controller given and none in the log's header, or one the configuration lacks.
    """
    from riprs import compare as cmp
    from riprs.config import Spec, load_config
    from riprs.log import load_log
    from riprs.sim import simulate

    rt = load_log(log) if isinstance(log, (str, os.PathLike)) else log
    cfg = config if isinstance(config, Spec) else (load_config(config) if config else Spec())
    name = (controller or rt.meta.get("controller") or "").upper()
    controllers = cmp.build_controllers(cfg)
    if name not in controllers:
        raise ConfigError(
            f"controller must be one of {sorted(c.lower() for c in controllers)} (or a log whose "
            f"header names one), got {name.lower() or None!r}"
        )
    start = cmp.start_of_logs({"log": rt})
    if start == "down":
        controllers = cmp._supervised(cfg, controllers)
    traj = cmp.Trajectory.from_log(rt)
    first = len(rt.t) - len(traj.t)
    duration = float(traj.t[-1]) if len(traj.t) else cmp._duration(cfg, start)
    result = simulate(
        cfg.build_plant(), controllers[name], duration, seed=seed, **cmp._sim_options(cfg, start)
    )
    v = Viewer(save=save, spawn=spawn, name="rip-rt log and its simulation")
    _name_run_series(v, "measured", _MEASURED)
    v.series("scopes/timing/run", ["jitter", "compute"], [[31, 119, 180], [255, 127, 14]])
    _series_of_log(v, "measured", rt, np.asarray(traj.t, dtype=float), slice(first, None))
    _series_of_sim(v, "simulated", np.asarray(result.t, dtype=float), result, slice(None))
    v.close()
    return v


def recorded_counts(path: PathLike) -> Mapping[str, int]:
    """Rows per entity in an ``.rrd`` recording (the frames a viewer drew), for checks.

    Parameters
    ----------
    path : path
        The ``.rrd`` file.

    Returns
    -------
    dict of str to int
        Rows by entity path (``/scopes/arm/measured``, ``/rig/true``, ...), static rows left out.
    """
    _rerun()
    from rerun.chunk import RrdReader

    counts: Dict[str, int] = {}
    for chunk in RrdReader(os.fspath(path)).stream():
        if chunk.is_static:
            continue
        counts[chunk.entity_path] = counts.get(chunk.entity_path, 0) + chunk.num_rows
    return counts

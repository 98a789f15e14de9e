"""Closed-loop simulation of a controller on the nonlinear plant.

The plant is integrated by RK4 with ``substeps`` steps per control period ``Ts``; the controller
is sampled every ``Ts`` and its input held (zero-order hold) and saturated at ``+-u_limit``.
The sensor quantises each angle to its encoder's counts (``q * round(angle / q)``,
``q = 2 pi / counts``), adds seeded Gaussian noise and an optional output step. A run stops,
flagged, when ``|alpha|`` exceeds ``fall_limit``; its arrays then end at the fall and never hold
NaN. A run whose integration diverges (the state overflows, e.g. for absurd plant parameters) is
not a fall: it stops with ``diverged=True`` and ``fell=False``, and ``x_final`` is the last finite
state. The native loop runs with the GIL released; :func:`simulate_batch` spreads runs over all
cores, and :func:`simulate_metrics` does so for studies too large to keep every record (it keeps
a few numbers per run). Ctrl-C stops any of them within a fraction of a second
(``KeyboardInterrupt``), and a controller object may be used from several threads at once: the
simulations run on their own copies of it.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any, Callable, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike

from riprs import _riprs
from riprs._riprs import FurutaParams, InvalidParameterError, Plant, ShapeError
from riprs._typing import FloatArray
from riprs.control import Controller

__all__ = ["BatchMetrics", "SimResult", "simulate", "simulate_batch", "simulate_metrics"]

PlantLike = Union[Plant, FurutaParams]


@dataclass(frozen=True)
class SimResult:
    """The record of one closed-loop run; one row per control sample ``k`` (time ``k Ts``).

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times (s).
    x : ndarray, shape (N, 4)
        True state ``[theta, theta_dot, alpha, alpha_dot]`` at each sample.
    y : ndarray, shape (N, 2)
        Measured angles given to the controller.
    u : ndarray, shape (N,)
        Voltage applied over the following period (after actuator saturation).
    r : ndarray, shape (N, 2)
        Reference.
    x_hat : ndarray, shape (N, n) or None
        The controller's state estimate after each step (``None`` if it has none).
    compute_time : ndarray, shape (N,)
        Wall-clock time of each controller step (s).
    fell : bool
        Whether the pendulum passed ``fall_limit`` (the arrays then end at the fall).
    diverged : bool
        Whether the integration diverged numerically (the state overflowed to NaN or Inf): a
        failure of the model or its parameters, not a fall. The arrays then end at the last
        finite state, ``fell`` is false and ``fall_time`` is ``None``.
    fall_time : float or None
        Time of the fall (s), to the integration substep.
    fallbacks : int
        Steps in which the controller used its fallback.
    x_final : ndarray, shape (4,)
        State at the end of the run (or at the fall).
    rmse : tuple of float
        The paper's Tab. 1 indices, ``rip-core``'s one definition (``riprs.compare.rmse`` and
        Monte Carlo use the same): RMSE of the measured ``theta - theta_ref`` and
        ``alpha - alpha_ref`` (rad) and RMS of ``u`` (V), over every sample of the run.
    phase : ndarray of int8, shape (N,) or None
        The controller's phase after each step: 0 swinging up, 1 balancing, 2 stopped (see
        :class:`riprs.SwingUp`; always 1 for a balance controller). The switch (catch) is the
        first sample where it turns from 0 to 1.
    catch_time : float or None
        Time (s) of the switch from swing-up to balance: the first balanced sample after a
        swing-up (``None`` without one).
    time_to_upright : float or None
        The time to upright (s), ``rip-core``'s one definition: the catch time.
    swing_up_succeeded : bool
        ``rip-core``'s one definition of a successful swing-up: caught, then balanced to the
        end of the run (no fall, stop or divergence). False for a balance controller.
    stop_cause : str or None
        Why a :class:`riprs.SwingUp` gave up (``"swing_up_timeout"`` or
        ``"left_balance_region"``); the arrays then end at that sample.
    """

    t: FloatArray
    x: FloatArray
    y: FloatArray
    u: FloatArray
    r: FloatArray
    x_hat: FloatArray | None
    compute_time: FloatArray
    fell: bool
    diverged: bool
    fall_time: float | None
    fallbacks: int
    x_final: FloatArray
    rmse: tuple[float, float, float]
    phase: np.ndarray | None = None
    catch_time: float | None = None
    stop_cause: str | None = None
    time_to_upright: float | None = None
    swing_up_succeeded: bool = False

    @classmethod
    def _from_native(cls, d: dict[str, Any]) -> SimResult:
        return cls(
            t=d["t"],
            x=d["x"],
            y=d["y"],
            u=d["u"],
            r=d["r"],
            x_hat=d["x_hat"],
            compute_time=d["compute_time"],
            fell=bool(d["fell"]),
            diverged=bool(d["diverged"]),
            fall_time=d["fall_time"],
            fallbacks=int(d["fallbacks"]),
            x_final=d["x_final"],
            rmse=(float(d["rmse"][0]), float(d["rmse"][1]), float(d["rmse"][2])),
            phase=d["phase"],
            catch_time=d["catch_time"],
            stop_cause=d["stop_cause"],
            time_to_upright=d["time_to_upright"],
            swing_up_succeeded=bool(d["swing_up_succeeded"]),
        )


def _as_plant(plant: Any, name: str) -> Plant:
    if isinstance(plant, Plant):
        return plant
    if isinstance(plant, FurutaParams):
        return Plant(plant)
    raise TypeError(f"{name} must be a riprs.Plant or riprs.FurutaParams, got {type(plant)}")


def _config(
    *,
    duration: float,
    Ts: float,
    substeps: int,
    x0: ArrayLike | None,
    reference: ArrayLike | None,
    reference_time: float,
    encoder_counts: ArrayLike | None,
    noise_std: ArrayLike,
    encoder_offsets: ArrayLike | None = None,
    output_disturbance: tuple[float, ArrayLike] | None,
    torque_disturbance: tuple[float, float] | None,
    u_limit: float,
    fall_limit: float,
    seed: int,
    step_after_catch: float | None = None,
) -> dict[str, Any]:
    # Arrays and numbers are coerced (and bad ones named) by the native side's one policy.
    config: dict[str, Any] = {
        "duration": duration,
        "Ts": Ts,
        "substeps": substeps,
        "x0": np.zeros(4) if x0 is None else x0,
        "reference_time": reference_time,
        "reference_value": np.zeros(2),
        "reference_sequence": None,
        "encoder_counts": encoder_counts,
        "noise_std": noise_std,
        "encoder_offsets": encoder_offsets,
        "output_disturbance": None,
        "torque_disturbance": None,
        "u_limit": u_limit,
        "fall_limit": fall_limit,
        "seed": _seed(seed, "seed"),
        "reference_after_catch": step_after_catch,
    }
    if reference is not None:
        try:
            ndim = np.ndim(reference)
        except ValueError as exc:
            raise ShapeError(f"reference: expected a rectangular array: {exc}") from None
        if ndim == 0:
            config["reference_value"] = [reference, 0.0]
        elif ndim == 1:
            column = np.asarray(reference, dtype=np.float64)
            config["reference_sequence"] = np.column_stack([column, np.zeros_like(column)])
        else:
            config["reference_sequence"] = reference
    if output_disturbance is not None:
        time, size = output_disturbance
        config["output_disturbance"] = (time, size)
    if torque_disturbance is not None:
        time, torque = torque_disturbance
        config["torque_disturbance"] = (time, torque)
    return config


def _seed(seed: Any, name: str) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"{name} must be a non-negative int, got {type(seed)}")
    if not 0 <= int(seed) < 2**64:
        raise InvalidParameterError(f"invalid {name}: must be in [0, 2**64), got {seed}")
    return int(seed)


_DEFAULTS: dict[str, Any] = {
    "reference": None,
    "reference_time": 0.0,
    "Ts": _riprs.TS,
    "substeps": _riprs.DEFAULT_SUBSTEPS,
    "x0": None,
    "encoder_counts": None,
    "noise_std": 0.0,
    "encoder_offsets": None,
    "output_disturbance": None,
    "torque_disturbance": None,
    "u_limit": _riprs.DEFAULT_U_LIMIT,
    "fall_limit": _riprs.DEFAULT_FALL_LIMIT,
    "step_after_catch": None,
}


def simulate(
    plant: PlantLike,
    controller: Controller | Callable[[FloatArray], float],
    duration: float = _riprs.DEFAULT_DURATION,
    *,
    reference: ArrayLike | None = None,
    reference_time: float = 0.0,
    Ts: float = _riprs.TS,
    substeps: int = _riprs.DEFAULT_SUBSTEPS,
    x0: ArrayLike | None = None,
    encoder_counts: ArrayLike | None = None,
    noise_std: ArrayLike = 0.0,
    encoder_offsets: ArrayLike | None = None,
    output_disturbance: tuple[float, ArrayLike] | None = None,
    torque_disturbance: tuple[float, float] | None = None,
    u_limit: float = _riprs.DEFAULT_U_LIMIT,
    fall_limit: float = _riprs.DEFAULT_FALL_LIMIT,
    seed: int = 0,
    step_after_catch: float | None = None,
) -> SimResult:
    r"""Run a controller in closed loop with the nonlinear plant.

    Every control period ``k`` (time :math:`t_k = k T_s`):

    .. math::

        y[k] &= \mathrm{quant}(\theta(t_k), \alpha(t_k)) + v[k] + d_y(t_k),
        \qquad v[k] \sim \mathcal N(0, \mathrm{diag}(\sigma^2)) \\
        u[k] &= \mathrm{controller.step}(y[k], r[k]) \\
        x(t_{k+1}) &= \mathrm{RK4}\big(x(t_k), \mathrm{sat}(u[k], \pm u_{limit}), \tau_d\big)
        \text{ with ``substeps`` steps}

    A riprs controller is copied and reset first, so the object passed in is not modified. A
    controller with a ``compensation`` (built from an experiment file whose ``[plant]`` has a
    dead zone or arm friction, see ``[compensation]``) runs with it, as ``rip-rt run`` runs
    it: ``u[k]`` is then the compensated voltage.

    Parameters
    ----------
    plant : Plant or FurutaParams
        The nonlinear plant.
    controller : Lqr, Lqg, Mpc, SwingUp or callable
        A riprs controller, or any Python callable ``u = controller(y)`` from the measured
        angles ``y = [theta, alpha]`` (float64 array, shape (2,)) to the voltage (a real
        number, saturated at ``u_limit``), e.g. a trained policy
        (:func:`riprs.envs.policy_controller`). A callable is called once per control period
        on the calling thread, in order, and is not copied or reset: keep its state (filters,
        clocks) inside it and use a fresh one per run. It is a balance controller (the run
        stops at ``fall_limit``). An exception it raises, or a result that is not a finite
        number (``NonFiniteError``), ends the run and propagates.
    duration : float
        Length of the run (s); ``round(duration / Ts)`` samples.
    reference : float or array_like, optional
        A scalar is a step of the arm angle to that value at ``reference_time`` (the paper steps
        it from 0 to 1 rad); a 1-D array of one value per sample is an arm-angle sequence; a 2-D
        array of shape (N, 2) gives both outputs per sample. Zero by default.
    reference_time : float
        Time of the reference step (s).
    Ts : float
        Control period (s).
    substeps : int
        RK4 steps per control period.
    x0 : array_like, shape (4,), optional
        Initial state; upright at rest by default.
    encoder_counts : float or array_like, shape (2,), optional
        Encoder counts per revolution of ``[theta, alpha]`` (e.g. 2048); exact angles if omitted.
    noise_std : float or array_like, shape (2,)
        Standard deviation of the white measurement noise (rad).
    encoder_offsets : array_like, shape (2,), optional
        Where each encoder's zero lies (rad): the sensor reads ``angle + offset`` (then
        quantised, then the noise added), as ``[sensor] encoder_offsets``; 0 by default.
    output_disturbance : (time, size), optional
        Step added to the measured outputs from ``time`` on; ``size`` a scalar or (2,).
    torque_disturbance : (time, torque), optional
        Step torque (N m) on the arm from ``time`` on.
    u_limit : float
        Actuator saturation (V).
    fall_limit : float
        The run stops, flagged, when ``|alpha|`` (wrapped to (-pi, pi]) exceeds this (rad) while
        the controller balances. A :class:`riprs.SwingUp` may start anywhere (e.g. hanging,
        ``x0=[0, 0, pi, 0]``); for it a fall is leaving its balance region after the catch.
    seed : int
        Seed of the measurement noise; equal seeds give identical runs.
    step_after_catch : float, optional
        With a :class:`riprs.SwingUp`: the scalar ``reference`` step happens this many seconds
        after the catch instead of at ``reference_time`` (``riprs compare --start down`` uses
        ``reference.step_time``, as the rig); no step in a run without a catch.

    Returns
    -------
    SimResult

    Raises
    ------
    InvalidParameterError, ShapeError, NonFiniteError
        A bad setting; the message names it.
    TypeError
        ``plant`` is not a riprs object, ``controller`` is neither a riprs controller nor
        callable, or a callable returned something that is not a number.
    """
    config = _config(
        duration=duration,
        Ts=Ts,
        substeps=substeps,
        x0=x0,
        reference=reference,
        reference_time=reference_time,
        encoder_counts=encoder_counts,
        noise_std=noise_std,
        encoder_offsets=encoder_offsets,
        output_disturbance=output_disturbance,
        torque_disturbance=torque_disturbance,
        u_limit=u_limit,
        fall_limit=fall_limit,
        seed=seed,
        step_after_catch=step_after_catch,
    )
    native = _riprs.sim_run(_as_plant(plant, "plant"), controller, config)
    return SimResult._from_native(native)


def simulate_batch(
    plants: PlantLike | Sequence[PlantLike],
    controller: Controller,
    seeds: Sequence[int] | int = 1,
    duration: float = _riprs.DEFAULT_DURATION,
    *,
    paired: bool = False,
    **options: Any,
) -> list[SimResult]:
    """Run many seeds and plant variants in parallel (Monte Carlo).

    Every pair ``(plant, seed)`` is simulated, each with its own copy of ``controller``, on all
    cores (rayon) with the GIL released. The results come back in plant-major order:
    ``[(plants[0], seeds[0]), (plants[0], seeds[1]), ..., (plants[1], seeds[0]), ...]``.
    With ``paired=True`` run ``i`` is ``(plants[i], seeds[i])`` instead (one fresh plant
    variant and noise seed per run); both sequences must then have the same length.

    Parameters
    ----------
    plants : Plant, FurutaParams or sequence of them
        Parameter variants, e.g. ``[FurutaParams.paper().replace(mp=m) for m in masses]``.
    controller : Lqr, Lqg or another riprs controller
    seeds : int or sequence of int
        An int ``n`` means seeds ``0 .. n-1``.
    paired : bool
        Pair plants and seeds one to one instead of running every combination.
    duration : float
        Length of each run (s).
    **options
        Any keyword of :func:`simulate` except ``seed``.

    Returns
    -------
    list of SimResult
    """
    if "seed" in options:
        raise TypeError("simulate_batch takes seeds=..., not seed=...")
    plant_list = [plants] if isinstance(plants, (Plant, FurutaParams)) else list(plants)
    if not plant_list:
        raise InvalidParameterError("invalid plants: need at least one plant")
    natives = [_as_plant(p, f"plants[{i}]") for i, p in enumerate(plant_list)]
    if isinstance(seeds, (int, np.integer)) and not isinstance(seeds, bool):
        seed_list = list(range(_seed(seeds, "seeds")))
    else:
        seed_list = [_seed(s, f"seeds[{i}]") for i, s in enumerate(seeds)]
    if not seed_list:
        raise InvalidParameterError("invalid seeds: need at least one seed")
    defaults = _DEFAULTS
    unknown = set(options) - set(defaults)
    if unknown:
        raise TypeError(f"unexpected keyword arguments: {sorted(unknown)}")
    config = _config(duration=duration, seed=0, **{**defaults, **options})
    return [
        SimResult._from_native(d)
        for d in _riprs.sim_batch(natives, controller, seed_list, config, paired)
    ]


@dataclass(frozen=True)
class BatchMetrics:
    """Per-run metrics of a :func:`simulate_metrics` study; one entry per run, in run order.

    Attributes
    ----------
    run : ndarray of uint64, shape (N,)
        Run index ``i``.
    seed : ndarray of uint64, shape (N,)
        Noise seed of the run (``seed + i``).
    rmse : ndarray, shape (N, 3)
        The paper's Tab. 1 indices per run, as :attr:`SimResult.rmse`: RMSE of the arm and
        pendulum angles against their references (rad) and RMS of the voltage (V).
    fell : ndarray of bool, shape (N,)
        Whether the pendulum fell.
    diverged : ndarray of bool, shape (N,)
        Whether the integration diverged numerically (as :attr:`SimResult.diverged`); such a
        run is not a fall.
    fall_time : ndarray, shape (N,)
        Time of the fall (s); NaN for runs that stayed up.
    peak_voltage : ndarray, shape (N,)
        Largest applied ``|u|`` (V).
    settle_time : ndarray, shape (N,)
        Earliest sample time from which ``|theta - theta_ref| <= settle_band`` holds to the end
        of the run (s); NaN if the run fell or ended outside the band.
    peak_arm : ndarray, shape (N,)
        Largest true ``|theta|`` at the samples (rad).
    time_to_upright : ndarray, shape (N,)
        Time to upright of a :class:`riprs.SwingUp` run (s), as
        :attr:`SimResult.time_to_upright`; NaN without a catch.
    swing_up_succeeded : ndarray of bool, shape (N,)
        Whether the swing-up succeeded, as :attr:`SimResult.swing_up_succeeded`.
    samples : ndarray of int64, shape (N,)
        Control samples taken (fewer than ``duration / Ts`` after a fall).
    fallbacks : ndarray of int64, shape (N,)
        Steps in which the controller used its fallback.
    """

    run: np.ndarray
    seed: np.ndarray
    rmse: FloatArray
    fell: np.ndarray
    diverged: np.ndarray
    fall_time: FloatArray
    peak_voltage: FloatArray
    settle_time: FloatArray
    peak_arm: FloatArray
    time_to_upright: FloatArray
    swing_up_succeeded: np.ndarray
    samples: np.ndarray
    fallbacks: np.ndarray

    def __len__(self) -> int:
        return len(self.run)


def simulate_metrics(
    plant: PlantLike,
    controller: Controller,
    runs: int,
    duration: float = _riprs.DEFAULT_DURATION,
    *,
    seed: int = 0,
    first_run: int = 0,
    perturbation: float = 0.0,
    parameters: Sequence[str] = (),
    settle_band: float = 0.02,
    progress: Callable[[int, int], object] | None = None,
    cancel: threading.Event | None = None,
    **options: Any,
) -> BatchMetrics:
    r"""Monte Carlo study that keeps a few metrics per run instead of the trajectories.

    Runs ``i = first_run, ..., first_run + runs - 1`` in parallel on all cores. Run ``i`` uses
    noise seed ``seed + i`` and ``plant`` with each parameter named in ``parameters`` multiplied
    by an independent factor drawn uniformly from ``[1 - perturbation, 1 + perturbation]`` by a
    generator seeded from ``(seed, i)``. A run therefore depends on its index alone: a study cut
    into chunks (``first_run``) gives the same numbers as one call. Memory grows by about 80
    bytes per run, never with the length of a run.

    Parameters
    ----------
    plant : Plant or FurutaParams
        The nominal plant.
    controller : Lqr, Lqg, Mpc or SwingUp
        Copied for every run; the object itself is not touched.
    runs : int
        Number of runs (1 to 10 000 000 per call).
    duration : float
        Length of each run (s).
    seed : int
        Noise seed of run 0; also seeds the parameter draws.
    first_run : int
        Index of the first run.
    perturbation : float
        Relative half-width of the parameter factors, in ``[0, 1)``.
    parameters : sequence of str
        Names of the perturbed parameters, as in ``[monte_carlo] parameters`` (``mr``, ``Lr``,
        ``Jr``, ``mp``, ``Lp``, ``Jp``, ``Dr``, ``Dp``, ``Rm``, ``kt``, ``km``).
    settle_band : float
        Half-width of the arm-error band that counts as settled (rad).
    progress : callable, optional
        Called as ``progress(done, runs)`` from the calling thread while the runs proceed.
    cancel : threading.Event, optional
        Setting it from another thread stops the runs like Ctrl-C does (``KeyboardInterrupt``).
        Needed when the call runs off the main thread, where signals are never seen.
    **options
        Any keyword of :func:`simulate` except ``seed``.

    Returns
    -------
    BatchMetrics

    Raises
    ------
    InvalidParameterError, ShapeError, NonFiniteError
        A bad setting; the message names it.
    KeyboardInterrupt
        On Ctrl-C; the runs stop within a fraction of a second.
    """
    if isinstance(runs, bool) or not isinstance(runs, (int, np.integer)):
        raise TypeError(f"runs must be an int, got {type(runs)}")
    if runs < 1:
        raise InvalidParameterError(f"invalid runs: must be at least 1, got {runs}")
    unknown = set(options) - set(_DEFAULTS)
    if unknown:
        raise TypeError(f"unexpected keyword arguments: {sorted(unknown)}")
    config = _config(duration=duration, seed=seed, **{**_DEFAULTS, **options})
    if isinstance(parameters, str):
        raise TypeError("parameters must be a sequence of parameter names, not a str")
    native = _riprs.sim_metrics(
        _as_plant(plant, "plant"),
        controller,
        config,
        int(runs),
        _seed(first_run, "first_run"),
        float(perturbation),
        [str(p) for p in parameters],
        float(settle_band),
        progress,
        cancel,
    )
    return BatchMetrics(**native)

"""The ``riprs`` command line."""

from __future__ import annotations

import argparse
import sys
from typing import Any, Callable, Dict, Sequence, TypeVar

import numpy as np

from riprs import RiprsError, __version__, paper

T = TypeVar("T")


def _format_matrix(name: str, ours: np.ndarray, printed: np.ndarray | None) -> str:
    lines = [f"{name} (riprs" + (" | paper eq. (12) | difference)" if printed is not None else ")")]
    for i in range(ours.shape[0]):
        row = " ".join(f"{v:9.4f}" for v in ours[i])
        if printed is not None:
            row += "  | " + " ".join(f"{v:9.4f}" for v in printed[i])
            row += "  | " + " ".join(f"{v:+9.1e}" for v in ours[i] - printed[i])
        lines.append("  " + row)
    return "\n".join(lines)


def cmd_gains(_: argparse.Namespace) -> int:
    """Print the paper's LQR gain and Kalman gains next to the printed ones."""
    K = paper.lqr_gain()
    L, M = paper.kalman_gains()
    print("LQR gain K (u = -K x): eq. (13) weights, section-3 plant (not printed in the paper)")
    print(_format_matrix("K", K, None))
    print()
    print(_format_matrix("L", L, paper.PRINTED["L"]))
    print()
    print(_format_matrix("M", M, paper.PRINTED["M"]))
    dev_l = np.abs(np.round(L, 4) - paper.PRINTED["L"]).max()
    dev_m = np.abs(M - paper.PRINTED["M"]).max()
    print()
    print(f"max |round(L, 4) - printed L| = {dev_l:.1e};  max |M - printed M| = {dev_m:.1e}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    """LQR, LQG and MPC on the nonlinear plant, Tab. 1 next to the paper's numbers."""
    from pathlib import Path

    from riprs.compare import (
        Trajectory,
        compare,
        format_monte_carlo,
        format_swing_up_monte_carlo,
        start_of_logs,
    )
    from riprs.log import load_log

    if args.hardware:
        return _compare_hardware(args)
    # Logs are read first, so that a wrong path fails before the runs, not after them; their
    # phase column says how the runs started, and the simulations start alike.
    read = {p: load_log(p) for p in args.log or []}
    start = start_of_logs(read, args.start)
    logs = {f"rip-rt {Path(p).stem}": Trajectory.from_log(log) for p, log in read.items()}
    result = compare(
        args.config,
        out=args.out,
        seed=args.seed,
        monte_carlo=args.monte_carlo,
        plots=not args.no_plots,
        progress=not args.quiet,
        overlays=logs,
        start=start,
    )
    print(result.table())
    if result.monte_carlo is not None:
        print()
        print(format_monte_carlo(result.monte_carlo))
        if start == "down":
            print()
            print(format_swing_up_monte_carlo(result.monte_carlo))
    print()
    where = result.files[0].parent if result.files else Path(args.out).absolute()
    print(f"wrote {len(result.files)} files to {where}")
    return 0


def _compare_hardware(args: argparse.Namespace) -> int:
    """``riprs compare --hardware``: the paper's controllers on its fitted rig, Tab. 1 beside
    the paper's hardware column (docs/paper.md, "The hardware column")."""
    from riprs import hardware

    given = [
        flag
        for flag, value in (
            ("--config", args.config),
            ("--log", args.log),
            ("--monte-carlo", args.monte_carlo),
            ("--start", args.start),
        )
        if value is not None
    ]
    if given:
        print(
            f"riprs: error: --hardware runs the paper's rig as the study fitted it; it takes no "
            f"{', '.join(given)}",
            file=sys.stderr,
        )
        return 2
    seeds = (args.seed, args.seed + 1, args.seed + 2)
    print(hardware.format_table(hardware.run(seeds=seeds)))
    print(f"(the mean over noise seeds {', '.join(map(str, seeds))}; no files written)")
    return 0


def cmd_campaign(args: argparse.Namespace) -> int:
    """Many runs over a grid of plant errors and settings; results in Parquet, maps."""
    from riprs import campaign

    if args.example:
        print(campaign.EXAMPLE_SPEC, end="")
        return 0
    if args.spec is None:
        print("riprs: error: campaign needs SPEC.toml (or --example)", file=sys.stderr)
        return 2
    try:
        result = campaign.run(
            args.spec,
            args.out,
            scheduler=args.scheduler,
            workers=args.workers,
            chunk_size=args.chunk_size,
            progress=not args.quiet,
            plots=not args.no_plots,
            map_axes=args.map.split(",") if args.map else None,
        )
    except campaign.CampaignError as exc:
        # run() names its keyword arguments; here they are options.
        flag = {
            "chunk_size": "--chunk-size",
            "workers": "--workers",
            "map_axes": "--map",
            "scheduler": "--scheduler",
        }
        raise (exc.renamed(flag[exc.key]) if exc.key in flag else exc) from None
    except KeyboardInterrupt:
        print(
            f"riprs: interrupted; finished chunks are in {args.out}/runs, the same command resumes",
            file=sys.stderr,
        )
        return 130
    print(campaign.summary(result.aggregates))
    print(
        f"{result.aggregates.runs} runs in {args.out}/runs ({result.chunks} chunks of "
        f"{result.chunk_size} runs computed now, engine: {result.engine}); "
        f"{len(result.files)} figures"
    )
    return 0


def cmd_identify(args: argparse.Namespace) -> int:
    """Fit the nonlinear model to excitation logs; report, figures, the [plant] file and the
    identification file beside it. An untrusted fit writes nothing unless --force."""
    import warnings
    from pathlib import Path

    from riprs import _outputs
    from riprs.identify import (
        IdentifyError,
        IdentifyWarning,
        identification_path,
        identify,
        plot_fit,
    )
    from riprs.log import load_log

    out = Path(args.out)
    names = [Path(p).stem for p in args.logs]
    inputs = [*args.logs, *([args.lab] if args.lab else [])]
    # The outputs are checked before the fit, which takes minutes; the logs are never
    # replaced.
    out, side = _renamed(
        lambda: _outputs.check([out, identification_path(out)], key="out", inputs=inputs),
        {"out": "--out"},
    )
    with warnings.catch_warnings():
        # The report prints every warning once, after the numbers.
        warnings.simplefilter("ignore", IdentifyWarning)
        result = identify(
            args.logs,
            start=args.start,
            holdout=args.holdout,
            segment=args.segment,
            max_iter=args.max_iter,
            lab=args.lab,
        )
    print(result.report())
    if result.problems and not args.force:
        raise IdentifyError(
            f"{', '.join(Path(p).name for p in args.logs)}: the identified model cannot be "
            f"trusted ({len(result.problems)} problems above); {out} was not written. Fix what "
            "they name (a lab file with --lab, more excitation) or pass --force to write it "
            "marked as untrusted"
        )
    source = ", ".join(Path(p).name for p in args.logs)
    _outputs.write([(out, result.to_toml(source)), (side, result.identification_toml(source))])
    figures = []
    if not args.no_plots:
        for name, path in zip(names, args.logs, strict=True):
            log = load_log(path)
            figures.append(plot_fit(result, log, name, out.with_name(f"{out.stem}-{name}.png")))
    print()
    print(
        f"wrote {out}{' (UNTRUSTED, --force)' if result.problems else ''} and {side}"
        + (f" and {len(figures)} figures next to them" if figures else "")
    )
    return 0


def _renamed(call: Callable[[], T], flags: Dict[str, str]) -> T:
    """``call()``, an error whose message begins with one of the keyword arguments of
    ``flags`` raised again naming its option instead (``seed: ...`` -> ``--seed: ...``)."""
    try:
        return call()
    except RiprsError as exc:
        text = str(exc)
        for key, flag in flags.items():
            if text.startswith(f"{key}: "):
                raise RiprsError(flag + text[len(key) :]) from None
        raise


def cmd_watch(args: argparse.Namespace) -> int:
    """Watch rip-rt's live stream, or draw a log, a simulation or both, in the live view."""
    from riprs.config import ConfigError

    try:
        from riprs import live
    except ImportError as exc:  # pragma: no cover - the extension is part of riprs
        raise ConfigError(str(exc)) from exc
    if args.compare and not args.log:
        raise ConfigError("--compare needs --log FILE.csv (the log to compare with its simulation)")
    if args.log and args.simulate:
        raise ConfigError("--log and --simulate draw different things: give one of them")
    for name in ("once", "idle", "stats", "ready"):
        if (args.log or args.simulate) and getattr(args, name) not in (None, False):
            raise ConfigError(f"--{name} applies to the live stream, not to --log or --simulate")
    spawn = args.save is None
    try:
        if args.log and args.compare:
            live.show_comparison(
                args.log, args.config, controller=args.controller, save=args.save, spawn=spawn
            )
        elif args.log:
            live.show_log(args.log, save=args.save, spawn=spawn)
        elif args.simulate:
            from riprs import compare as cmp
            from riprs.config import Spec, load_config
            from riprs.sim import simulate

            cfg = load_config(args.config) if args.config else Spec()
            controllers = cmp.build_controllers(cfg)
            if args.start == "down":
                controllers = cmp._supervised(cfg, controllers)
            duration = args.duration or cmp._duration(cfg, args.start)
            result = simulate(
                cfg.build_plant(),
                controllers[args.simulate.upper()],
                duration,
                **cmp._sim_options(cfg, args.start),
            )
            live.show_simulation(result, save=args.save, spawn=spawn)
        else:
            if not args.quiet:
                print(
                    f"riprs: watching 127.0.0.1:{args.port} (rip-rt ... --live {args.port}); "
                    "Ctrl-C stops",
                    file=sys.stderr,
                )
            stats = live.watch(
                args.port,
                save=args.save,
                spawn=spawn,
                once=args.once,
                idle=args.idle,
                stats=args.stats,
                ready=args.ready,
            )
            if not args.quiet:
                s = stats.summary()
                print(
                    f"riprs: received {s['frames']} of {s['expected']} frames; "
                    f"lag p50 {s['lag_ms']['p50']} ms, p99 {s['lag_ms']['p99']} ms",
                    file=sys.stderr,
                )
    except ImportError as exc:
        raise ConfigError(str(exc)) from exc
    return 0


def cmd_tune(args: argparse.Namespace) -> int:
    """Choose shared LQR/LQG/MPC weights for a rig and write the tuned experiment file."""
    from riprs._riprs import identification_untrusted
    from riprs.config import ConfigError
    from riprs.tune import check_out, tune

    # Everything that can be found wrong is found before the search, which takes up to a
    # minute: the outputs, then the arguments and the rig's voltage (in tune()).
    out, _ = _renamed(
        lambda: check_out(args.out, args.rig, overwrite=args.force, key="out", force="--force"),
        {"out": "--out"},
    )
    untrusted = identification_untrusted(args.rig)
    if untrusted:
        # Said before the search, not after it: the weights are only as good as this model.
        print(f"riprs: warning: {untrusted}", file=sys.stderr)
    result = _renamed(
        lambda: tune(
            args.rig,
            runs=args.runs,
            seed=args.seed,
            spread=args.spread,
            progress=not args.quiet,
            swing_up=not args.no_swing_up,
        ),
        {"runs": "--runs", "seed": "--seed", "spread": "--spread"},
    )
    print(result.report())
    if result.refusal is not None:
        raise ConfigError(f"{args.rig}: {result.refusal}; {out} was not written")
    side = _renamed(lambda: result.write(out, overwrite=args.force), {"out": "--out"})
    print()
    print(f"wrote {out} (riprs compare --config, riprs campaign and rip-rt run --config read it)")
    print(f"wrote {side} (the predictions rip-rt run's pre-flight reads while they are current)")
    return 0


REFERENCE_HEADER = """# Configuration reference

One TOML file drives `riprs compare --config FILE`, `riprs.load_config(FILE)`,
`rip-rt run --config FILE` and `rip-rt emulate --config FILE`. Its sections are defined once,
in `rip-core` (`crates/rip-core/src/spec/`), with every default and every check; each key is
documented there (`cargo doc -p rip-core`, module `spec`). A key that does not exist, or a
value of the wrong type or range, is an error naming the file and the key path, e.g.
`cfg.toml: mpc.prediction_horizon: must be in 1..=10000, got 0`, from `riprs` and `rip-rt`
alike. Where two keys are checked against each other and the file wrote only one (a
`[plant] Cr` whose friction voltage the compensation's default would have to fit inside the
input bounds, a `[safety] arm_limit` inside the default arm step), the error names the key the
file wrote and the values of it that would work, never the default.

Every key is optional. Below is the complete file with every default (the paper's settings),
as `riprs config` prints it; `riprs config FILE` prints a file resolved the same way.
`rip-rt` adds its own `[loop]`, `[device]`, `[safety]` and `[calibration]` sections
([rip-rt.md](rip-rt.md)); `rip-rt config FILE` prints them after these, resolved. A file
riprs reads keeps the ones it sets: `riprs config FILE`, `Spec.to_toml` and the file
`riprs tune` writes carry them after the experiment's, as the file gave them.

- `controllers`: what `riprs compare` runs.
- `[plant]`: `preset` (`paper` or `qube_servo2`) and the physical parameters
  `mr, Lr, Jr, mp, Lp, Jp, Dr, Dp, Rm, kt, km` (SI units), Coulomb friction `Cr, Cp` (N m,
  sign smoothed as `tanh(rate / 0.05 rad/s)`) and the voltage dead zone `Vd` (V, applied
  voltage `u - clip(u, -Vd, Vd)`) and the cable's stiffness `Kc` (N m/rad, a torque
  `-Kc theta` on the arm about its zero; 0 in both presets), each overriding the preset, and
  optionally the arm's breakaway torque `arm_breakaway` (N m, at least `Cr`: stiction of the
  simulated plant, friction decaying as `exp(-(rate / 0.1 rad/s)^2)` to `Cr`, which no
  controller knows), so an identified rig (`riprs identify`) is a file; the controllers are
  designed on this plant's linearisation at the loop period without friction and dead zone
  but with the cable (the unchanged `paper` preset keeps the paper's recovered model).
  `substeps`, `initial_state`, `fall_limit` set up a simulated run.
- `[sensor]`: the rig's encoders, simulated or real: counts per revolution (128 to 2^24; the
  one resolution `rip-rt` turns counts into angles with, and the emulator counts in),
  white-noise standard deviation (rad) and encoder zero offsets (rad; an encoder reads
  `angle + offset`). `riprs compare` and `rip-rt emulate` simulate all three alike. The
  former `[device] arm_counts_per_rev` and `pendulum_counts_per_rev` are refused, naming
  `sensor.encoder_counts`.
- `[reference]`: the arm step (rad), its time (s) and the run length (s).
- `[lqr]`: `Q` (diagonal) and `R` of eq. (13), shared by LQR and LQG; LQR's rate-filter
  cut-off (Hz, `inf` for none); `integral_weight`, the weight of the integrated arm error in
  LQR's and LQG's integral action (MATLAB's `lqi`, [design.md](design.md#integral-action);
  0, the paper's setting, for none); `disturbance_bandwidth` (Hz, default 0 for none), LQR's
  own: an observer of a disturbance at the plant input whose estimate its law cancels
  ([tuning.md](tuning.md#lqr-cancelling-an-input-disturbance)); `riprs tune` sets it where
  LQR needs it.
- `[kalman]`: the one Kalman filter LQG and MPC share: the output-disturbance gain of eq. (1)
  and the measurement-noise diagonal of eq. (2). `input_disturbance` (V² per period, default
  0) gives LQG a filter of its own instead, on the model with a random-walk disturbance at
  the plant input whose estimate its law cancels, `u = −K (x̂ − x_ref) − d̂`: what the
  compensation leaves of a dead zone, friction or breakaway torque
  ([tuning.md](tuning.md#lqg-cancelling-an-input-disturbance)); `riprs tune` sets it where
  LQG needs it. `regulate_outputs` (default `false`, the paper's LQG) makes LQG's law act on
  the estimated outputs, the plant part of the shared filter's estimate plus what the output
  disturbance of eq. (1) adds to each angle, as the MPC's cost does
  ([tuning.md](tuning.md#lqg-regulating-the-estimated-outputs)); `riprs tune` sets it where
  LQG needs it.
- `[mpc]`: section 3's MPC; the section is the MPC's own settings (`MpcSettings`, the keywords
  of Python's `riprs.Mpc`), each missing key taking the paper profile (`riprs.Mpc.paper()`,
  which is this section's default exactly, solver included; `riprs.Mpc(...)`'s own keyword
  defaults are MATLAB's, e.g. `prediction_horizon = 10`). `prediction_step` (periods, default
  1, no MATLAB equivalent) puts the prediction, its cost and its soft bounds on a grid of that
  many loop periods, each move held for one grid step: the horizon is `prediction_horizon ·
  prediction_step` periods, so a 1 kHz loop keeps the paper's 0.5 s and its QP's size with
  `prediction_step = 10` ([firmware.md](firmware.md)). `input_bounds` (V) also clamps LQR
  and LQG; `output_bounds` per output, `[-inf, inf]` for none, `[y, y]` a soft equality;
  `input_target` is the input `input_weights` pull towards. `solver` is `active_set` (the
  default everywhere) or `clarabel`: both solve the same strictly convex QP, the active set
  exactly to rounding and Clarabel to its stopping tolerances (about 1e-6 V in the first move;
  [design.md](design.md) gives both measured against the exact solution); the active set also
  warm-starts from the previous working set, runs without allocating in the 100 Hz loop and
  costs about a hundredth of Clarabel's interior-point solve per step.
- `[compensation]`: the dead zone and arm Coulomb friction compensated on the voltage of
  every controller and of the swing-up (dead-zone inverse and friction feed-forward,
  [design.md](design.md#dead-zone-and-friction-compensation)): `dead_zone` (V) and
  `arm_friction` (N m) default to the `[plant]`'s `Vd` and `Cr`, `voltage_scale` (V) and
  `velocity_scale` (rad/s) are the widths of the ramps that replace their signs;
  `dead_zone_gain` and `friction_gain` (default 1) are the multiples of the dead zone and the
  friction the correction applies, which `riprs tune` raises where an identification 30 % off
  would leave the arm in a limit cycle ([tuning.md](tuning.md#the-compensations-gains)); the
  controllers then plan within `input_bounds` shrunk by the correction, so the voltage written
  stays inside them. `enabled = false` runs the controllers uncompensated; a rig with neither
  (every preset) has none. A dead zone and friction voltage (`Cr Rm / kt`) that together
  leave no room inside `input_bounds` are refused through the key written for the larger of
  the two (`compensation.dead_zone` or `plant.Vd`, `compensation.arm_friction` or
  `plant.Cr`, or its gain where that is not 1), with the largest value of it that fits.
- `[monte_carlo]`: runs over noise seeds and uniform perturbations of the named parameters.

```toml
"""


def reference() -> str:
    """The configuration reference (``docs/configuration.md``), generated from the spec."""
    from riprs.config import Spec

    return REFERENCE_HEADER + Spec().to_toml() + "```\n"


def cmd_config(args: argparse.Namespace) -> int:
    """Print the resolved configuration (every default filled in) as TOML."""
    from riprs.config import Spec, load_config

    if args.reference:
        print(reference(), end="")
        return 0
    spec = load_config(args.file) if args.file else Spec()
    print(spec.to_toml(), end="")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="riprs",
        description="LQR, LQG and MPC for the rotary inverted pendulum.",
    )
    parser.add_argument("--version", action="version", version=f"riprs {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    gains = sub.add_parser("gains", help="print the paper's LQR and Kalman gains")
    gains.set_defaults(func=cmd_gains)
    comp = sub.add_parser(
        "compare",
        help="run the paper's LQR / LQG / MPC comparison on the nonlinear plant",
        description="Designs LQR, LQG and MPC with the paper's weights, runs them on the "
        "nonlinear paper plant with sensor noise while the arm steps 0 -> 1 rad, prints Tab. 1 "
        "next to the paper's numbers and writes CSV files and figures.",
    )
    comp.add_argument("--config", metavar="FILE.toml", help="settings (default: the paper's)")
    comp.add_argument("--out", metavar="DIR", default="riprs-compare", help="output directory")
    comp.add_argument("--seed", type=int, default=0, metavar="N", help="noise seed (default 0)")
    comp.add_argument(
        "--monte-carlo",
        type=int,
        default=None,
        metavar="N",
        help="N runs over noise seeds and parameter perturbations",
    )
    comp.add_argument(
        "--start",
        choices=("up", "down"),
        default=None,
        help="up: balanced near upright (the paper's experiment, default); down: hanging at "
        "rest, swung up and caught first, the step reference.step_time after the catch. With "
        "--log, default: as the logged run started (its phase column); a logged swing-up is "
        "drawn from the start of its swing",
    )
    comp.add_argument("--log", action="append", metavar="FILE.csv", help="rip-rt log to overlay")
    comp.add_argument(
        "--hardware",
        action="store_true",
        help="the paper's controllers as printed on the rig its hardware study fitted (dead "
        "zone, arm friction, cable, encoders, noise: riprs.hardware.RIG); prints Tab. 1 over "
        "the study's window beside the paper's hardware column, the mean over seeds N, N+1, "
        "N+2; writes no files",
    )
    comp.add_argument("--no-plots", action="store_true", help="skip the figures")
    comp.add_argument("--quiet", action="store_true", help="no progress bars")
    comp.set_defaults(func=cmd_compare)
    conf = sub.add_parser(
        "config",
        help="print a configuration file resolved, every default filled in",
        description="Checks FILE as riprs compare does (designs included) and prints it as "
        "TOML with every default filled in; without FILE, the defaults.",
    )
    conf.add_argument("file", nargs="?", metavar="FILE.toml", help="configuration file")
    conf.add_argument(
        "--reference", action="store_true", help="print docs/configuration.md instead"
    )
    conf.set_defaults(func=cmd_config)
    camp = sub.add_parser(
        "campaign",
        help="many runs over a grid of plant errors and settings (robustness maps)",
        description="Runs every controller over the grid and seeds of a campaign spec, in "
        "process on all cores or on a Dask cluster, writes one Parquet row per run and "
        "robustness maps; the same command resumes an interrupted campaign.",
    )
    camp.add_argument("spec", nargs="?", metavar="SPEC.toml", help="campaign spec")
    camp.add_argument("--out", metavar="DIR", default="riprs-campaign", help="output directory")
    camp.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a running Dask scheduler")
    camp.add_argument("--workers", type=int, metavar="N", help="start a local Dask cluster")
    camp.add_argument("--chunk-size", type=int, metavar="N", help="runs per chunk")
    camp.add_argument("--map", metavar="X,Y", help="axes of the maps (default: the first two)")
    camp.add_argument("--example", action="store_true", help="print the example spec")
    camp.add_argument("--no-plots", action="store_true", help="skip the figures")
    camp.add_argument("--quiet", action="store_true", help="no progress bar")
    camp.set_defaults(func=cmd_campaign)
    ident = sub.add_parser(
        "identify",
        help="fit the nonlinear model to rip-rt excite logs and write a [plant] file",
        description="Output-error fit of the nonlinear Furuta model (rigid-body combinations, "
        "motor constant, viscous and Coulomb friction, dead zone) to excitation logs; prints "
        "the estimates with standard errors, the held-out fit per log and output and the "
        "identifiability diagnostics, draws measured vs simulated for each log next to --out "
        "and writes the [plant] file that riprs compare, rip-rt run and rip-rt emulate read.",
    )
    ident.add_argument("logs", nargs="+", metavar="LOG.csv", help="rip-rt excite logs")
    ident.add_argument("--out", metavar="RIG.toml", required=True, help="[plant] file to write")
    ident.add_argument(
        "--start",
        metavar="paper|qube_servo2|FILE",
        default="qube_servo2",
        help="start set; holds mp, Lp, mr, Rm and g where the lab file does not give them, "
        "and km = kt unless it gives km (default qube_servo2)",
    )
    ident.add_argument(
        "--holdout", type=float, default=0.25, metavar="F", help="held-out fraction of each log"
    )
    ident.add_argument(
        "--segment", type=float, default=2.0, metavar="S", help="simulated segment length (s)"
    )
    ident.add_argument("--max-iter", type=int, default=60, metavar="N", help="iteration limit")
    ident.add_argument(
        "--lab",
        metavar="LAB.toml",
        help="lab file: measured masses, lengths, motor resistance, encoder counts (docs/rig.md)",
    )
    ident.add_argument(
        "--force",
        action="store_true",
        help="write the rig file even when the fit cannot be trusted (marked as such)",
    )
    ident.add_argument("--no-plots", action="store_true", help="skip the figures")
    ident.set_defaults(func=cmd_identify)
    tun = sub.add_parser(
        "tune",
        help="choose shared LQR/LQG/MPC weights for a rig and write the tuned file",
        description="Keeps the file's shared weights where they work; otherwise chooses shared "
        "weights (one Q, R for LQR, LQG and MPC; the estimator's measurement noise; integral "
        "action where needed) that stay inside the voltage bound on the reference step, keep "
        "margins of 6 dB and 30 deg at the plant input (or the disk margin of that disk) and "
        "balance the rig's model within the bar; prints per controller the predicted RMSE, "
        "margins and the fraction of rigs drawn around this one that it balances.",
    )
    tun.add_argument("rig", metavar="RIG.toml", help="the rig's experiment file")
    tun.add_argument("--out", metavar="TUNED.toml", required=True, help="tuned file to write")
    tun.add_argument(
        "--runs", type=int, default=20, metavar="N", help="robustness runs per controller"
    )
    tun.add_argument("--seed", type=int, default=0, metavar="N", help="their seed")
    tun.add_argument(
        "--no-swing-up",
        action="store_true",
        help="skip the search of the swing-up's catch settings (up to a minute; the file's "
        "[swing_up] is kept and rip-rt run --swing-up judges it by the energy bound alone)",
    )
    tun.add_argument(
        "--spread",
        type=float,
        default=0.1,
        metavar="F",
        help="relative spread of each parameter without an identification covariance",
    )
    tun.add_argument(
        "--force",
        action="store_true",
        help="write the tuned file even where it replaces RIG.toml",
    )
    tun.add_argument("--quiet", action="store_true", help="no progress bar")
    tun.set_defaults(func=cmd_tune)
    _watch_parser(sub)
    return parser


def _watch_parser(sub: Any) -> None:
    wat = sub.add_parser(
        "watch",
        help="watch a rip-rt run live (scopes and the rig), or a log or simulation after it",
        description="Receives the telemetry of `rip-rt run/excite/emulate --live PORT` and "
        "draws it in the Rerun viewer (the live extra: pip install 'riprs[live]'): scopes of "
        "the arm, pendulum and voltage with their limits, the loop's timing, events and the "
        "rig, measured and true. With --log, --simulate or --log --compare, the same panels "
        "after the fact. --save writes a .rrd recording instead of opening a window "
        "(`rerun FILE.rrd` opens it).",
    )
    wat.add_argument(
        "--port",
        type=_port,
        default=9870,
        metavar="N",
        help="UDP port on 127.0.0.1 to listen on (default 9870)",
    )
    wat.add_argument("--save", metavar="FILE.rrd", help="write a recording, no window")
    wat.add_argument("--once", action="store_true", help="end after the first run's stop")
    wat.add_argument(
        "--idle", type=float, metavar="S", help="end after S seconds without a frame"
    )
    wat.add_argument(
        "--stats", metavar="FILE.json", help="write the frames received and the lag at the end"
    )
    wat.add_argument(
        "--ready", metavar="FILE", help="create FILE once listening (for scripts)"
    )
    wat.add_argument("--log", metavar="FILE.csv", help="draw this rip-rt log")
    wat.add_argument(
        "--compare",
        action="store_true",
        help="with --log: also its simulation, aligned as riprs compare --log aligns them",
    )
    wat.add_argument(
        "--simulate", choices=["lqr", "lqg", "mpc"], help="draw a simulation of this controller"
    )
    wat.add_argument(
        "--controller",
        choices=["lqr", "lqg", "mpc"],
        help="with --compare: the controller to simulate (default: the log's)",
    )
    wat.add_argument("--config", metavar="FILE.toml", help="experiment file (default: paper)")
    wat.add_argument(
        "--start", choices=["up", "down"], default="up", help="with --simulate: the start"
    )
    wat.add_argument(
        "--duration", type=float, metavar="S", help="with --simulate: seconds (default: file's)"
    )
    wat.add_argument("--quiet", action="store_true", help="no messages")
    wat.set_defaults(func=cmd_watch)


def _port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer in 1..65535, got {text!r}") from None
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"must be in 1..65535, got {port}")
    return port


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    try:
        return int(args.func(args))
    except (RiprsError, OSError) as exc:
        print(f"riprs: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        # Native work stops within a fraction of a second of Ctrl-C and raises this; outputs
        # are staged, so nothing half-written is left behind. 130 = 128 + SIGINT, as shells do.
        print("riprs: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

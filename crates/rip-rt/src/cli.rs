//! The `rip-rt` command line: the 100 Hz control loop over serial (`run`), the identification
//! experiment (`excite`), the device emulator (`emulate`) and the resolved configuration
//! (`config`).
//!
//! [`run`] is the whole program, from its arguments to its exit code. The `rip-rt` binary is a
//! thin `main` around it, and the Python package's `rip-rt` console script calls it in-process
//! through the native module (so `pip install` puts a working `rip-rt` on the PATH). Either way
//! the exit codes (`rip-rt run --help`) and the signal dispositions ([`crate::stop`]) are the
//! same: they are set here, not by the caller.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use clap::{Parser, Subcommand};

use rip_rt::config::Config;
use rip_rt::controllers::{self, ControllerKind};
use rip_rt::emulator::{self, EmulatorConfig, EmulatorExit, Wiring};
use rip_rt::log::LogWriter;
use rip_rt::loop_core::LoopCore;
use rip_rt::plant::Model;
use rip_rt::runner::{self, RunOptions};
use rip_rt::serial::{Pty, SerialPort};
use rip_rt::stop::{self, exit_code, SetupError, StopReason};
use rip_rt::timing;

mod excite_cmd;
mod preflight_cmd;
use excite_cmd::{ExciteArgs, EXCITE_AFTER_HELP};

const RUN_AFTER_HELP: &str = "\
Exit codes (docs/rip-rt.md has the safety rules behind each):
    0    the run finished (--duration elapsed)
    1    could not start: port (missing, busy), log file (header not writable) or controller
         design failed (motor never enabled)
    2    bad command line or configuration
    3    device lost: I/O error, or the device vanished
    4    watchdog: no valid measurement for loop.watchdog_periods periods (at most 100 ms)
    5    angle limit exceeded (safety.pendulum_limit / safety.arm_limit), or with --swing-up
         the rig left the balance region after the catch with swing_up.on_fall = stop: the
         pendulum past swing_up.balance_angle or the arm past swing_up.arm_limit (the message
         names which)
    6    refused to start: pendulum not within safety.start_tolerance of upright
    7    controller fault: non-finite output
    8    the device reported a driver fault
    9    log fault: the log could not be written (disk full, file-size limit, storage stalled)
    10   compute overrun: a step over loop.max_step_periods, loop.max_consecutive_misses
         periods in a row longer than a period, or the loop stalled (suspended) for 100 ms
    11   refused to start: timed controller steps do not fit the period (motor never enabled)
    12   refused to start: the rig is not at rest hanging down (rest check; motor never enabled)
    13   swing-up failed: no catch within swing_up.max_time; or, after falls with
         swing_up.on_fall = retry, the swing-ups took swing_up.max_time in total, or the run
         was not balanced for --duration within swing_up.max_time + --duration
    14   refused the swing (--swing-up): the sign check's pulse found a reversed motor or
         encoder, or a silent encoder (the message says what to swap or flip)
    15   the rig did not move as commanded (the witness: the measured motion disagrees with
         what the applied voltage must produce; the message names the likely fault)
    16   refused to start by the pre-flight check: an untrusted identification, an
         identification or tuning record beside the rig file that cannot be read, a rig no
         controller can balance at the voltage bound, a controller predicted to fall, or with
         --swing-up a rig that cannot be swung up (the energy balance of the last swing) (the
         message says why; --force runs it anyway; motor never enabled)
    101  internal error (panic)
    128+N  stopped by signal N: 129 SIGHUP, 130 SIGINT (Ctrl-C), 131 SIGQUIT, 143 SIGTERM,
         148 SIGTSTP (Ctrl-Z), ...; the stop runs first (a balanced pendulum lowered; at most
         14 s); a second one disables the driver at once, giving up safety.arm_limit (log:
         stop: signal_again); a fatal signal (SIGSEGV, ...) ends it after the stop command
Every exit after the device was opened sends 0 V with the driver disabled.";

#[derive(Debug, Parser)]
#[command(
    name = "rip-rt",
    version,
    about = "Real-time control loop for the rotary inverted pendulum over a serial link, \
             and a device emulator"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a controller in a periodic loop against the device on PORT.
    #[command(after_help = RUN_AFTER_HELP)]
    Run(RunArgs),
    /// Run an identification experiment (chirp, PRBS, steps or free swing) with the pendulum
    /// hanging down: rest check, sign check, excitation; logged for `riprs identify`.
    #[command(after_help = EXCITE_AFTER_HELP)]
    Excite(ExciteArgs),
    /// Emulate the device on a new pseudo-terminal (prints its path).
    Emulate(Box<EmulateArgs>),
    /// Print the resolved configuration (every default filled in) as TOML; its experiment
    /// sections are exactly what `riprs config` prints for the same file.
    Config(ConfigArgs),
}

#[derive(Debug, clap::Args)]
struct ConfigArgs {
    /// The configuration file (default: the built-in defaults).
    #[arg(value_name = "FILE.toml")]
    file: Option<PathBuf>,
}

fn cmd_config(args: ConfigArgs) -> ExitCode {
    let cfg = match &args.file {
        Some(path) => Config::load(path),
        None => Ok(Config::default()),
    };
    // The designs are part of the check, as in `rip-rt run` and `riprs config`.
    let checked = cfg.and_then(|cfg| {
        cfg.spec
            .design(cfg.period_s())
            .and_then(|d| d.controllers().map(|_| ()))
            .map_err(|e| match &args.file {
                Some(path) => e.in_file(path),
                None => e,
            })?;
        Ok(cfg)
    });
    match checked {
        Ok(cfg) => {
            print!("{}", cfg.to_toml());
            ExitCode::SUCCESS
        }
        Err(e) => fail(exit_code::USAGE, e),
    }
}

pub(crate) fn positive_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("not a number: {s:?}"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("must be a positive number of seconds, got {s}"))
    }
}

fn nonnegative(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("not a number: {s:?}"))?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("must be a non-negative number, got {s}"))
    }
}

fn probability(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("not a number: {s:?}"))?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be a probability in [0, 1], got {s}"))
    }
}

fn finite(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("not a number: {s:?}"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("must be finite, got {s}"))
    }
}

pub(crate) fn cpu(s: &str) -> Result<usize, String> {
    let max = libc::CPU_SETSIZE as usize - 1;
    match s.parse::<i64>() {
        Ok(v) if (0..=max as i64).contains(&v) => Ok(v as usize),
        Ok(v) => Err(format!("must be a CPU number in 0..={max}, got {v}")),
        Err(_) => Err(format!("not a CPU number: {s:?}")),
    }
}

pub(crate) fn baud(s: &str) -> Result<u32, String> {
    let v: u32 = s.parse().map_err(|_| format!("not a baud rate: {s:?}"))?;
    if rip_rt::serial::SUPPORTED_BAUDS.contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "must be one of {:?}, got {v}",
            rip_rt::serial::SUPPORTED_BAUDS
        ))
    }
}

fn model(s: &str) -> Result<Model, String> {
    match rip_core::spec::Preset::from_name(s) {
        Some(rip_core::spec::Preset::Paper) => Ok(Model::Paper),
        Some(rip_core::spec::Preset::QubeServo2) => Ok(Model::QubeServo2),
        None => Err(format!("must be paper or qube_servo2, got {s:?}")),
    }
}

#[derive(Debug, clap::Args)]
struct RunArgs {
    /// Serial device of the pendulum (e.g. /dev/ttyACM0, or the path `rip-rt emulate` prints).
    #[arg(long, value_name = "PATH")]
    port: PathBuf,
    /// Baud rate (ignored by USB CDC devices and pseudo-terminals).
    #[arg(long, value_name = "N", default_value_t = 115200, allow_negative_numbers = true, value_parser = baud)]
    baud: u32,
    /// Controller: lqr, lqg or mpc.
    #[arg(long, value_name = "NAME")]
    controller: ControllerKind,
    /// TOML configuration (see docs/rip-rt.md); defaults are the paper's settings.
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// Stop after this many seconds of balancing (default: run until stopped).
    #[arg(long, value_name = "S", allow_negative_numbers = true, value_parser = positive_seconds)]
    duration: Option<f64>,
    /// Write a CSV log of every period.
    #[arg(long, value_name = "FILE.csv")]
    log: Option<PathBuf>,
    /// Run the loop with SCHED_FIFO at this priority (1-99) and locked memory, if permitted.
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = clap::value_parser!(i32).range(1..=99))]
    rt_priority: Option<i32>,
    /// Pin the loop to this CPU, if permitted.
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = cpu)]
    cpu: Option<usize>,
    /// Only print the final summary.
    #[arg(long)]
    quiet: bool,
    /// Start with the pendulum hanging at rest: check the rest, calibrate the encoders from it,
    /// check the motor sign and encoder directions with a small pulse (exit 14), swing up with the `[swing_up]` settings and catch with the controller, then run the
    /// experiment (the reference step and --duration count from the catch; a fall, retried,
    /// starts them again at the next catch).
    #[arg(long)]
    swing_up: bool,
    /// Run in lockstep with `rip-rt emulate --lockstep`: no period waits for the wall clock,
    /// the emulator advances its plant one period per exchange (refused by any other device).
    #[arg(long)]
    lockstep: bool,
    /// Run the controller on the device (protocol v2): after the same pre-flight check as
    /// without it (exit 16, --force), upload the design, verify its checksum, start onboard
    /// mode, then supervise and log the device's telemetry.
    #[arg(long, conflicts_with = "swing_up")]
    onboard: bool,
    /// Run even when the pre-flight check refuses (an untrusted or unreadable
    /// identification, an unreadable tuning record, a rig no controller can balance at the
    /// voltage bound, a controller predicted to fall, a rig that cannot be swung up; exit 16).
    #[arg(long)]
    force: bool,
    /// Publish every period's telemetry to `riprs watch` on UDP port PORT of 127.0.0.1
    /// (overrides `[loop] live_port`; docs/live.md); a slow viewer loses frames, not time.
    #[arg(long, value_name = "PORT", value_parser = clap::value_parser!(u16).range(1..))]
    live: Option<u16>,
}

#[derive(Debug, clap::Args)]
struct EmulateArgs {
    /// Also make a symbolic link at PATH to the device (removed on exit).
    #[arg(long, value_name = "PATH")]
    link: Option<PathBuf>,
    /// Simulated pendulum: paper (fitted to the paper's model) or qube_servo2 (QUBE-Servo 2).
    #[arg(long, value_name = "NAME", default_value = "paper", value_parser = model, conflicts_with = "config")]
    model: Model,
    /// Simulate the `[plant]` of this configuration file (preset and parameters), the same
    /// file `rip-rt run --config` and `riprs compare --config` read.
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// Gaussian noise on each encoder reading, standard deviation in counts. Default: the
    /// `[sensor] noise_std` of --config, else none.
    #[arg(long, allow_negative_numbers = true, value_name = "COUNTS", value_parser = nonnegative)]
    noise: Option<f64>,
    /// Probability that a measurement is not sent.
    #[arg(long, allow_negative_numbers = true, value_name = "P", default_value_t = 0.0, value_parser = probability)]
    drop_rate: f64,
    /// Probability that a measurement is corrupted (flipped byte or inserted garbage).
    #[arg(long, allow_negative_numbers = true, value_name = "P", default_value_t = 0.0, value_parser = probability)]
    corrupt_rate: f64,
    /// Vanish (close the device) this many seconds after the first command.
    #[arg(long, allow_negative_numbers = true, value_name = "S", value_parser = nonnegative)]
    vanish_after: Option<f64>,
    /// Exit after this many seconds.
    #[arg(long, allow_negative_numbers = true, value_name = "S", value_parser = positive_seconds)]
    duration: Option<f64>,
    /// Initial pose: `up` (0.05 rad from upright, held there until the first enabling command,
    /// as by an operator) or `down` (hanging at rest). Default: the `[plant] initial_state` of
    /// --config, else `up`.
    #[arg(long, value_name = "POSE", value_parser = ["up", "down"], conflicts_with = "initial_pendulum")]
    start: Option<String>,
    /// Initial pendulum angle from upright (rad), instead of --start.
    #[arg(long, value_name = "RAD", allow_negative_numbers = true, value_parser = finite)]
    initial_pendulum: Option<f64>,
    /// Initial arm angle (rad). Default: the `[plant] initial_state` of --config, else 0.
    #[arg(long, value_name = "RAD", allow_negative_numbers = true, value_parser = finite)]
    initial_arm: Option<f64>,
    /// Let the pendulum fall from the start instead of holding it until the first enabling
    /// command.
    #[arg(long)]
    no_hold: bool,
    /// Device watchdog: zero the motor when no command arrives for this long (s).
    #[arg(long, allow_negative_numbers = true, value_name = "S", default_value_t = 0.05, value_parser = positive_seconds)]
    command_timeout: f64,
    /// Simulation rate (Hz).
    #[arg(long, allow_negative_numbers = true, value_name = "HZ", default_value_t = 1000.0, value_parser = positive_seconds)]
    sim_rate: f64,
    /// Seed of the noise and fault generator.
    #[arg(
        long,
        allow_negative_numbers = true,
        value_name = "N",
        default_value_t = 1
    )]
    seed: u64,
    /// Append every command the device receives to this CSV (t_s,seq,voltage_mv,flags).
    #[arg(long, value_name = "FILE.csv")]
    record: Option<PathBuf>,
    /// Write the simulated plant's true state to this CSV
    /// (t_s,theta,theta_dot,alpha,alpha_dot,voltage,current,driver), from the simulation
    /// rather than the encoders; each row is flushed at once, and a last row is written on
    /// exit.
    #[arg(long, value_name = "FILE.csv")]
    true_state: Option<PathBuf>,
    /// Interval of --true-state rows in simulated seconds (0: every simulation step).
    #[arg(long, allow_negative_numbers = true, value_name = "S", default_value_t = 0.01, value_parser = nonnegative)]
    true_state_period: f64,
    /// The emulated bridge cannot brake: a motor it does not drive always has its windings
    /// open (by default it shorts them on a brake command and on its own watchdog stop).
    #[arg(long)]
    no_brake: bool,
    /// Wiring fault: the motor's leads are swapped (a positive voltage turns the arm the
    /// negative way).
    #[arg(long)]
    reverse_motor: bool,
    /// Wiring fault: the arm encoder counts backwards.
    #[arg(long)]
    reverse_arm_encoder: bool,
    /// Wiring fault: the pendulum encoder counts backwards.
    #[arg(long)]
    reverse_pendulum_encoder: bool,
    /// Wiring fault: the arm encoder does not count.
    #[arg(long)]
    freeze_arm_encoder: bool,
    /// Wiring fault: the pendulum encoder does not count.
    #[arg(long)]
    freeze_pendulum_encoder: bool,
    /// Start the wiring faults this many seconds after the first enabling command instead of
    /// at power-up (from the readings then: a frozen encoder keeps its count, a reversed one
    /// counts backwards from it).
    #[arg(long, allow_negative_numbers = true, value_name = "S", value_parser = nonnegative)]
    fault_at: Option<f64>,
    /// An operator raises the pendulum this many seconds after the first enabling command:
    /// set 0.05 rad from upright at rest and held there until the next enabling command (a
    /// run that checked the wiring with the pendulum hanging, then waits for it upright).
    #[arg(long, allow_negative_numbers = true, value_name = "S", value_parser = nonnegative)]
    raise_at: Option<f64>,
    /// A breakpoint, with --lockstep: the first time a sample request finds the true arm past
    /// ±RAD and moving outwards, the emulator stops itself (SIGSTOP) before answering, its
    /// true-state record ending on that state; `kill -CONT` resumes it.
    #[arg(long, allow_negative_numbers = true, value_name = "RAD")]
    pause_at_arm: Option<f64>,
    /// Answer nothing for --silent-for seconds starting this many seconds after the first
    /// enabling command (every measurement in the window lost; commands still arrive).
    #[arg(long, allow_negative_numbers = true, value_name = "S", value_parser = nonnegative, requires = "silent_for")]
    silent_at: Option<f64>,
    /// How long the silence of --silent-at lasts (s).
    #[arg(long, allow_negative_numbers = true, value_name = "S", value_parser = nonnegative, requires = "silent_at")]
    silent_for: Option<f64>,
    /// Lockstep with `rip-rt run/excite --lockstep`: advance the plant by one host period
    /// (`[loop] period_ms` of --config, else 10 ms) per sample request instead of in real
    /// time; after 1.5 s without a host frame the plant runs on in real time.
    #[arg(long)]
    lockstep: bool,
    /// Publish the true state to `riprs watch` on UDP port PORT of 127.0.0.1 every
    /// --true-state-period (default: `[loop] live_port` of --config).
    #[arg(long, value_name = "PORT", value_parser = clap::value_parser!(u16).range(1..))]
    live: Option<u16>,
}

/// The loop's clock for a `--lockstep` flag.
pub(crate) fn clock_mode(lockstep: bool) -> timing::ClockMode {
    if lockstep {
        timing::ClockMode::Lockstep
    } else {
        timing::ClockMode::RealTime
    }
}

pub(crate) fn fail(code: i32, msg: impl std::fmt::Display) -> ExitCode {
    rip_rt::say!("rip-rt: error: {msg}");
    ExitCode::from(code as u8)
}

/// Completes `log` with its `footer` after the command (`what`: "run", "experiment") stopped
/// for `stopped`. A log that cannot be completed turns a finished command into a log error
/// (`code` and `reason`) and is added to any other stop's `reason`; after a log fault the
/// reason already says what failed, and a second message about the same file would only
/// repeat it.
fn finish_log(
    log: &mut LogWriter,
    footer: &[(&str, String)],
    stopped: &StopReason,
    what: &str,
    code: &mut i32,
    reason: &mut String,
) {
    if let Err(e) = log.finish(footer) {
        if !matches!(stopped, StopReason::LogError(_)) {
            if *code == exit_code::FINISHED {
                *code = exit_code::LOG_ERROR;
                *reason = format!("{what} finished, but its log could not be completed: {e}");
            } else {
                *reason = format!("{reason}; the log could not be completed: {e}");
            }
        }
    }
}

/// The level of the stop's line: "stop" for an orderly stop whose log was completed, else
/// "FAULT".
fn stop_level(stopped: &StopReason, code: i32) -> &'static str {
    if stopped.is_orderly() && code != exit_code::LOG_ERROR {
        "stop"
    } else {
        "FAULT"
    }
}

/// What `rip-rt run` drives the motor with.
enum Law {
    /// The controller, stepped by the host's loop (boxed: it is a thousand bytes or more, the
    /// image's handle a few).
    Host(Box<LoopCore>),
    /// The design as an onboard image, for the device to step (`--onboard`).
    Onboard(Vec<u8>),
}

/// Everything that can fail before the motor is enabled, for the host loop and `--onboard`
/// alike, in an order that leaves nothing behind on failure: configuration, controller design,
/// the pre-flight check, signal dispositions, the port (a mistyped `--port` leaves an existing
/// log untouched), the log with its header flushed. Both modes come through here, so that no
/// path to an enabled motor skips the pre-flight or its `--force`.
fn prepare(args: &RunArgs) -> Result<(Config, Law, SerialPort, Option<LogWriter>), SetupError> {
    let mut cfg = match &args.config {
        Some(path) => Config::load(path)?,
        None => Config::default(),
    };
    if let Some(port) = args.live {
        cfg.loop_.live_port = port;
    }
    let law = if args.onboard {
        // The device's design is the host loop's (the one assembly; only an MPC's iteration
        // cap may be lowered to fit the device's period), so the pre-flight's verdict on the
        // controller is a verdict on what the device will run.
        let image = rip_rt::onboard::design(args.controller, &cfg)
            .and_then(|d| rip_rt::onboard::image(&d, &cfg))
            .map_err(SetupError::Design)?;
        Law::Onboard(image)
    } else {
        let controller = if args.swing_up {
            cfg.validate_swing_up()
                .and_then(|()| rip_rt::envelope::check_swing_up(&cfg))
                .map_err(|e| match &args.config {
                    Some(path) => e.in_file(path),
                    None => e,
                })?;
            controllers::build_swing_up(args.controller, &cfg)
        } else {
            controllers::build(args.controller, &cfg)
        }
        .map_err(SetupError::Design)?;
        Law::Host(Box::new(LoopCore::new(controller, &cfg)?))
    };
    preflight_cmd::check(args, &cfg)?;
    stop::install_signal_handlers()?;
    let port = SerialPort::open(&args.port, args.baud).map_err(SetupError::Port)?;
    let log = match &args.log {
        Some(path) => {
            let mode = match &law {
                Law::Host(_) => ("swing_up", args.swing_up.to_string()),
                Law::Onboard(_) => ("onboard", "true".to_string()),
            };
            let header = [
                ("rip-rt", env!("CARGO_PKG_VERSION").to_string()),
                ("protocol", rip_rt::protocol::VERSION.to_string()),
                ("controller", args.controller.to_string()),
                mode,
                ("port", args.port.display().to_string()),
                ("period_ms", cfg.loop_.period_ms.to_string()),
                ("voltage_limit", cfg.safety.voltage_limit.to_string()),
                ("arm_limit", cfg.safety.arm_limit.to_string()),
                ("pendulum_limit", cfg.safety.pendulum_limit.to_string()),
            ];
            // The onboard telemetry carries no state estimate.
            let n_estimates = match &law {
                Law::Host(core) => core.state_estimate().map_or(0, |x| x.len()),
                Law::Onboard(_) => 0,
            };
            Some(LogWriter::create(path, &header, n_estimates)?.waiting(args.lockstep))
        }
        None => None,
    };
    Ok((cfg, law, port, log))
}

/// `--rt-priority` and `--cpu`, best effort: a refusal is a warning.
pub(crate) fn apply_realtime(rt_priority: Option<i32>, cpu: Option<usize>) {
    if let Some(prio) = rt_priority {
        if let Err(e) = timing::lock_memory() {
            rip_rt::say!("rip-rt: warning: cannot lock memory ({e}); continuing");
        }
        if let Err(e) = timing::set_realtime_priority(prio) {
            rip_rt::say!(
                "rip-rt: warning: SCHED_FIFO priority {prio} not permitted ({e}); \
                 continuing with normal scheduling"
            );
        }
    }
    if let Some(cpu) = cpu {
        if let Err(e) = timing::pin_to_cpu(cpu) {
            rip_rt::say!("rip-rt: warning: cannot pin to CPU {cpu} ({e}); continuing");
        }
    }
}

fn cmd_run(args: RunArgs) -> ExitCode {
    let (cfg, law, port, mut log) = match prepare(&args) {
        Ok(ready) => ready,
        Err(e) => return fail(e.exit_code(), e),
    };
    let mut core = match law {
        Law::Host(core) => *core,
        Law::Onboard(image) => {
            let a = rip_rt::onboard::OnboardArgs {
                port: &args.port,
                controller: args.controller,
                duration: args.duration,
                quiet: args.quiet,
                lockstep: args.lockstep,
            };
            let code = rip_rt::onboard::command(&a, &cfg, &image, &port, log);
            return ExitCode::from(code as u8);
        }
    };

    // From here on every exit path must stop the motor; a panic does it through this hook
    // before unwinding, and again through the loop's stop guard.
    stop::install_panic_hook();

    apply_realtime(args.rt_priority, args.cpu);

    if !args.quiet {
        rip_rt::say!(
            "rip-rt: {}{} on {} every {} ms; Ctrl-C stops",
            if args.swing_up { "swing-up and " } else { "" },
            args.controller,
            args.port.display(),
            cfg.loop_.period_ms
        );
    }
    let opts = RunOptions {
        duration_s: args.duration,
        quiet: args.quiet,
        clock: clock_mode(args.lockstep),
    };
    let report = runner::run(port.io(), &mut core, &cfg, &opts, log.as_mut());
    let mut code = report.reason.exit_code();
    let stop_note = if report.stop_sent {
        "stop command (0 V, disabled) sent"
    } else {
        "stop command could not be written (the device's own watchdog must stop the motor)"
    };
    let p = report.parser;
    let parser_line = format!(
        "frames={} crc_errors={} bad_headers={} unknown={} skipped_bytes={} missing_replies={}",
        p.frames,
        p.crc_errors,
        p.bad_headers,
        p.unknown_frames,
        p.skipped_bytes,
        report.missing_replies
    );
    let probe_line = report
        .probe
        .map_or_else(|| "not run".to_string(), |p| p.to_string());
    let calibration_line = report
        .calibration
        .map_or_else(|| "none".to_string(), |c| c.to_string());
    let sign_check_line = match (args.swing_up, report.sign_check) {
        (_, Some(r)) => r.to_string(),
        (true, None) => "not passed".to_string(),
        (false, None) => "not run".to_string(),
    };
    let catch_line = report
        .catch_s
        .map_or_else(|| "none".to_string(), |t| format!("{t:.3}"));
    let mut reason = report.reason.to_string();
    let witness_line = report.witness_peak.map_or_else(
        || "off".to_string(),
        |[arm, pendulum, frozen, sign, reversal]| {
            format!(
                "peak arm={arm:.1} pendulum={pendulum:.1} frozen={frozen:.2} sign={sign:.1} \
                 reversal={reversal:.1}"
            )
        },
    );
    if let Some(log) = log.as_mut() {
        let footer = [
            ("stop", report.reason.name().to_string()),
            ("stop_message", reason.clone()),
            ("exit_code", code.to_string()),
            ("stop_sent", report.stop_sent.to_string()),
            ("balanced_s", format!("{:.3}", report.balanced_s)),
            ("timing", report.timing.to_string()),
            ("probe", probe_line.clone()),
            ("link", parser_line.clone()),
            ("calibration", calibration_line.clone()),
            ("sign_check", sign_check_line.clone()),
            ("catch_s", catch_line.clone()),
            ("catches", report.catches.to_string()),
            ("witness", witness_line.clone()),
        ];
        finish_log(log, &footer, &report.reason, "run", &mut code, &mut reason);
    }
    let level = stop_level(&report.reason, code);
    rip_rt::say!("rip-rt: {level}: {reason} — {stop_note}");
    rip_rt::say!("rip-rt: timing: {}", report.timing);
    rip_rt::say!("rip-rt: probe: {probe_line}");
    if args.swing_up {
        rip_rt::say!(
            "rip-rt: swing-up: catch_s={catch_line} catches={} calibration: {calibration_line}",
            report.catches
        );
        rip_rt::say!("rip-rt: sign check: {sign_check_line}");
    }
    rip_rt::say!("rip-rt: link: {parser_line}");
    rip_rt::say!("rip-rt: witness: {witness_line}");
    ExitCode::from(code as u8)
}

fn make_link(link: &Path, target: &Path) -> std::io::Result<()> {
    match std::fs::symlink_metadata(link) {
        Ok(meta) if meta.file_type().is_symlink() => std::fs::remove_file(link)?,
        Ok(_) => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                format!(
                    "--link {}: exists and is not a symbolic link",
                    link.display()
                ),
            ))
        }
        Err(_) => {}
    }
    std::os::unix::fs::symlink(target, link)
        .map_err(|e| std::io::Error::new(e.kind(), format!("--link {}: {e}", link.display())))
}

fn cmd_emulate(args: EmulateArgs) -> ExitCode {
    let defaults = EmulatorConfig::default();
    // The pose: the flags, else the file's initial state, else the defaults (upright). A file
    // also gives the plant's sensor, as the simulation reads it (`Spec::simulation`): encoder
    // resolutions, zero offsets and noise.
    let mut live_cfg = Config::default();
    let (model, sensor, mut initial_arm, mut initial_pendulum, period_s) = match &args.config {
        Some(path) => match Config::load(path) {
            Ok(c) => {
                let x0 = c.spec.plant.initial_state;
                let period_s = c.period_s();
                live_cfg = c.clone();
                (
                    match c.spec.plant.arm_breakaway {
                        Some(cs) => Model::Stiction(c.spec.plant.params(), cs),
                        None => Model::Params(c.spec.plant.params()),
                    },
                    c.spec.sim_config(period_s, 0).sensor,
                    x0[0],
                    x0[2],
                    period_s,
                )
            }
            Err(e) => return fail(exit_code::USAGE, e),
        },
        None => (
            args.model,
            rip_core::sim::SensorModel {
                noise_std: [0.0; 2],
                ..rip_core::Spec::default().sim_config(0.01, 0).sensor
            },
            defaults.initial_arm,
            defaults.initial_pendulum,
            Config::default().period_s(),
        ),
    };
    match args.start.as_deref() {
        Some("down") => initial_pendulum = std::f64::consts::PI,
        Some(_) => initial_pendulum = defaults.initial_pendulum,
        None => {}
    }
    initial_pendulum = args.initial_pendulum.unwrap_or(initial_pendulum);
    initial_arm = args.initial_arm.unwrap_or(initial_arm);
    let cfg = EmulatorConfig {
        model,
        sim_rate_hz: args.sim_rate,
        initial_arm,
        initial_pendulum,
        hold_until_enabled: !args.no_hold,
        command_timeout_s: args.command_timeout,
        drop_rate: args.drop_rate,
        corrupt_rate: args.corrupt_rate,
        vanish_after_s: args.vanish_after,
        seed: args.seed,
        duration_s: args.duration,
        record: args.record,
        true_state: args.true_state,
        true_state_period_s: args.true_state_period,
        can_brake: !args.no_brake,
        wiring: Wiring {
            motor_reversed: args.reverse_motor,
            encoder_reversed: [args.reverse_arm_encoder, args.reverse_pendulum_encoder],
            encoder_frozen: [args.freeze_arm_encoder, args.freeze_pendulum_encoder],
        },
        fault_at_s: args.fault_at,
        raise_at_s: args.raise_at,
        pause_at_arm: args.pause_at_arm,
        silence: args.silent_at.zip(args.silent_for),
        lockstep_period_s: args.lockstep.then_some(period_s),
        live: Some(args.live.unwrap_or(live_cfg.loop_.live_port))
            .filter(|&port| port != 0)
            .map(|port| (port, rip_rt::live::Bounds::of(&live_cfg))),
        ..EmulatorConfig::default()
    }
    .with_sensor(&sensor);
    let cfg = match args.noise {
        // --noise is in counts of each encoder.
        Some(counts) => EmulatorConfig {
            noise_std: [cfg.arm_counts_per_rev, cfg.pendulum_counts_per_rev]
                .map(|n| counts * std::f64::consts::TAU / f64::from(n)),
            ..cfg
        },
        None => cfg,
    };
    if let Err(e) = cfg.validate() {
        return fail(exit_code::USAGE, e);
    }
    let stop = Arc::new(AtomicBool::new(false));
    for sig in [libc::SIGINT, libc::SIGTERM] {
        if let Err(e) = signal_hook::flag::register(sig, Arc::clone(&stop)) {
            return fail(
                exit_code::SETUP,
                format!("cannot install signal handler: {e}"),
            );
        }
    }
    let pty = match Pty::open() {
        Ok(p) => p,
        Err(e) => {
            return fail(
                exit_code::SETUP,
                format!("cannot open a pseudo-terminal: {e}"),
            )
        }
    };
    if let Some(link) = &args.link {
        if let Err(e) = make_link(link, pty.path()) {
            return fail(exit_code::SETUP, e);
        }
    }
    println!("device: {}", pty.path().display());
    if let Some(link) = &args.link {
        println!("link: {}", link.display());
    }
    let _ = std::io::stdout().flush();
    let result = emulator::run(cfg, pty, &stop);
    if let Some(link) = &args.link {
        let _ = std::fs::remove_file(link);
    }
    match result {
        Ok(EmulatorExit::Vanished) => {
            rip_rt::say!("rip-rt emulate: device vanished (injected fault)");
            ExitCode::SUCCESS
        }
        Ok(EmulatorExit::Stopped) | Ok(EmulatorExit::Finished) => ExitCode::SUCCESS,
        Err(e) => fail(exit_code::SETUP, format!("emulator: {e}")),
    }
}

/// The exit status of a command (`rip-rt run --help` lists them). std's `ExitCode` cannot be
/// read back, and the in-process caller needs the number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ExitCode(u8);

impl ExitCode {
    pub(crate) const SUCCESS: ExitCode = ExitCode(0);
}

impl From<u8> for ExitCode {
    fn from(code: u8) -> Self {
        ExitCode(code)
    }
}

/// Runs `rip-rt` with the command line `args` (the program name first, as in
/// [`std::env::args_os`]) and returns its exit code.
///
/// Usage errors, `--help` and `--version` are printed as clap prints them and return its code
/// (2 for a usage error, 0 otherwise) instead of exiting the process. Standard output is
/// flushed before returning. A panic is not caught here: the binary lets it end the process
/// with 101, an embedding caller catches it (the motor has been stopped by the panic hook and
/// the loop's stop guard by then).
pub fn run<I, T>(args: I) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let code = match Cli::try_parse_from(args) {
        Ok(cli) => match cli.command {
            Command::Run(args) => cmd_run(args),
            Command::Excite(args) => excite_cmd::cmd_excite(args),
            Command::Emulate(args) => cmd_emulate(*args),
            Command::Config(args) => cmd_config(args),
        },
        Err(e) => {
            let _ = e.print();
            ExitCode(u8::try_from(e.exit_code()).unwrap_or(exit_code::USAGE as u8))
        }
    };
    let _ = std::io::stdout().flush();
    code.0
}

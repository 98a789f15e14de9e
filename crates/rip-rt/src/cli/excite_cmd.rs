//! `rip-rt excite`: the command line of an identification experiment ([`rip_rt::excite`]).

use std::path::PathBuf;

use rip_core::excitation::{Excitation, ExcitationSettings, Signal, Sweep};
use rip_core::identify::lab::Lab;
use rip_core::RipError;
use rip_rt::config::{Config, PendulumZero};
use rip_rt::excite::{self, ExciteOptions};
use rip_rt::log::LogWriter;
use rip_rt::loop_core::LoopCore;
use rip_rt::serial::SerialPort;
use rip_rt::sign_check::PULSE_VOLTAGE;
use rip_rt::stop::{self, SetupError};

use super::{apply_realtime, baud, cpu, fail, finish_log, positive_seconds, stop_level, ExitCode};

pub(crate) const EXCITE_AFTER_HELP: &str = "\
Stages: rest check and calibration (motor disabled), sign check (a short pulse, then 0 V),
excitation (signal through a weak arm-centring feedback; free swing: kick, then 0 V).
Exit codes are those of `rip-rt run` (docs/rip-rt.md), with:
    0    the signal is complete
    5    arm limit (safety.arm_limit); the hanging pendulum has no limit here
    12   refused: the rig was not at rest hanging down (motor never enabled)
    14   refused: the sign check failed; the message says what to swap or flip
Every exit after the device was opened sends 0 V with the driver disabled.";

fn signal(s: &str) -> Result<Signal, String> {
    Signal::from_name(s)
        .ok_or_else(|| format!("must be chirp, prbs, steps or free-swing, got {s:?}"))
}

fn sweep(s: &str) -> Result<Sweep, String> {
    Sweep::from_name(s).ok_or_else(|| format!("must be linear or log, got {s:?}"))
}

fn number(s: &str) -> Result<f64, String> {
    s.parse().map_err(|_| format!("not a number: {s:?}"))
}

#[derive(Debug, clap::Args)]
pub(crate) struct ExciteArgs {
    /// Serial device of the pendulum (e.g. /dev/ttyACM0, or the path `rip-rt emulate` prints).
    #[arg(long, value_name = "PATH")]
    port: PathBuf,
    /// Baud rate (ignored by USB CDC devices and pseudo-terminals).
    #[arg(long, value_name = "N", default_value_t = 115200, allow_negative_numbers = true, value_parser = baud)]
    baud: u32,
    /// Excitation signal: chirp, prbs, steps or free-swing.
    #[arg(long, value_name = "NAME", value_parser = signal)]
    signal: Signal,
    /// The CSV log of the experiment (rip-rt's log format with a phase column).
    #[arg(long, value_name = "FILE.csv")]
    log: PathBuf,
    /// TOML configuration (docs/rip-rt.md): [loop], [device], [safety], [calibration].
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// Amplitude (V), at most safety.voltage_limit (default: the signal's, docs/rip-rt.md).
    #[arg(long, value_name = "V", allow_negative_numbers = true, value_parser = number)]
    amplitude: Option<f64>,
    /// Publish every period's telemetry to `riprs watch` on UDP port PORT of 127.0.0.1
    /// (overrides `[loop] live_port`; docs/live.md).
    #[arg(long, value_name = "PORT", value_parser = clap::value_parser!(u16).range(1..))]
    live: Option<u16>,
    /// Length of the signal (s) (default: the signal's).
    #[arg(long, value_name = "S", allow_negative_numbers = true, value_parser = positive_seconds)]
    duration: Option<f64>,
    /// Chirp start frequency (Hz).
    #[arg(long, value_name = "HZ", allow_negative_numbers = true, value_parser = number)]
    f_start: Option<f64>,
    /// Chirp end frequency (Hz), below the Nyquist frequency of the loop.
    #[arg(long, value_name = "HZ", allow_negative_numbers = true, value_parser = number)]
    f_end: Option<f64>,
    /// Chirp sweep law: log or linear.
    #[arg(long, value_name = "LAW", value_parser = sweep)]
    sweep: Option<Sweep>,
    /// PRBS register length (2 to 20 bits).
    #[arg(long, value_name = "N", allow_negative_numbers = true)]
    prbs_bits: Option<u32>,
    /// PRBS clock period (s).
    #[arg(long, value_name = "S", allow_negative_numbers = true, value_parser = number)]
    prbs_clock: Option<f64>,
    /// PRBS seed (the same seed gives the same sequence).
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    /// Steps: seconds per level.
    #[arg(long, value_name = "S", allow_negative_numbers = true, value_parser = number)]
    step_hold: Option<f64>,
    /// Free swing: length of the kick (s).
    #[arg(long, value_name = "S", allow_negative_numbers = true, value_parser = number)]
    kick: Option<f64>,
    /// Arm-centring gain (V/rad, 0 to 10; 0 turns it off).
    #[arg(long, value_name = "V_PER_RAD", allow_negative_numbers = true, value_parser = number)]
    centering: Option<f64>,
    /// Arm-centring damping (V·s/rad, 0 to 2).
    #[arg(long, value_name = "V_S_PER_RAD", allow_negative_numbers = true, value_parser = number)]
    damping: Option<f64>,
    /// Sign-check pulse voltage (V), at most safety.voltage_limit.
    #[arg(long, value_name = "V", default_value_t = PULSE_VOLTAGE, allow_negative_numbers = true, value_parser = number)]
    check_voltage: f64,
    /// Run the loop with SCHED_FIFO at this priority (1-99) and locked memory, if permitted.
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = clap::value_parser!(i32).range(1..=99))]
    rt_priority: Option<i32>,
    /// Pin the loop to this CPU, if permitted.
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = cpu)]
    cpu: Option<usize>,
    /// Lab file of the rig's measured values (docs/rig.md): carried into the log's header
    /// (`lab.mp: ...`), from which `riprs identify` reads it.
    #[arg(long, value_name = "FILE.toml")]
    lab: Option<PathBuf>,
    /// Only print the final summary.
    #[arg(long)]
    quiet: bool,
    /// Run in lockstep with `rip-rt emulate --lockstep` (see `rip-rt run --lockstep`).
    #[arg(long)]
    lockstep: bool,
}

/// A bad setting as a usage error naming its option (`f_end` → `--f-end`).
fn option_error(e: RipError) -> SetupError {
    let e = match e {
        RipError::InvalidParameter { name, reason } => {
            rip_core::spec::SpecError::new(format!("--{}", name.replace('_', "-")), reason)
        }
        other => rip_core::spec::SpecError::new("", other.to_string()),
    };
    SetupError::Config(e)
}

/// The signal's settings: its defaults, then the options given.
fn settings(args: &ExciteArgs, cfg: &Config) -> Result<Excitation, SetupError> {
    let mut s = ExcitationSettings::new(args.signal);
    let set = |field: &mut f64, v: Option<f64>| {
        if let Some(v) = v {
            *field = v;
        }
    };
    // A default is a suggestion within what the rig allows; a given amplitude is checked.
    s.amplitude = args
        .amplitude
        .unwrap_or(s.amplitude.min(cfg.safety.voltage_limit));
    set(&mut s.duration, args.duration);
    set(&mut s.f_start, args.f_start);
    set(&mut s.f_end, args.f_end);
    set(&mut s.prbs_clock, args.prbs_clock);
    set(&mut s.step_hold, args.step_hold);
    set(&mut s.kick, args.kick);
    set(&mut s.centering, args.centering);
    set(&mut s.damping, args.damping);
    if let Some(v) = args.sweep {
        s.sweep = v;
    }
    if let Some(v) = args.prbs_bits {
        s.prbs_bits = v;
    }
    if let Some(v) = args.seed {
        s.seed = v;
    }
    let limit = cfg.safety.voltage_limit;
    for (name, v) in [
        ("amplitude", s.amplitude),
        ("check_voltage", args.check_voltage),
    ] {
        if !(v > 0.0 && v <= limit) {
            return Err(option_error(RipError::invalid(
                name,
                format!("must be in (0, safety.voltage_limit = {limit}] V, got {v}"),
            )));
        }
    }
    let model = match &args.config {
        Some(path) => format!("the [plant] of {}", path.display()),
        None => format!(
            "the [plant] of the {} preset (no --config: pass the rig's file to check its own)",
            cfg.spec.plant.preset.name()
        ),
    };
    // Bad settings are named as options before the envelope simulates them.
    s.validate(cfg.period_s()).map_err(option_error)?;
    if args.amplitude.is_none() {
        // An amplitude left to its default is the largest the rig can stop from, at most the
        // signal's default: a file `riprs tune` wrote runs every signal as is. One that clears
        // needs no second check; none at all is refused below, with the check's reason.
        let fits = rip_core::preflight::largest_excitation_amplitude(&cfg.spec, &cfg.rig(), &s)
            .map_err(option_error)?;
        if fits > 0.0 {
            if fits < s.amplitude && !args.quiet {
                rip_rt::say!(
                    "rip-rt: --amplitude {fits:.2} V (the signal's default {} V would reach the \
                     braking envelope on {model})",
                    s.amplitude
                );
            }
            s.amplitude = fits;
            return Excitation::new(s, cfg.period_s()).map_err(option_error);
        }
    }
    rip_rt::envelope::check_excitation(cfg, &s, &model).map_err(SetupError::Config)?;
    Excitation::new(s, cfg.period_s()).map_err(option_error)
}

/// The log's header: the run's settings, and the sensor and device settings the rig was excited
/// with (`riprs identify` writes them into the rig file), and the lab file's values.
fn header(args: &ExciteArgs, cfg: &Config, x: &Excitation, lab: &Lab) -> Vec<(String, String)> {
    let s = x.settings();
    let mut h: Vec<(&str, String)> = vec![
        ("rip-rt", env!("CARGO_PKG_VERSION").to_string()),
        ("protocol", rip_rt::protocol::VERSION.to_string()),
        ("mode", "excite".to_string()),
        ("signal", s.signal.to_string()),
        ("amplitude", s.amplitude.to_string()),
        ("duration", s.duration.to_string()),
    ];
    match s.signal {
        Signal::Chirp => {
            h.push(("f_start", s.f_start.to_string()));
            h.push(("f_end", s.f_end.to_string()));
            h.push(("sweep", s.sweep.name().to_string()));
        }
        Signal::Prbs => {
            h.push(("prbs_bits", s.prbs_bits.to_string()));
            h.push(("prbs_clock", s.prbs_clock.to_string()));
            h.push(("seed", s.seed.to_string()));
        }
        Signal::Steps => h.push(("step_hold", s.step_hold.to_string())),
        Signal::FreeSwing => h.push(("kick", s.kick.to_string())),
    }
    if s.signal != Signal::FreeSwing {
        h.push(("centering", s.centering.to_string()));
        h.push(("damping", s.damping.to_string()));
    }
    h.extend([
        ("port", args.port.display().to_string()),
        ("period_ms", cfg.loop_.period_ms.to_string()),
        ("voltage_limit", cfg.safety.voltage_limit.to_string()),
        ("arm_limit", cfg.safety.arm_limit.to_string()),
        (
            "arm_counts_per_rev",
            cfg.device.arm_counts_per_rev.to_string(),
        ),
        (
            "pendulum_counts_per_rev",
            cfg.device.pendulum_counts_per_rev.to_string(),
        ),
        (
            "pendulum_zero",
            match cfg.device.pendulum_zero {
                PendulumZero::Down => "down",
                PendulumZero::Up => "up",
            }
            .to_string(),
        ),
        ("arm_sign", cfg.device.arm_sign.to_string()),
        ("pendulum_sign", cfg.device.pendulum_sign.to_string()),
    ]);
    let mut out: Vec<(String, String)> = h.into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    out.extend(lab.header());
    out
}

/// Everything that can fail before the motor is enabled, in `rip-rt run`'s order.
fn prepare(
    args: &ExciteArgs,
) -> Result<(Config, Excitation, LoopCore, SerialPort, LogWriter), SetupError> {
    let mut cfg = match &args.config {
        Some(path) => Config::load(path)?,
        None => Config::default(),
    };
    if let Some(port) = args.live {
        cfg.loop_.live_port = port;
    }
    let excitation = settings(args, &cfg)?;
    let lab = match &args.lab {
        Some(path) => Lab::load(path).map_err(SetupError::Config)?,
        None => Lab::default(),
    };
    let core = LoopCore::open_loop(&cfg);
    stop::install_signal_handlers()?;
    let port = SerialPort::open(&args.port, args.baud).map_err(SetupError::Port)?;
    let head = header(args, &cfg, &excitation, &lab);
    let head: Vec<(&str, String)> = head.iter().map(|(k, v)| (k.as_str(), v.clone())).collect();
    let log = LogWriter::create(&args.log, &head, 0)?.waiting(args.lockstep);
    Ok((cfg, excitation, core, port, log))
}

pub(crate) fn cmd_excite(args: ExciteArgs) -> ExitCode {
    let (cfg, mut excitation, mut core, port, mut log) = match prepare(&args) {
        Ok(ready) => ready,
        Err(e) => return fail(e.exit_code(), e),
    };
    stop::install_panic_hook();
    apply_realtime(args.rt_priority, args.cpu);
    if !args.quiet {
        rip_rt::say!(
            "rip-rt: excite {} on {} every {} ms; Ctrl-C stops",
            args.signal,
            args.port.display(),
            cfg.loop_.period_ms
        );
    }
    let opts = ExciteOptions {
        check_voltage: args.check_voltage,
        quiet: args.quiet,
        clock: super::clock_mode(args.lockstep),
    };
    let report = excite::run(
        port.io(),
        &mut core,
        &cfg,
        &mut excitation,
        &opts,
        Some(&mut log),
    );
    let mut code = report.reason.exit_code();
    let stop_note = if report.stop_sent {
        "stop command (0 V, disabled) sent"
    } else {
        "stop command could not be written (the device's own watchdog must stop the motor)"
    };
    let p = report.parser;
    let link = format!(
        "frames={} crc_errors={} bad_headers={} unknown={} skipped_bytes={} missing_replies={}",
        p.frames,
        p.crc_errors,
        p.bad_headers,
        p.unknown_frames,
        p.skipped_bytes,
        report.missing_replies
    );
    let calibration = report
        .calibration
        .clone()
        .unwrap_or_else(|| "not completed".into());
    let sign_check = report
        .sign_check
        .map_or_else(|| "not passed".to_string(), |r| r.to_string());
    let mut reason = report.reason.to_string();
    let footer = [
        ("stop", report.reason.name().to_string()),
        ("stop_message", reason.clone()),
        ("exit_code", code.to_string()),
        ("stop_sent", report.stop_sent.to_string()),
        ("calibration", calibration.clone()),
        ("sign_check", sign_check.clone()),
        ("excited_s", format!("{:.3}", report.excited_s)),
        ("max_abs_theta", format!("{:.4}", report.max_arm)),
        ("timing", report.timing.to_string()),
        ("link", link.clone()),
    ];
    finish_log(
        &mut log,
        &footer,
        &report.reason,
        "experiment",
        &mut code,
        &mut reason,
    );
    let level = stop_level(&report.reason, code);
    rip_rt::say!("rip-rt: {level}: {reason} — {stop_note}");
    rip_rt::say!("rip-rt: calibration: {calibration}");
    rip_rt::say!("rip-rt: sign check: {sign_check}");
    rip_rt::say!(
        "rip-rt: excited {:.2} s, largest |theta| {:.3} rad (limit {})",
        report.excited_s,
        report.max_arm,
        cfg.safety.arm_limit
    );
    rip_rt::say!("rip-rt: timing: {}", report.timing);
    rip_rt::say!("rip-rt: link: {link}");
    ExitCode::from(code as u8)
}

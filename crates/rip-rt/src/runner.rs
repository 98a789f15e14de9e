//! The control loop: every period it requests a sample, waits for the measurement, steps the
//! controller and writes the voltage, on a grid of absolute deadlines, with the safety rules of
//! `docs/rip-rt.md`.
//!
//! # Safety
//!
//! Every way out of [`run`] — the duration elapsing, SIGINT/SIGTERM/SIGHUP/SIGQUIT (a flag checked every
//! period), the watchdog, an angle limit, a device fault, an I/O error, and a panic — ends with
//! the stop frame (0 V, driver disabled) written to the device:
//!
//! - normal and fault stops send it explicitly and report whether it went out;
//! - a [`StopGuard`] sends it again from `Drop`, which also runs while a panic unwinds;
//! - [`emergency_stop`], called from the binary's panic hook, sends it with a bare `write(2)`
//!   on the registered descriptor, without locks or allocation, before anything else runs.
//!
//! A process killed with SIGKILL can do none of this; the device's own command watchdog (a
//! requirement of the protocol) zeroes the motor then.

use std::fmt;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use std::sync::atomic::{AtomicI32, AtomicU16, AtomicUsize, Ordering};

use rip_core::{Controller, StepStatus};

use crate::config::{Config, PendulumZero};
use crate::protocol::{
    encode, Command, Frame, Measurement, Message, Parser, ParserStats, COMMAND_ENABLE, MAX_FRAME,
    STATUS_FAULT,
};
use crate::serial::{Fd, Readiness};
use crate::timing::{now_ns, Histogram, Periodic, TimingSummary};

/// Log status bit (above the device's 8 status bits): no measurement arrived this period; the
/// previous command was repeated and the controller, instead of being stepped, was told that
/// the period passed with that command ([`LoopCore::hold`]).
pub const FLAG_NO_REPLY: u32 = 1 << 8;
/// Log status bit: the controller used its fallback (e.g. the MPC solver failed).
pub const FLAG_FALLBACK: u32 = 1 << 9;
/// Log status bit: the command is at `±safety.voltage_limit`, saturated by the controller (LQR and
/// LQG saturate, the MPC bounds its moves, at that limit) or clamped by the loop.
pub const FLAG_CLAMPED: u32 = 1 << 10;
/// Log status bit: deadlines were missed (skipped) right before this period.
pub const FLAG_DEADLINE_MISS: u32 = 1 << 11;

/// Why the loop stopped. Each reason has its own exit code ([`StopReason::exit_code`]).
#[derive(Debug, Clone, PartialEq)]
pub enum StopReason {
    /// `--duration` elapsed.
    Finished,
    /// SIGINT or SIGTERM (the signal number).
    Signal(i32),
    /// Reading from or writing to the device failed, or it went away.
    DeviceLost(String),
    /// No valid measurement for this many consecutive periods.
    Watchdog(u32),
    /// An angle left its limit.
    AngleLimit {
        /// `"pendulum"` or `"arm"`.
        which: &'static str,
        /// The measured angle (rad).
        angle: f64,
        /// The limit (rad).
        limit: f64,
    },
    /// The pendulum was not near upright when balancing was to start.
    NotUpright {
        /// The measured pendulum angle (rad from upright).
        angle: f64,
        /// `safety.start_tolerance` (rad).
        tolerance: f64,
    },
    /// The controller produced a non-finite voltage.
    ControllerFault(String),
    /// The device reported a driver fault.
    DeviceFault(u8),
    /// The log file could not be written.
    LogError(String),
}

/// Exit codes, as documented in `rip-rt --help` and `docs/rip-rt.md`.
pub mod exit_code {
    /// `--duration` elapsed.
    pub const FINISHED: i32 = 0;
    /// The loop could not start (port, controller design); the motor was never enabled.
    pub const SETUP: i32 = 1;
    /// Bad command line or configuration (clap's own usage errors also use 2).
    pub const USAGE: i32 = 2;
    /// The device went away or I/O failed.
    pub const DEVICE_LOST: i32 = 3;
    /// Watchdog: no valid measurement for `loop.watchdog_periods` periods.
    pub const WATCHDOG: i32 = 4;
    /// An angle limit was exceeded.
    pub const ANGLE_LIMIT: i32 = 5;
    /// Refused to start: the pendulum was not near upright.
    pub const NOT_UPRIGHT: i32 = 6;
    /// The controller produced a non-finite output.
    pub const CONTROLLER_FAULT: i32 = 7;
    /// The device reported a driver fault.
    pub const DEVICE_FAULT: i32 = 8;
    /// The log could not be written.
    pub const LOG_ERROR: i32 = 9;
    /// A panic (Rust's own exit code for one).
    pub const PANIC: i32 = 101;
    /// SIGINT (128 + 2).
    pub const SIGINT: i32 = 130;
    /// SIGTERM (128 + 15).
    pub const SIGTERM: i32 = 143;
    /// SIGHUP (128 + 1): the terminal or the SSH session closed.
    pub const SIGHUP: i32 = 129;
    /// SIGQUIT (128 + 3): Ctrl-Backslash.
    pub const SIGQUIT: i32 = 131;
}

impl StopReason {
    /// The process exit code for this stop.
    pub fn exit_code(&self) -> i32 {
        match self {
            StopReason::Finished => exit_code::FINISHED,
            StopReason::Signal(s) => 128 + s,
            StopReason::DeviceLost(_) => exit_code::DEVICE_LOST,
            StopReason::Watchdog(_) => exit_code::WATCHDOG,
            StopReason::AngleLimit { .. } => exit_code::ANGLE_LIMIT,
            StopReason::NotUpright { .. } => exit_code::NOT_UPRIGHT,
            StopReason::ControllerFault(_) => exit_code::CONTROLLER_FAULT,
            StopReason::DeviceFault(_) => exit_code::DEVICE_FAULT,
            StopReason::LogError(_) => exit_code::LOG_ERROR,
        }
    }

    /// A short machine-readable name (used in the log footer).
    pub fn name(&self) -> &'static str {
        match self {
            StopReason::Finished => "finished",
            StopReason::Signal(_) => "signal",
            StopReason::DeviceLost(_) => "device_lost",
            StopReason::Watchdog(_) => "watchdog",
            StopReason::AngleLimit { .. } => "angle_limit",
            StopReason::NotUpright { .. } => "not_upright",
            StopReason::ControllerFault(_) => "controller_fault",
            StopReason::DeviceFault(_) => "device_fault",
            StopReason::LogError(_) => "log_error",
        }
    }
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StopReason::Finished => write!(f, "run finished (duration elapsed)"),
            StopReason::Signal(s) => {
                let name = match *s {
                    libc::SIGINT => "SIGINT",
                    libc::SIGTERM => "SIGTERM",
                    libc::SIGHUP => "SIGHUP",
                    libc::SIGQUIT => "SIGQUIT",
                    _ => "signal",
                };
                write!(f, "stopped by {name} ({s})")
            }
            StopReason::DeviceLost(e) => write!(f, "device lost: {e}"),
            StopReason::Watchdog(n) => write!(
                f,
                "watchdog: no valid measurement from the device for {n} consecutive periods"
            ),
            StopReason::AngleLimit {
                which,
                angle,
                limit,
            } => write!(
                f,
                "{which} angle limit: |{angle:.3}| rad exceeds {limit:.3} rad"
            ),
            StopReason::NotUpright { angle, tolerance } => write!(
                f,
                "refusing to balance: pendulum at {angle:.3} rad from upright, \
                 start tolerance is {tolerance:.3} rad"
            ),
            StopReason::ControllerFault(e) => write!(f, "controller fault: {e}"),
            StopReason::DeviceFault(s) => {
                write!(f, "device reported a driver fault (status 0x{s:02x})")
            }
            StopReason::LogError(e) => write!(f, "log write failed: {e}"),
        }
    }
}

// The descriptor and sequence counter the panic hook needs; -1 when no loop is running.
static STOP_FD: AtomicI32 = AtomicI32::new(-1);
static TX_SEQ: AtomicU16 = AtomicU16::new(0);

fn next_seq() -> u16 {
    TX_SEQ.fetch_add(1, Ordering::Relaxed)
}

/// Writes the stop frame to `fd` with a bare `write(2)`; returns whether all bytes went out.
fn write_stop(fd: i32) -> bool {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(
        &Frame {
            seq: next_seq(),
            message: Message::Command(Command::STOP),
        },
        &mut buf,
    );
    // SAFETY: `buf` is valid for `n` bytes; a stale descriptor only makes write fail.
    let written = unsafe { libc::write(fd, buf.as_ptr().cast(), n) };
    written == n as isize
}

/// Sends the stop frame on the descriptor registered by the running loop, if any. Safe to call
/// from a panic hook: no locks, no allocation.
pub fn emergency_stop() {
    let fd = STOP_FD.load(Ordering::SeqCst);
    if fd >= 0 {
        write_stop(fd);
    }
}

/// Registers the device descriptor for [`emergency_stop`] and sends the stop frame when
/// dropped, including during a panic's unwinding.
#[derive(Debug)]
pub struct StopGuard {
    fd: i32,
}

impl StopGuard {
    /// Arms the guard for `fd`.
    pub fn new(fd: i32) -> Self {
        STOP_FD.store(fd, Ordering::SeqCst);
        Self { fd }
    }

    /// Sends the stop frame (three times, so that one corrupted copy cannot leave the motor
    /// running); returns whether at least one copy was written.
    pub fn stop(&self) -> bool {
        let mut ok = false;
        for _ in 0..3 {
            ok |= write_stop(self.fd);
        }
        ok
    }
}

impl Drop for StopGuard {
    fn drop(&mut self) {
        self.stop();
        STOP_FD.store(-1, Ordering::SeqCst);
    }
}

/// What one control step produced (see [`LoopCore::control`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutput {
    /// Measured arm angle (rad).
    pub theta: f64,
    /// Measured pendulum angle (rad from upright).
    pub alpha: f64,
    /// Arm reference (rad).
    pub reference: f64,
    /// Commanded voltage after clamping (V).
    pub voltage: f64,
    /// Device status bits and `FLAG_*` bits.
    pub flags: u32,
    /// Bytes of the encoded command frame.
    pub len: usize,
}

/// The loop's logic without I/O or clocks: frame decoding, angle conversion, safety checks,
/// the controller step, clamping and command encoding. Allocation-free after construction.
pub struct LoopCore {
    controller: Box<dyn Controller>,
    parser: Parser,
    arm_rad_per_count: f64,
    pendulum_rad_per_count: f64,
    pendulum_offset: f64,
    pendulum_limit: f64,
    arm_limit: f64,
    start_tolerance: f64,
    voltage_limit: f64,
    step_height: f64,
    step_time: f64,
    y: [f64; 2],
    r: [f64; 2],
    u: [f64; 1],
    last_command: Command,
}

impl fmt::Debug for LoopCore {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LoopCore")
            .field("y", &self.y)
            .field("u", &self.u)
            .finish_non_exhaustive()
    }
}

fn wrap_angle(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let w = a - tau * (a / tau).round();
    if w <= -std::f64::consts::PI {
        w + tau
    } else {
        w
    }
}

impl LoopCore {
    /// Wraps `controller` (2 outputs: arm, pendulum angle; 1 input: voltage) with the settings
    /// of `cfg`.
    pub fn new(controller: Box<dyn Controller>, cfg: &Config) -> Result<Self, String> {
        if controller.n_outputs() != 2 || controller.n_inputs() != 1 {
            return Err(format!(
                "the controller has {} outputs and {} inputs; the pendulum needs 2 and 1",
                controller.n_outputs(),
                controller.n_inputs()
            ));
        }
        let tau = std::f64::consts::TAU;
        let d = &cfg.device;
        Ok(Self {
            controller,
            parser: Parser::new(),
            arm_rad_per_count: d.arm_sign * tau / d.arm_counts_per_rev as f64,
            pendulum_rad_per_count: d.pendulum_sign * tau / d.pendulum_counts_per_rev as f64,
            pendulum_offset: match d.pendulum_zero {
                PendulumZero::Down => std::f64::consts::PI,
                PendulumZero::Up => 0.0,
            },
            pendulum_limit: cfg.safety.pendulum_limit,
            arm_limit: cfg.safety.arm_limit,
            start_tolerance: cfg.safety.start_tolerance,
            voltage_limit: cfg.safety.voltage_limit,
            step_height: cfg.reference.arm_step,
            step_time: cfg.reference.step_time,
            y: [0.0; 2],
            r: [0.0; 2],
            u: [0.0],
            last_command: Command::STOP,
        })
    }

    /// The parser's counters.
    pub fn parser_stats(&self) -> ParserStats {
        self.parser.stats()
    }

    /// The controller's state estimate, if it has one.
    pub fn state_estimate(&self) -> Option<&[f64]> {
        self.controller.state_estimate()
    }

    /// Restarts the controller (estimator, previous input) and forgets any partial frame.
    pub fn reset(&mut self) {
        self.controller.reset();
        self.u = [0.0];
        self.last_command = Command::STOP;
    }

    /// The voltage the device applies under the last command: its value when the driver is
    /// enabled, else 0 V.
    pub fn held_voltage(&self) -> f64 {
        if self.last_command.enabled() {
            f64::from(self.last_command.voltage_mv) / 1000.0
        } else {
            0.0
        }
    }

    /// A period without a measurement, in which the device keeps applying the last command:
    /// passes its voltage to [`Controller::hold`], so that rate filters and estimators account
    /// for the period (and for the input actually applied, after clamping and rounding to mV)
    /// before the next step. Returns that voltage.
    pub fn hold(&mut self) -> f64 {
        let held = [self.held_voltage()];
        self.controller.hold(&held);
        held[0]
    }

    /// Encodes a sample request; returns its sequence number and length.
    pub fn encode_request(&mut self, out: &mut [u8; MAX_FRAME]) -> (u16, usize) {
        let seq = next_seq();
        let n = encode(
            &Frame {
                seq,
                message: Message::SampleRequest,
            },
            out,
        );
        (seq, n)
    }

    /// Encodes the last command again (used when a measurement is missing).
    pub fn encode_repeat(&mut self, out: &mut [u8; MAX_FRAME]) -> usize {
        encode(
            &Frame {
                seq: next_seq(),
                message: Message::Command(self.last_command),
            },
            out,
        )
    }

    /// Encodes the stop command and makes it the last command.
    pub fn encode_stop(&mut self, out: &mut [u8; MAX_FRAME]) -> usize {
        self.last_command = Command::STOP;
        self.encode_repeat(out)
    }

    /// Feeds received bytes to the parser; returns the newest measurement answering `seq`.
    /// Anything else (stale answers, host-type frames echoed back) is ignored.
    pub fn receive(&mut self, bytes: &[u8], seq: u16) -> Option<Measurement> {
        let mut found = None;
        self.parser.feed(bytes, |frame| {
            if let Message::Measurement(m) = frame.message {
                if m.ack_seq == seq {
                    found = Some(m);
                }
            }
        });
        found
    }

    /// Arm and pendulum angles (rad; pendulum wrapped to (−π, π], 0 upright) of a measurement.
    pub fn angles(&self, m: &Measurement) -> (f64, f64) {
        let theta = m.arm_counts as f64 * self.arm_rad_per_count;
        let alpha = wrap_angle(
            m.pendulum_counts as f64 * self.pendulum_rad_per_count - self.pendulum_offset,
        );
        (theta, alpha)
    }

    /// `Ok` when the pendulum is close enough to upright (and the arm inside its limit) to
    /// start balancing.
    pub fn check_start(&self, m: &Measurement) -> Result<(), StopReason> {
        let (theta, alpha) = self.angles(m);
        if alpha.abs() > self.start_tolerance {
            return Err(StopReason::NotUpright {
                angle: alpha,
                tolerance: self.start_tolerance,
            });
        }
        if theta.abs() > self.arm_limit {
            return Err(StopReason::AngleLimit {
                which: "arm",
                angle: theta,
                limit: self.arm_limit,
            });
        }
        Ok(())
    }

    /// The arm reference at `t` seconds after balancing started.
    pub fn reference_at(&self, t: f64) -> f64 {
        if t >= self.step_time {
            self.step_height
        } else {
            0.0
        }
    }

    /// One control step on measurement `m` at `t` seconds after balancing started: checks the
    /// device status and the angle limits, steps the controller, clamps the voltage and encodes
    /// the enabling command into `out`. A failed check returns the stop reason and encodes
    /// nothing.
    pub fn control(
        &mut self,
        m: &Measurement,
        t: f64,
        out: &mut [u8; MAX_FRAME],
    ) -> Result<StepOutput, StopReason> {
        if m.status & STATUS_FAULT != 0 {
            return Err(StopReason::DeviceFault(m.status));
        }
        let (theta, alpha) = self.angles(m);
        if alpha.abs() > self.pendulum_limit {
            return Err(StopReason::AngleLimit {
                which: "pendulum",
                angle: alpha,
                limit: self.pendulum_limit,
            });
        }
        if theta.abs() > self.arm_limit {
            return Err(StopReason::AngleLimit {
                which: "arm",
                angle: theta,
                limit: self.arm_limit,
            });
        }
        let reference = self.reference_at(t);
        self.y = [theta, alpha];
        self.r = [reference, 0.0];
        let status = self.controller.step(&self.y, &self.r, &mut self.u);
        let mut flags = m.status as u32;
        if status == StepStatus::Fallback {
            flags |= FLAG_FALLBACK;
        }
        let raw = self.u[0];
        if !raw.is_finite() {
            return Err(StopReason::ControllerFault(format!(
                "non-finite voltage {raw} at t = {t:.3} s"
            )));
        }
        let voltage = raw.clamp(-self.voltage_limit, self.voltage_limit);
        // LQR/LQG saturate and the MPC bounds its moves at the same limit, so a saturated
        // command usually arrives already at the limit rather than beyond it.
        if voltage.abs() >= self.voltage_limit {
            flags |= FLAG_CLAMPED;
        }
        self.last_command = Command {
            voltage_mv: (voltage * 1000.0).round() as i16,
            flags: COMMAND_ENABLE,
        };
        let len = self.encode_repeat(out);
        Ok(StepOutput {
            theta,
            alpha,
            reference,
            voltage,
            flags,
            len,
        })
    }

    /// One loop iteration without I/O: decodes `rx`, and for a measurement answering `seq`
    /// runs [`control`](Self::control). `Ok(None)` when no such measurement was in `rx`.
    pub fn iterate(
        &mut self,
        rx: &[u8],
        seq: u16,
        t: f64,
        out: &mut [u8; MAX_FRAME],
    ) -> Result<Option<StepOutput>, StopReason> {
        match self.receive(rx, seq) {
            Some(m) => self.control(&m, t, out).map(Some),
            None => Ok(None),
        }
    }
}

/// Options of one run besides the configuration.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Controller name for the log header.
    pub controller_name: String,
    /// Stop after this many seconds of balancing.
    pub duration_s: Option<f64>,
    /// Suppress progress messages on stderr.
    pub quiet: bool,
}

/// The outcome of [`run`].
#[derive(Debug, Clone)]
pub struct RunReport {
    /// Why the loop stopped.
    pub reason: StopReason,
    /// Whether the final stop frame was written to the device.
    pub stop_sent: bool,
    /// Timing figures.
    pub timing: TimingSummary,
    /// Parser counters.
    pub parser: ParserStats,
    /// Periods without a valid measurement.
    pub missing_replies: u64,
    /// Seconds of balancing.
    pub balanced_s: f64,
}

/// The CSV log (columns documented in `docs/rip-rt.md`).
pub struct LogWriter {
    out: BufWriter<File>,
    n_estimates: usize,
}

impl fmt::Debug for LogWriter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LogWriter")
            .field("n_estimates", &self.n_estimates)
            .finish_non_exhaustive()
    }
}

impl LogWriter {
    /// Creates `path` and writes the header (comment lines `# key: value`, then the columns).
    pub fn create(path: &Path, header: &[(&str, String)], n_estimates: usize) -> io::Result<Self> {
        let file = File::create(path)
            .map_err(|e| io::Error::new(e.kind(), format!("--log {}: {e}", path.display())))?;
        let mut out = BufWriter::with_capacity(1 << 16, file);
        for (k, v) in header {
            writeln!(out, "# {k}: {v}")?;
        }
        write!(out, "t,seq,theta,alpha,theta_ref,u")?;
        for i in 0..n_estimates {
            write!(out, ",xhat_{i}")?;
        }
        writeln!(out, ",compute_us,jitter_us,status")?;
        Ok(Self { out, n_estimates })
    }

    /// Appends one row (formatting into the buffer; no allocation).
    #[allow(clippy::too_many_arguments)]
    pub fn row(
        &mut self,
        t: f64,
        seq: u16,
        step: &StepOutput,
        estimate: Option<&[f64]>,
        compute_us: f64,
        jitter_us: f64,
    ) -> io::Result<()> {
        write!(
            self.out,
            "{t:.4},{seq},{:.6},{:.6},{:.6},{:.4}",
            step.theta, step.alpha, step.reference, step.voltage
        )?;
        for i in 0..self.n_estimates {
            match estimate.and_then(|x| x.get(i)) {
                Some(v) => write!(self.out, ",{v:.6}")?,
                None => write!(self.out, ",")?,
            }
        }
        writeln!(self.out, ",{compute_us:.1},{jitter_us:.1},{}", step.flags)
    }

    /// Writes the footer comment lines and flushes.
    pub fn finish(&mut self, footer: &[(&str, String)]) -> io::Result<()> {
        for (k, v) in footer {
            writeln!(self.out, "# {k}: {v}")?;
        }
        self.out.flush()
    }
}

/// The stop request raised by a signal handler: 0 for none, else the signal number.
pub type SignalFlag = AtomicUsize;

enum Phase {
    Arming { since_ns: u64, told: bool },
    Balancing { start_ns: u64 },
}

/// Runs the loop on `io` until a stop reason arises (see the module docs); always ends with the
/// stop frame. `signal` is set (to the signal number) by the handlers of SIGINT, SIGTERM,
/// SIGHUP and SIGQUIT.
pub fn run(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    opts: &RunOptions,
    mut log: Option<&mut LogWriter>,
    signal: &SignalFlag,
) -> RunReport {
    let guard = StopGuard::new(io.raw());
    let period_ns = cfg.period_ns();
    let reply_timeout_ns = (cfg.loop_.reply_timeout_ms * 1e6).round() as u64;
    let watchdog = cfg.loop_.watchdog_periods;
    let wait_upright_ns = (cfg.safety.wait_upright_s * 1e9) as u64;
    let duration_ns = opts.duration_s.map(|d| (d * 1e9) as u64);
    let mut jitter = Histogram::new();
    let mut compute = Histogram::new();
    let mut tx = [0u8; MAX_FRAME];
    let mut rx = [0u8; 512];
    let mut missing_in_row = 0u32;
    let mut missing_total = 0u64;
    let mut last_step: Option<StepOutput> = None;
    io.flush_input();
    let first = now_ns() + period_ns;
    let mut periodic = Periodic::new(period_ns, first);
    let mut phase = Phase::Arming {
        since_ns: first,
        told: false,
    };
    let mut balanced_ns = 0u64;

    let reason = 'outer: loop {
        let tick = periodic.wait();
        let sig = signal.load(Ordering::Relaxed);
        if sig != 0 {
            break StopReason::Signal(sig as i32);
        }
        if let Phase::Balancing { start_ns } = phase {
            balanced_ns = tick.deadline_ns - start_ns;
            if duration_ns.is_some_and(|d| balanced_ns >= d) {
                break StopReason::Finished;
            }
        }
        jitter.record(tick.lateness_ns);

        // Sample request, then wait for its answer until the reply timeout.
        let (seq, n) = core.encode_request(&mut tx);
        if let Err(e) = io.write_all(&tx[..n]) {
            break StopReason::DeviceLost(e.to_string());
        }
        // Counted from the request, so a late wake-up does not cost a measurement the device
        // answers at once; capped at the next deadline, which the next request must keep.
        let reply_deadline = (now_ns() + reply_timeout_ns).min(tick.deadline_ns + period_ns);
        let mut measurement = None;
        let mut rx_done_ns = 0;
        while measurement.is_none() {
            let now = now_ns();
            if now >= reply_deadline {
                break;
            }
            match io.wait_readable(reply_deadline - now) {
                Ok(Readiness::Readable) => {}
                Ok(Readiness::Timeout) => break,
                Ok(Readiness::Interrupted) => continue,
                Err(e) => break 'outer StopReason::DeviceLost(e.to_string()),
            }
            let got = match io.read_available(&mut rx) {
                Ok(got) => got,
                Err(e) => break 'outer StopReason::DeviceLost(e.to_string()),
            };
            rx_done_ns = now_ns();
            measurement = core.receive(&rx[..got], seq);
        }

        let Some(m) = measurement else {
            missing_in_row += 1;
            missing_total += 1;
            if missing_in_row >= watchdog {
                break StopReason::Watchdog(missing_in_row);
            }
            // Keep the device's command watchdog fed with the command it already applies.
            let n = core.encode_repeat(&mut tx);
            if let Err(e) = io.write_all(&tx[..n]) {
                break StopReason::DeviceLost(e.to_string());
            }
            // Without this the controller's next step would treat two periods as one: a rate
            // difference over 2 Ts divided by Ts, an estimator prior one period stale.
            if matches!(phase, Phase::Balancing { .. }) {
                core.hold();
            }
            if let (Phase::Balancing { start_ns }, Some(log), Some(prev)) =
                (&phase, log.as_deref_mut(), last_step)
            {
                let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
                let step = StepOutput {
                    flags: FLAG_NO_REPLY,
                    reference: core.reference_at(t),
                    ..prev
                };
                if let Err(e) = log.row(t, seq, &step, None, 0.0, tick.lateness_ns as f64 / 1e3) {
                    break StopReason::LogError(e.to_string());
                }
            }
            continue;
        };
        missing_in_row = 0;

        if let Phase::Arming { since_ns, told } = &mut phase {
            match core.check_start(&m) {
                Ok(()) => {
                    core.reset();
                    if !opts.quiet {
                        crate::say!("rip-rt: pendulum upright, balancing");
                    }
                    phase = Phase::Balancing {
                        start_ns: tick.deadline_ns,
                    };
                }
                Err(reason) => {
                    let waited = tick.deadline_ns.saturating_sub(*since_ns);
                    if matches!(reason, StopReason::AngleLimit { .. }) || waited >= wait_upright_ns
                    {
                        break reason;
                    }
                    if !*told && !opts.quiet {
                        crate::say!(
                            "rip-rt: waiting for the pendulum to be brought upright ({reason})"
                        );
                        *told = true;
                    }
                    let n = core.encode_stop(&mut tx);
                    if let Err(e) = io.write_all(&tx[..n]) {
                        break StopReason::DeviceLost(e.to_string());
                    }
                    continue;
                }
            }
        }
        let Phase::Balancing { start_ns } = phase else {
            unreachable!("arming either breaks, continues or switches to balancing")
        };
        let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
        let mut step = match core.control(&m, t, &mut tx) {
            Ok(step) => step,
            Err(reason) => break reason,
        };
        let compute_ns = now_ns().saturating_sub(rx_done_ns);
        if let Err(e) = io.write_all(&tx[..step.len]) {
            break StopReason::DeviceLost(e.to_string());
        }
        compute.record(compute_ns);
        if tick.skipped > 0 {
            step.flags |= FLAG_DEADLINE_MISS;
        }
        last_step = Some(step);
        if let Some(log) = log.as_deref_mut() {
            if let Err(e) = log.row(
                t,
                seq,
                &step,
                core.state_estimate(),
                compute_ns as f64 / 1e3,
                tick.lateness_ns as f64 / 1e3,
            ) {
                break StopReason::LogError(e.to_string());
            }
        }
    };

    let stop_sent = guard.stop();
    drop(guard);
    let timing = TimingSummary::from_histograms(&jitter, &compute, periodic.missed());
    RunReport {
        reason,
        stop_sent,
        timing,
        parser: core.parser_stats(),
        missing_replies: missing_total,
        balanced_s: balanced_ns as f64 * 1e-9,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Parser;

    /// A controller whose output is a fixed function of y, to check the plumbing.
    struct Affine {
        gain: f64,
    }

    impl Controller for Affine {
        fn n_outputs(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
            u[0] = self.gain * (r[0] - y[0]) + 100.0 * y[1];
            StepStatus::Nominal
        }
        fn reset(&mut self) {}
    }

    /// Records what the loop tells it about held periods.
    struct Recorder {
        held: std::sync::Arc<std::sync::Mutex<Vec<f64>>>,
    }

    impl Controller for Recorder {
        fn n_outputs(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn step(&mut self, _y: &[f64], _r: &[f64], u: &mut [f64]) -> StepStatus {
            u[0] = 3.21049;
            StepStatus::Nominal
        }
        fn hold(&mut self, u: &[f64]) {
            self.held.lock().unwrap().push(u[0]);
        }
        fn reset(&mut self) {}
    }

    fn core(gain: f64) -> LoopCore {
        LoopCore::new(Box::new(Affine { gain }), &Config::default()).unwrap()
    }

    fn measurement(ack: u16, arm: i32, pend: i32) -> Measurement {
        Measurement {
            ack_seq: ack,
            arm_counts: arm,
            pendulum_counts: pend,
            ..Default::default()
        }
    }

    fn decode_one(bytes: &[u8]) -> Frame {
        let mut p = Parser::new();
        let mut out = None;
        p.feed(bytes, |f| out = Some(f));
        out.expect("one frame")
    }

    #[test]
    fn hold_passes_the_command_the_device_applies() {
        let held = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let rec = Recorder { held: held.clone() };
        let mut c = LoopCore::new(Box::new(rec), &Config::default()).unwrap();
        let mut out = [0u8; MAX_FRAME];
        // Before any command the driver is disabled: 0 V.
        assert_eq!(c.hold(), 0.0);
        c.control(&measurement(1, 0, 1024), 0.0, &mut out).unwrap();
        // The command is rounded to millivolts; the controller hears the rounded value.
        assert_eq!(c.hold(), 3.21);
        c.encode_stop(&mut out);
        assert_eq!(c.hold(), 0.0);
        assert_eq!(*held.lock().unwrap(), vec![0.0, 3.21, 0.0]);
    }

    #[test]
    fn counts_map_to_angles_with_upright_zero() {
        let c = core(1.0);
        // 2048 counts/rev; pendulum zero hanging down: 1024 counts = upright.
        let (theta, alpha) = c.angles(&measurement(0, 512, 1024));
        assert!((theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(alpha.abs() < 1e-12);
        let (_, alpha) = c.angles(&measurement(0, 0, 1024 + 2048 * 3 + 10));
        assert!((alpha - 10.0 * std::f64::consts::TAU / 2048.0).abs() < 1e-9);
        let (_, alpha) = c.angles(&measurement(0, 0, 0));
        assert!((alpha - std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn control_encodes_clamped_enabling_command() {
        let mut c = core(-100.0);
        let mut out = [0u8; MAX_FRAME];
        // theta = π/2 > step 0, so u = -100·(0 − π/2) = 157 V → clamped to 12 V.
        let s = c
            .control(&measurement(3, 512, 1024), 0.0, &mut out)
            .unwrap();
        assert_eq!(s.voltage, 12.0);
        assert!(s.flags & FLAG_CLAMPED != 0);
        match decode_one(&out[..s.len]).message {
            Message::Command(cmd) => {
                assert_eq!(cmd.voltage_mv, 12000);
                assert!(cmd.enabled());
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn limits_and_faults_stop_without_a_command() {
        let mut c = core(1.0);
        let mut out = [0u8; MAX_FRAME];
        // Pendulum 0.7 rad from upright > 0.6 limit.
        let pend = 1024 + (0.7 / std::f64::consts::TAU * 2048.0) as i32;
        let e = c
            .control(&measurement(0, 0, pend), 0.0, &mut out)
            .unwrap_err();
        assert!(
            matches!(
                e,
                StopReason::AngleLimit {
                    which: "pendulum",
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(e.exit_code(), exit_code::ANGLE_LIMIT);
        let e = c
            .control(&measurement(0, 1100, 1024), 0.0, &mut out)
            .unwrap_err();
        assert!(
            matches!(e, StopReason::AngleLimit { which: "arm", .. }),
            "{e}"
        );
        let mut m = measurement(0, 0, 1024);
        m.status = STATUS_FAULT;
        let e = c.control(&m, 0.0, &mut out).unwrap_err();
        assert_eq!(e.exit_code(), exit_code::DEVICE_FAULT);
    }

    #[test]
    fn start_requires_upright() {
        let c = core(1.0);
        assert!(c.check_start(&measurement(0, 0, 1030)).is_ok());
        let e = c.check_start(&measurement(0, 0, 0)).unwrap_err();
        assert_eq!(e.exit_code(), exit_code::NOT_UPRIGHT);
        assert!(e.to_string().contains("refusing"), "{e}");
    }

    #[test]
    fn non_finite_output_is_a_controller_fault() {
        let mut c = core(f64::NAN);
        let mut out = [0u8; MAX_FRAME];
        let e = c
            .control(&measurement(0, 0, 1024), 0.0, &mut out)
            .unwrap_err();
        assert_eq!(e.exit_code(), exit_code::CONTROLLER_FAULT);
    }

    #[test]
    fn receive_ignores_stale_answers() {
        let mut c = core(1.0);
        let mut bytes = Vec::new();
        let mut buf = [0u8; MAX_FRAME];
        for ack in [4u16, 5] {
            let n = encode(
                &Frame {
                    seq: 0,
                    message: Message::Measurement(measurement(ack, ack as i32, 1024)),
                },
                &mut buf,
            );
            bytes.extend_from_slice(&buf[..n]);
        }
        assert_eq!(c.receive(&bytes, 4).map(|m| m.arm_counts), Some(4));
        assert_eq!(c.receive(&bytes, 9), None);
    }

    #[test]
    fn exit_codes_are_distinct() {
        let reasons = [
            StopReason::Finished,
            StopReason::Signal(libc::SIGINT),
            StopReason::Signal(libc::SIGTERM),
            StopReason::DeviceLost(String::new()),
            StopReason::Watchdog(5),
            StopReason::AngleLimit {
                which: "arm",
                angle: 0.0,
                limit: 0.0,
            },
            StopReason::NotUpright {
                angle: 0.0,
                tolerance: 0.0,
            },
            StopReason::ControllerFault(String::new()),
            StopReason::DeviceFault(0),
            StopReason::LogError(String::new()),
        ];
        let mut codes: Vec<i32> = reasons.iter().map(|r| r.exit_code()).collect();
        codes.push(exit_code::SETUP);
        codes.push(exit_code::USAGE);
        codes.push(exit_code::PANIC);
        let n = codes.len();
        codes.sort();
        codes.dedup();
        assert_eq!(codes.len(), n);
        assert_eq!(StopReason::Signal(libc::SIGINT).exit_code(), 130);
    }
}

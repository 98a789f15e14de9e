//! Stop handling: why the loop stops and with which exit code, the stop frame (0 V, driver
//! disabled) on every exit path, and what each signal does.
//!
//! # Every exit path sends the stop frame
//!
//! - normal and fault stops send it explicitly and report whether it went out;
//! - a [`StopGuard`] sends it again from `Drop`, which also runs while a panic unwinds;
//! - [`emergency_stop`], called from the binary's panic hook and from the handler of the fatal
//!   signals, sends it with a bare `write(2)` on the registered descriptor, without locks or
//!   allocation.
//!
//! An orderly stop first brings the arm to rest ([`crate::braking::bring_to_rest`]) and then
//! sends the stop frame. The paths that cannot run the braking law (a fatal signal, a panic)
//! send the brake command instead (0 V, disabled, windings shorted: protocol.md rule 9), which
//! a device that can brake holds until the next command, so that the arm is braked by its
//! back-EMF rather than left to coast.
//!
//! # Signals ([`install_signal_handlers`])
//!
//! | class | signals | effect |
//! |---|---|---|
//! | stop | HUP INT QUIT USR1 USR2 ALRM TERM STKFLT TSTP TTIN XCPU VTALRM PROF IO PWR, RTMIN…RTMAX | the loop ends at its next period and brings the arm to rest, then the stop frame; exit code 128 + signal. Another one during that stop sends the stop frame at once ([`StopWatch`], [`StopReason::SignalAgain`]); one during the stop of a run that reached its duration does too, and the run exits 128 + that signal ([`cut_short`]) |
//! | fatal | ILL TRAP ABRT BUS FPE SEGV SYS | the handler writes the stop frame, then the signal's default action ends the process (core dump) |
//! | ignored | PIPE XFSZ TTOU | a broken pipe or a log over the file-size limit fails the write instead (a device loss or a log fault, both stops); a background write to the terminal proceeds instead of stopping the process |
//! | harmless | CHLD CONT URG WINCH | default (nothing happens); a resumed loop finds its deadlines missed and stops as stalled |
//! | uncatchable | KILL STOP | the device's command watchdog (protocol.md) zeroes the motor |
//!
//! SIGTSTP (Ctrl-Z) and SIGTTIN end the run rather than suspend it: a suspended loop would leave
//! the motor at its last voltage until the device's watchdog noticed. SIGTTOU is ignored
//! rather than handled because a background write with `stty tostop` would otherwise raise it
//! again on every retry of the write, inside the loop.

use std::io;
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU16, AtomicUsize, Ordering};

use crate::config::ConfigError;
use crate::log::LogError;
use crate::protocol::{encode, Command, Frame, Message, MAX_FRAME};

/// Exit codes, as documented in `rip-rt run --help` and `docs/rip-rt.md`.
pub mod exit_code {
    /// `--duration` elapsed.
    pub const FINISHED: i32 = 0;
    /// The loop could not start (port, log, controller design); the motor was never enabled.
    pub const SETUP: i32 = 1;
    /// Bad command line or configuration (clap's own usage errors also use 2).
    pub const USAGE: i32 = 2;
    /// The device went away or I/O failed.
    pub const DEVICE_LOST: i32 = 3;
    /// Watchdog: no valid measurement for `loop.watchdog_periods` periods.
    pub const WATCHDOG: i32 = 4;
    /// An angle limit was exceeded, or the arm's braking envelope reached `safety.arm_limit`.
    pub const ANGLE_LIMIT: i32 = 5;
    /// Refused to start: the pendulum was not near upright.
    pub const NOT_UPRIGHT: i32 = 6;
    /// The controller produced a non-finite output.
    pub const CONTROLLER_FAULT: i32 = 7;
    /// The device reported a driver fault.
    pub const DEVICE_FAULT: i32 = 8;
    /// The log could not be written.
    pub const LOG_ERROR: i32 = 9;
    /// Compute overrun while running: a step too long, too many deadline misses in a row, or
    /// the loop stalled.
    pub const OVERRUN: i32 = 10;
    /// Refused to start: timed steps of the controller do not fit the period.
    pub const TOO_SLOW: i32 = 11;
    /// Refused to start: the rig was not at rest hanging down (the rest check before a run
    /// that starts hanging); the motor was never enabled.
    pub const NOT_AT_REST: i32 = 12;
    /// The swing-up did not reach its catch region within `swing_up.max_time`; or, after
    /// falls with `swing_up.on_fall = "retry"`, the swing-ups took `swing_up.max_time` in total,
    /// or the run was not balanced for `--duration` within `swing_up.max_time + --duration`.
    pub const SWING_UP_FAILED: i32 = 13;
    /// Refused the experiment: the motor-sign / encoder-direction check before it failed (the
    /// message says what to swap); the motor had only the check's short pulse.
    pub const SIGN_CHECK: i32 = 14;
    /// The rig did not move as commanded: the witness ([`crate::witness`]) found the measured
    /// motion disagreeing with what the applied voltage must produce (a motor lead swapped, an
    /// encoder reversed or not counting).
    pub const WITNESS: i32 = 15;
    /// Refused to start: the pre-flight check (rip-core's `preflight`) refused the run (an
    /// untrusted identification, a rig no controller can balance at the voltage bound, a
    /// controller predicted to fall); `--force` runs it anyway. The motor was never enabled.
    pub const PREFLIGHT: i32 = 16;
    /// A panic (Rust's own exit code for one).
    pub const PANIC: i32 = 101;
    /// Stopped by a signal: 128 + its number (130 SIGINT, 143 SIGTERM, 129 SIGHUP, …); a
    /// second signal during the stop ([`super::StopReason::SignalAgain`]) exits with 128 + the
    /// second one's number, the log's footer saying `stop=signal_again`.
    pub const SIGNAL_BASE: i32 = 128;
}

/// How a compute overrun showed itself.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum Overrun {
    /// One controller step took longer than `loop.max_step_periods`; its command was not sent.
    #[error("a controller step took {took_ms:.2} ms, longer than loop.max_step_periods ({limit_ms:.2} ms); its command was not sent")]
    Step {
        /// The step's duration (ms).
        took_ms: f64,
        /// The limit (ms).
        limit_ms: f64,
    },
    /// `loop.max_consecutive_misses` periods in a row took longer than a period from wake-up
    /// to command.
    #[error("{0} periods in a row took longer than a period from wake-up to command (loop.max_consecutive_misses)")]
    Misses(u32),
    /// The loop did not run (suspended, or starved of the CPU) for
    /// [`MAX_BLIND_MS`](crate::config::MAX_BLIND_MS) or longer.
    #[error("the loop stalled for {ms:.0} ms (suspended or starved of the CPU)")]
    Stall {
        /// How long (ms).
        ms: f64,
    },
}

/// Why the loop stopped. Each reason has its own exit code ([`StopReason::exit_code`]).
#[derive(Debug, thiserror::Error)]
pub enum StopReason {
    /// `--duration` elapsed.
    #[error("run finished (duration elapsed)")]
    Finished,
    /// A stop signal (its number).
    #[error("stopped by {name} ({0})", name = signal_name(*.0))]
    Signal(i32),
    /// A second stop signal while the stop after the first brought the arm to rest: the
    /// driver was disabled at once, before the arm was at rest ([`StopWatch`]).
    #[error(
        "stopped by {first_name} ({first}), then {second_name} ({second}) during the stop: \
         the driver was disabled before the arm was at rest (it may coast past safety.arm_limit)",
        first_name = signal_name(*.first),
        second_name = signal_name(*.second)
    )]
    SignalAgain {
        /// The signal that began the stop.
        first: i32,
        /// The signal that cut it short.
        second: i32,
    },
    /// Reading from or writing to the device failed, or it went away.
    #[error("device lost: {0}")]
    DeviceLost(#[source] io::Error),
    /// No valid measurement for this many consecutive periods.
    #[error("watchdog: no valid measurement from the device for {0} consecutive periods")]
    Watchdog(u32),
    /// An angle left its limit.
    #[error("{which} angle limit: |{angle:.3}| rad exceeds {limit:.3} rad")]
    AngleLimit {
        /// `"pendulum"` or `"arm"`.
        which: &'static str,
        /// The measured angle (rad).
        angle: f64,
        /// The limit (rad).
        limit: f64,
    },
    /// The arm's stopping point (where braking at the voltage bound would stop it, from its
    /// measured angle and rate: [`crate::envelope`]) left `safety.arm_limit`, less the
    /// envelope's margin: stopped while it can still stop inside the limit.
    #[error("arm braking envelope: at {angle:.3} rad and {rate:.2} rad/s the arm would stop at {stop_at:.3} rad when braked, past safety.arm_limit ({limit:.3} rad) less its margin")]
    ArmEnvelope {
        /// The measured arm angle (rad).
        angle: f64,
        /// The measured arm rate (rad/s).
        rate: f64,
        /// The predicted stopping point (rad).
        stop_at: f64,
        /// `safety.arm_limit` (rad).
        limit: f64,
    },
    /// The pendulum was not near upright when balancing was to start.
    #[error("refusing to balance: pendulum at {angle:.3} rad from upright, start tolerance is {tolerance:.3} rad")]
    NotUpright {
        /// The measured pendulum angle (rad from upright).
        angle: f64,
        /// `safety.start_tolerance` (rad).
        tolerance: f64,
    },
    /// The controller produced a non-finite voltage.
    #[error("controller fault: non-finite voltage {voltage} at t = {t:.3} s")]
    ControllerFault {
        /// The voltage it produced.
        voltage: f64,
        /// Seconds since balancing started.
        t: f64,
    },
    /// The device reported a driver fault.
    #[error("device reported a driver fault (status 0x{0:02x})")]
    DeviceFault(u8),
    /// The log file could not be written.
    #[error("log fault: {0}")]
    LogError(#[source] LogError),
    /// The controller or the loop did not keep up with the period while running.
    #[error("compute overrun: {0}")]
    Overrun(#[source] Overrun),
    /// Before enabling the motor, timed controller steps did not fit the period.
    #[error("refusing to start: the controller needs {median_ms:.3} ms per step (median of {steps} timed step(s)), the period leaves {budget_ms:.3} ms after the reply timeout")]
    TooSlow {
        /// Median step time (ms).
        median_ms: f64,
        /// `loop.period_ms − loop.reply_timeout_ms`.
        budget_ms: f64,
        /// Steps timed.
        steps: usize,
    },
    /// After a swing-up's catch the rig left the balance region (the pendulum past
    /// `swing_up.balance_angle`, or the arm past `swing_up.arm_limit`) and `swing_up.on_fall`
    /// is `stop`.
    #[error("the {part} left the balance region after the catch: |{angle:.3}| rad is past {key} ({limit:.3} rad), and swing_up.on_fall is \"stop\"")]
    Fell {
        /// `"pendulum"` or `"arm"`: which part left the region.
        part: &'static str,
        /// The key of the bound it passed: `swing_up.balance_angle` or `swing_up.arm_limit`.
        key: &'static str,
        /// The measured angle of that part (rad; the pendulum's from upright).
        angle: f64,
        /// The bound (rad).
        limit: f64,
    },
    /// The swing-up did not bring the pendulum into its catch region in time.
    #[error("the swing-up failed: no catch within swing_up.max_time ({max_time} s){}", report.map_or(String::new(), |r| format!(": {r}")))]
    SwingUpFailed {
        /// `swing_up.max_time` (s).
        max_time: f64,
        /// What the swing-up did (peak energy against the target, voltage, arm travel).
        report: Option<rip_core::swingup::SwingUpReport>,
    },
    /// After falls with `swing_up.on_fall = "retry"`, the swing-ups together took
    /// `swing_up.max_time`: a rig that catches and drops the pendulum again and again (a wrong
    /// model or calibration) is stopped instead of pumping for ever.
    #[error("the swing-up failed: the pendulum fell {falls} time(s) after its catch, and the swing-ups took swing_up.max_time ({max_time} s) in total")]
    SwingUpRetriesExhausted {
        /// Falls after a catch.
        falls: u32,
        /// `swing_up.max_time` (s).
        max_time: f64,
    },
    /// A swing-up run with `--duration` was not balanced for the duration within
    /// `swing_up.max_time + --duration` of the swing's start (falls and new swing-ups used
    /// up the time): the whole run is bounded.
    #[error("the swing-up failed: the pendulum fell {falls} time(s) after its catch and was not balanced for --duration ({duration} s) within swing_up.max_time + --duration ({bound} s) of the swing's start")]
    SwingUpRunTimeout {
        /// Falls after a catch.
        falls: u32,
        /// `--duration` (s).
        duration: f64,
        /// `swing_up.max_time + --duration` (s).
        bound: f64,
    },
    /// The rest check before a run that starts hanging found the rig moving, or resting away
    /// from hanging; the motor was never enabled.
    #[error("refusing to start: the rig is not at rest hanging down: {0}")]
    NotAtRest(#[source] crate::rest::RestFault),
    /// The motor-sign / encoder-direction check before an experiment failed.
    #[error("refusing to start the experiment: sign check failed: {0}")]
    SignCheck(#[source] crate::sign_check::SignFault),
    /// The rig does not move as commanded ([`crate::witness`]).
    #[error("the rig does not move as commanded: {0}")]
    Witness(#[source] crate::witness::WitnessFault),
    /// A thread other than the loop panicked (the panic hook already sent the stop frame).
    #[error("internal error: a panic outside the loop")]
    Panic,
}

impl StopReason {
    /// The process exit code for this stop.
    pub fn exit_code(&self) -> i32 {
        match self {
            StopReason::Finished => exit_code::FINISHED,
            StopReason::Signal(s) => exit_code::SIGNAL_BASE + s,
            // The signal that ended the process, as a shell expects of one it interrupted.
            StopReason::SignalAgain { second, .. } => exit_code::SIGNAL_BASE + second,
            StopReason::DeviceLost(_) => exit_code::DEVICE_LOST,
            StopReason::Watchdog(_) => exit_code::WATCHDOG,
            StopReason::AngleLimit { .. } | StopReason::ArmEnvelope { .. } => {
                exit_code::ANGLE_LIMIT
            }
            StopReason::NotUpright { .. } => exit_code::NOT_UPRIGHT,
            StopReason::ControllerFault { .. } => exit_code::CONTROLLER_FAULT,
            StopReason::DeviceFault(_) => exit_code::DEVICE_FAULT,
            StopReason::LogError(_) => exit_code::LOG_ERROR,
            StopReason::Overrun(_) => exit_code::OVERRUN,
            StopReason::TooSlow { .. } => exit_code::TOO_SLOW,
            StopReason::NotAtRest(_) => exit_code::NOT_AT_REST,
            StopReason::Fell { .. } => exit_code::ANGLE_LIMIT,
            StopReason::SwingUpFailed { .. }
            | StopReason::SwingUpRetriesExhausted { .. }
            | StopReason::SwingUpRunTimeout { .. } => exit_code::SWING_UP_FAILED,
            StopReason::SignCheck(_) => exit_code::SIGN_CHECK,
            StopReason::Witness(_) => exit_code::WITNESS,
            StopReason::Panic => exit_code::PANIC,
        }
    }

    /// A short machine-readable name (used in the log footer).
    pub fn name(&self) -> &'static str {
        match self {
            StopReason::Finished => "finished",
            StopReason::Signal(_) => "signal",
            StopReason::SignalAgain { .. } => "signal_again",
            StopReason::DeviceLost(_) => "device_lost",
            StopReason::Watchdog(_) => "watchdog",
            StopReason::AngleLimit { .. } | StopReason::ArmEnvelope { .. } => "angle_limit",
            StopReason::NotUpright { .. } => "not_upright",
            StopReason::ControllerFault { .. } => "controller_fault",
            StopReason::DeviceFault(_) => "device_fault",
            StopReason::LogError(_) => "log_error",
            StopReason::Overrun(_) => "overrun",
            StopReason::TooSlow { .. } => "too_slow",
            StopReason::NotAtRest(_) => "not_at_rest",
            StopReason::Fell { .. } => "fell",
            StopReason::SwingUpFailed { .. }
            | StopReason::SwingUpRetriesExhausted { .. }
            | StopReason::SwingUpRunTimeout { .. } => "swing_up_failed",
            StopReason::SignCheck(_) => "sign_check",
            StopReason::Witness(_) => "witness",
            StopReason::Panic => "panic",
        }
    }

    /// Whether this is an orderly stop (the duration, or an operator's signal) rather than a
    /// fault.
    pub fn is_orderly(&self) -> bool {
        matches!(
            self,
            StopReason::Finished | StopReason::Signal(_) | StopReason::SignalAgain { .. }
        )
    }
}

/// Why `rip-rt run` could not start; the motor was never enabled.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The configuration file is unreadable or invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The controller could not be designed.
    #[error("{0}")]
    Design(String),
    /// The controller does not have the pendulum's 2 outputs and 1 input.
    #[error(
        "the controller has {outputs} outputs and {inputs} inputs; the pendulum needs 2 and 1"
    )]
    ControllerShape {
        /// Its outputs.
        outputs: usize,
        /// Its inputs.
        inputs: usize,
    },
    /// A signal handler could not be installed.
    #[error("cannot install the handler of signal {signal}: {source}")]
    Signal {
        /// The signal.
        signal: i32,
        /// Why.
        #[source]
        source: io::Error,
    },
    /// The port could not be opened, set up or locked.
    #[error(transparent)]
    Port(io::Error),
    /// The log could not be created or its header not written.
    #[error(transparent)]
    Log(#[from] LogError),
    /// The pre-flight check refused the run (its findings, one a line).
    #[error("the pre-flight check refuses this run (--force runs it anyway):\n{0}")]
    Preflight(String),
}

impl SetupError {
    /// The process exit code: [`exit_code::USAGE`] for a bad configuration,
    /// [`exit_code::PREFLIGHT`] for a pre-flight refusal, else [`exit_code::SETUP`].
    pub fn exit_code(&self) -> i32 {
        match self {
            SetupError::Config(_) => exit_code::USAGE,
            SetupError::Preflight(_) => exit_code::PREFLIGHT,
            _ => exit_code::SETUP,
        }
    }
}

/// The name of signal `sig` (`"SIGINT"`, …; `"SIGRTMIN+3"` for real-time signals).
pub fn signal_name(sig: i32) -> String {
    let name = match sig {
        libc::SIGHUP => "SIGHUP",
        libc::SIGINT => "SIGINT",
        libc::SIGQUIT => "SIGQUIT",
        libc::SIGILL => "SIGILL",
        libc::SIGTRAP => "SIGTRAP",
        libc::SIGABRT => "SIGABRT",
        libc::SIGBUS => "SIGBUS",
        libc::SIGFPE => "SIGFPE",
        libc::SIGUSR1 => "SIGUSR1",
        libc::SIGSEGV => "SIGSEGV",
        libc::SIGUSR2 => "SIGUSR2",
        libc::SIGPIPE => "SIGPIPE",
        libc::SIGALRM => "SIGALRM",
        libc::SIGTERM => "SIGTERM",
        libc::SIGSTKFLT => "SIGSTKFLT",
        libc::SIGTSTP => "SIGTSTP",
        libc::SIGTTIN => "SIGTTIN",
        libc::SIGTTOU => "SIGTTOU",
        libc::SIGXCPU => "SIGXCPU",
        libc::SIGXFSZ => "SIGXFSZ",
        libc::SIGVTALRM => "SIGVTALRM",
        libc::SIGPROF => "SIGPROF",
        libc::SIGIO => "SIGIO",
        libc::SIGPWR => "SIGPWR",
        libc::SIGSYS => "SIGSYS",
        s if (libc::SIGRTMIN()..=libc::SIGRTMAX()).contains(&s) => {
            return format!("SIGRTMIN+{}", s - libc::SIGRTMIN())
        }
        _ => "signal",
    };
    name.to_string()
}

/// Signals that end the run at the next period, with exit code 128 + the signal.
pub fn stop_signals() -> Vec<i32> {
    let mut v = vec![
        libc::SIGHUP,
        libc::SIGINT,
        libc::SIGQUIT,
        libc::SIGUSR1,
        libc::SIGUSR2,
        libc::SIGALRM,
        libc::SIGTERM,
        libc::SIGSTKFLT,
        libc::SIGTSTP,
        libc::SIGTTIN,
        libc::SIGXCPU,
        libc::SIGVTALRM,
        libc::SIGPROF,
        libc::SIGIO,
        libc::SIGPWR,
    ];
    v.extend(libc::SIGRTMIN()..=libc::SIGRTMAX());
    v
}

/// Signals raised by a fault in the process itself (or sent as if they were): the stop frame
/// goes out from the handler, then the default action ends the process.
pub const FATAL_SIGNALS: [i32; 7] = [
    libc::SIGILL,
    libc::SIGTRAP,
    libc::SIGABRT,
    libc::SIGBUS,
    libc::SIGFPE,
    libc::SIGSEGV,
    libc::SIGSYS,
];

/// Signals ignored, so that the operation that raised them fails (or, for SIGTTOU, proceeds)
/// and is handled where it happened.
pub const IGNORED_SIGNALS: [i32; 3] = [libc::SIGPIPE, libc::SIGXFSZ, libc::SIGTTOU];

// The stop request: 0 for none, a signal number, or PANIC_REQUEST.
static STOP_REQUEST: AtomicUsize = AtomicUsize::new(0);
const PANIC_REQUEST: usize = usize::MAX;
// Every stop signal received, and the latest one: the stop request keeps only the first, and
// the active stop must see the ones after it ([`StopWatch`]).
static SIGNALS: AtomicUsize = AtomicUsize::new(0);
static LAST_SIGNAL: AtomicI32 = AtomicI32::new(0);

/// The stop requested by a signal or by a panic on another thread, if any.
pub fn requested_stop() -> Option<StopReason> {
    match STOP_REQUEST.load(Ordering::Relaxed) {
        0 => None,
        PANIC_REQUEST => Some(StopReason::Panic),
        sig => Some(StopReason::Signal(sig as i32)),
    }
}

/// Asks the running loop to stop at its next period with [`StopReason::Signal`]`(sig)`.
/// Async-signal-safe.
pub(crate) fn request_stop(sig: i32) {
    LAST_SIGNAL.store(sig, Ordering::Relaxed);
    // Counted after the signal is stored, so that a watcher that sees the count sees it.
    SIGNALS.fetch_add(1, Ordering::Release);
    // The first request wins: its signal is the one reported.
    let _ = STOP_REQUEST.compare_exchange(0, sig as usize, Ordering::Relaxed, Ordering::Relaxed);
}

/// Watches, period by period, for a stop signal that arrives while the active stop brings the
/// arm to rest: an operator who signals again (a second Ctrl-C) wants the driver disabled at
/// once, not in up to [`crate::braking::MAX_STOP_S`]. Lock-free (two atomic loads).
#[derive(Debug, Clone, Copy)]
pub struct StopWatch {
    seen: usize,
}

impl StopWatch {
    /// The watch of the stop after `reason`: a stop begun by a signal counts that signal as
    /// seen, and any signal after it cuts the stop short; any other stop (a fault, the
    /// duration) is cut short by the first.
    pub fn for_stop(reason: &StopReason) -> Self {
        let seen = match reason {
            StopReason::Signal(_) => 1,
            _ => 0,
        };
        Self { seen }
    }

    /// The latest signal, if one arrived that the stop has not seen.
    pub fn interrupted(&self) -> Option<i32> {
        self.interrupted_after(SIGNALS.load(Ordering::Acquire), || {
            LAST_SIGNAL.load(Ordering::Relaxed)
        })
    }

    fn interrupted_after(&self, received: usize, last: impl FnOnce() -> i32) -> Option<i32> {
        (received > self.seen).then(last)
    }
}

/// The reason of a stop that a signal, `by`, cut short ([`StopWatch`]): a signal's stop becomes
/// [`StopReason::SignalAgain`]; the stop of a run that reached its duration becomes the
/// signal's ([`StopReason::Signal`], exit 128 + `by`): the run did not end as it was asked to,
/// the arm-limit guarantee was given up, and exit 0 would say otherwise; a fault's stop keeps
/// its own reason (its exit code says what went wrong; the stop's line says it was cut short).
pub fn cut_short(reason: StopReason, by: i32) -> StopReason {
    match reason {
        StopReason::Signal(first) => StopReason::SignalAgain { first, second: by },
        StopReason::Finished => StopReason::Signal(by),
        other => other,
    }
}

extern "C" fn on_fatal_signal(sig: libc::c_int) {
    emergency_stop();
    const MSG: &[u8] =
        b"rip-rt: fatal signal; brake command (0 V, disabled, windings shorted) sent\n";
    // SAFETY: write, sigaction and raise are async-signal-safe; every pointer is valid.
    unsafe {
        libc::write(2, MSG.as_ptr().cast(), MSG.len());
        let mut dfl: libc::sigaction = std::mem::zeroed();
        dfl.sa_sigaction = libc::SIG_DFL;
        libc::sigaction(sig, &dfl, std::ptr::null_mut());
        // Blocked until this handler returns, then delivered with the default action. A real
        // fault would also repeat on return; a signal sent with kill would not, hence raise.
        libc::raise(sig);
    }
}

/// Gives every catchable signal its disposition (module docs). Call once, before the port is
/// opened.
pub fn install_signal_handlers() -> Result<(), SetupError> {
    for sig in stop_signals() {
        // SAFETY: the action only does an atomic compare-exchange (async-signal-safe).
        unsafe { signal_hook::low_level::register(sig, move || request_stop(sig)) }.map_err(
            |source| SetupError::Signal {
                signal: sig,
                source,
            },
        )?;
    }
    for sig in FATAL_SIGNALS {
        // SAFETY: a zeroed sigaction is valid; the handler is async-signal-safe. SA_ONSTACK
        // lets a stack overflow's SIGSEGV run it on the alternate stack std sets up.
        let rc = unsafe {
            let mut act: libc::sigaction = std::mem::zeroed();
            act.sa_sigaction = on_fatal_signal as extern "C" fn(libc::c_int) as *const () as usize;
            act.sa_flags = libc::SA_ONSTACK;
            libc::sigemptyset(&mut act.sa_mask);
            libc::sigaction(sig, &act, std::ptr::null_mut())
        };
        if rc != 0 {
            return Err(SetupError::Signal {
                signal: sig,
                source: io::Error::last_os_error(),
            });
        }
    }
    for sig in IGNORED_SIGNALS {
        // SAFETY: installing SIG_IGN has no memory-safety preconditions.
        if unsafe { libc::signal(sig, libc::SIG_IGN) } == libc::SIG_ERR {
            return Err(SetupError::Signal {
                signal: sig,
                source: io::Error::last_os_error(),
            });
        }
    }
    Ok(())
}

/// Installs a panic hook that sends the brake command before anything else runs, and asks the
/// loop to stop when the panic is on another thread (the loop's own panic unwinds through its
/// [`StopGuard`]).
pub fn install_panic_hook() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        emergency_stop();
        if !IN_LOOP_THREAD.with(|t| t.load(Ordering::Relaxed)) {
            STOP_REQUEST.store(PANIC_REQUEST, Ordering::Relaxed);
        }
        previous(info);
    }));
}

thread_local! {
    static IN_LOOP_THREAD: AtomicBool = const { AtomicBool::new(false) };
}

// The descriptor and sequence counter the emergency stop needs; -1 when no loop is running.
static STOP_FD: AtomicI32 = AtomicI32::new(-1);
static TX_SEQ: AtomicU16 = AtomicU16::new(0);

/// The next host sequence number (shared by the loop and the emergency stop).
pub(crate) fn next_seq() -> u16 {
    TX_SEQ.fetch_add(1, Ordering::Relaxed)
}

/// Writes the stop frame to `fd` with a bare `write(2)`; returns whether all bytes went out.
/// Async-signal-safe: no locks, no allocation.
fn write_stop(fd: i32) -> bool {
    write_command(fd, Command::STOP)
}

/// Writes `command` to `fd` with a bare `write(2)`; async-signal-safe.
fn write_command(fd: i32, command: Command) -> bool {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(
        &Frame {
            seq: next_seq(),
            message: Message::Command(command),
        },
        &mut buf,
    );
    // SAFETY: `buf` is valid for `n` bytes; a stale descriptor only makes write fail.
    let written = unsafe { libc::write(fd, buf.as_ptr().cast(), n) };
    written == n as isize
}

/// Sends the brake command (0 V, driver disabled, windings shorted; module docs) three times
/// on the descriptor registered by the running loop, if any. Safe to call from a panic hook or
/// a signal handler: no locks, no allocation.
pub fn emergency_stop() {
    let fd = STOP_FD.load(Ordering::SeqCst);
    if fd >= 0 {
        for _ in 0..3 {
            write_command(fd, Command::BRAKE);
        }
    }
}

/// Registers the device descriptor for [`emergency_stop`] and sends the stop frame when
/// dropped, including during a panic's unwinding.
#[derive(Debug)]
pub struct StopGuard {
    fd: i32,
}

impl StopGuard {
    /// Arms the guard for `fd` (and marks the calling thread as the loop's).
    pub fn new(fd: i32) -> Self {
        STOP_FD.store(fd, Ordering::SeqCst);
        IN_LOOP_THREAD.with(|t| t.store(true, Ordering::Relaxed));
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
        if std::thread::panicking() {
            // Unwinding past the braking law: brake with the windings instead (module docs).
            for _ in 0..3 {
                write_command(self.fd, Command::BRAKE);
            }
        } else {
            self.stop();
        }
        STOP_FD.store(-1, Ordering::SeqCst);
        IN_LOOP_THREAD.with(|t| t.store(false, Ordering::Relaxed));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_codes_are_distinct() {
        let reasons = [
            StopReason::Finished,
            StopReason::Signal(libc::SIGINT),
            StopReason::Signal(libc::SIGTERM),
            StopReason::DeviceLost(io::Error::other("x")),
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
            StopReason::ControllerFault {
                voltage: f64::NAN,
                t: 0.0,
            },
            StopReason::DeviceFault(0),
            StopReason::LogError(LogError::WriterGone),
            StopReason::Overrun(Overrun::Misses(3)),
            StopReason::TooSlow {
                median_ms: 1.0,
                budget_ms: 0.5,
                steps: 3,
            },
            StopReason::NotAtRest(crate::rest::RestFault::NotHanging {
                offset: 1.0,
                max: 0.5,
            }),
            StopReason::SwingUpFailed {
                max_time: 20.0,
                report: None,
            },
            StopReason::SignCheck(crate::sign_check::SignFault::MotorReversed { arm: -10.0 }),
            StopReason::Panic,
        ];
        let mut codes: Vec<i32> = reasons.iter().map(|r| r.exit_code()).collect();
        codes.push(exit_code::SETUP);
        codes.push(exit_code::USAGE);
        let n = codes.len();
        codes.sort();
        codes.dedup();
        assert_eq!(codes.len(), n);
        assert_eq!(StopReason::Signal(libc::SIGINT).exit_code(), 130);
    }

    #[test]
    fn a_second_signal_cuts_a_signals_stop_short_and_the_first_signal_any_other() {
        let sigint = StopWatch::for_stop(&StopReason::Signal(libc::SIGINT));
        assert_eq!(sigint.interrupted_after(1, || libc::SIGINT), None);
        assert_eq!(
            sigint.interrupted_after(2, || libc::SIGTERM),
            Some(libc::SIGTERM)
        );
        let fault = StopWatch::for_stop(&StopReason::Watchdog(5));
        assert_eq!(fault.interrupted_after(0, || 0), None);
        assert_eq!(
            fault.interrupted_after(1, || libc::SIGINT),
            Some(libc::SIGINT)
        );
        let again = cut_short(StopReason::Signal(libc::SIGINT), libc::SIGINT);
        assert!(matches!(
            again,
            StopReason::SignalAgain {
                first: libc::SIGINT,
                second: libc::SIGINT
            }
        ));
        assert_eq!(again.exit_code(), 130);
        assert_eq!(again.name(), "signal_again");
        assert!(again.is_orderly());
        assert!(again
            .to_string()
            .contains("disabled before the arm was at rest"));
        let term = cut_short(StopReason::Signal(libc::SIGINT), libc::SIGTERM);
        assert_eq!(term.exit_code(), 143);
        // A fault's stop keeps its own code: it says what went wrong.
        let fault = cut_short(StopReason::Watchdog(5), libc::SIGINT);
        assert_eq!(fault.exit_code(), exit_code::WATCHDOG);
        // A finished run's stop cut short is no longer a clean end.
        let finished = cut_short(StopReason::Finished, libc::SIGINT);
        assert_eq!(finished.exit_code(), 130);
        assert_eq!(finished.name(), "signal");
        assert_ne!(
            cut_short(StopReason::Finished, libc::SIGTERM).exit_code(),
            exit_code::FINISHED
        );
    }

    #[test]
    fn every_catchable_signal_has_one_disposition() {
        let stop = stop_signals();
        let harmless = [libc::SIGCHLD, libc::SIGCONT, libc::SIGURG, libc::SIGWINCH];
        let uncatchable = [libc::SIGKILL, libc::SIGSTOP];
        for sig in 1..=libc::SIGRTMAX() {
            // glibc keeps 32 and 33 for its threads; they are not valid to send to us.
            if sig > libc::SIGSYS && sig < libc::SIGRTMIN() {
                continue;
            }
            let classes = [
                stop.contains(&sig),
                FATAL_SIGNALS.contains(&sig),
                IGNORED_SIGNALS.contains(&sig),
                harmless.contains(&sig),
                uncatchable.contains(&sig),
            ];
            let n = classes.iter().filter(|c| **c).count();
            assert_eq!(
                n,
                1,
                "signal {sig} ({}) is in {n} classes",
                signal_name(sig)
            );
        }
    }
}

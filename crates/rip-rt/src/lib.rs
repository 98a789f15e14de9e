//! # rip-rt
//!
//! The PC side of the rotary inverted pendulum rig: the control loop that talks to the
//! pendulum's microcontroller over a serial link, and a device emulator that speaks the same
//! protocol over a pseudo-terminal so the whole loop can be tested on any machine.
//!
//! - [`cli`] — the `rip-rt` command line, from arguments to exit code (the binary and the
//!   Python package's console script both run it).
//! - [`protocol`] — wire protocol v1, the `rip-protocol` crate that the firmware runs too.
//! - [`period`] — the period driver: the exchange, staleness, watchdog, stall, compute and
//!   log rules every command law (`run`, `excite`) runs under, on one clock.
//! - [`runner`] — `rip-rt run`'s command law and its phases (probe, arming, balancing).
//! - [`excite`] — `rip-rt excite`: the sign check and an open-loop excitation, hanging down.
//! - [`sign_check`] — the motor-sign / encoder-direction check pulse and its diagnosis.
//! - [`loop_core`] — the loop's logic without I/O: decoding, limits, the controller step,
//!   command frames.
//! - [`envelope`] — the arm's braking envelope (`safety.arm_limit` for the arm's stopping
//!   point) and the law of the active stop that brakes it to rest; [`braking`] runs that stop
//!   on the device.
//! - [`stop`] — stop reasons and exit codes, the stop frame on every exit path, signals.
//! - [`step`] — what one period produced (the log's row data and status bits).
//! - [`log`] — the CSV log and its writer thread; [`live`] — the live telemetry stream for
//!   `riprs watch`, which never holds the loop up.
//! - [`timing`] — absolute-deadline scheduling, latency histograms, real-time settings.
//! - [`rest`] — the rest check and the encoder zeros taken hanging down, without I/O;
//!   [`calibrate`] runs it on the device.
//! - [`config`] — the TOML configuration.
//! - [`serial`] — raw termios serial I/O and pseudo-terminals.
//!
//! `docs/protocol.md` specifies the protocol for firmware authors and `docs/rip-rt.md` the
//! command line, the safety rules, the exit codes and the log format.

// The command line was written as the binary's crate, naming this library `rip_rt`; the alias
// keeps those paths valid now that it lives here.
extern crate self as rip_rt;

pub mod braking;
pub mod calibrate;
pub mod cli;
pub mod config;
pub mod controllers;
pub mod emulator;
pub mod envelope;
pub mod exchange;
pub mod excite;
pub mod live;
pub mod log;
pub mod loop_core;
pub mod onboard;
pub mod period;
pub mod plant;
pub mod rest;
pub use rip_protocol as protocol;
pub mod runner;
pub mod serial;
pub mod sign_check;
pub mod step;
pub mod stop;
pub mod timing;
pub mod witness;

/// `eprintln!` that ignores a failed write: once the terminal or the pipe behind stderr has
/// gone (SIGHUP, a closed SSH session), a status line must not turn into a panic and its exit
/// code 101 in place of the stop's own.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        let _ = ::std::writeln!(::std::io::stderr(), $($arg)*);
    }};
}

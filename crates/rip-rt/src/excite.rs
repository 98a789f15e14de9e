//! `rip-rt excite`: an open-loop identification experiment with the pendulum hanging down.
//!
//! A run goes through these stages, on the loop's grid of absolute deadlines:
//!
//! 1. **rest check and calibration** (motor disabled): the encoder zeros are taken with the rig
//!    at rest hanging down ([`crate::calibrate`]);
//! 2. **sign check** ([`crate::sign_check`]): a short, small pulse and 0 V; a rig whose motor
//!    or encoders disagree with the model's convention is refused
//!    ([`StopReason::SignCheck`]) before any experiment;
//! 3. **excitation**: every period the signal `e(t)` of `rip_core::excitation` at the time
//!    since this stage started, through the weak arm-centring law (free swing: unchanged), as
//!    an enabling command, until the signal's duration has passed.
//!
//! The rules of `rip-rt run` hold throughout (`docs/rip-rt.md`): the arm limit
//! (`safety.arm_limit`, checked on every measurement; the hanging pendulum has none), the
//! voltage clamp, the watchdog and the bound on driving without a measurement, the compute and
//! stall rules, stop signals, log faults, and the stop frame on every way out (the caller's
//! [`StopGuard`] and this module's explicit stop).

use rip_core::excitation::{Excitation, Signal, Stage as SignalStage};

use crate::calibrate::check_rest;
use crate::config::Config;
use crate::log::LogWriter;
use crate::loop_core::LoopCore;
use crate::period::{Act, Law, Logged, Period, Reply};
use crate::protocol::{ParserStats, MAX_FRAME};
use crate::serial::Fd;
use crate::sign_check::{SignCheck, SignReport};
use crate::stop::{StopGuard, StopReason};
use crate::timing::{ClockMode, Periodic, Tick, TimingSummary};

/// Options of one excitation run besides the configuration and the signal.
#[derive(Debug, Clone)]
pub struct ExciteOptions {
    /// Sign-check pulse voltage (V), capped at `safety.voltage_limit`.
    pub check_voltage: f64,
    /// Suppress progress messages on stderr.
    pub quiet: bool,
    /// The clock of the loop: real time, or lockstep with an emulator (`--lockstep`).
    pub clock: ClockMode,
}

/// The outcome of [`run`].
#[derive(Debug)]
pub struct ExciteReport {
    /// Why the run stopped ([`StopReason::Finished`] once the signal is complete).
    pub reason: StopReason,
    /// Whether the final stop frame was written to the device.
    pub stop_sent: bool,
    /// Timing figures of the periods that drove the motor.
    pub timing: TimingSummary,
    /// Parser counters.
    pub parser: ParserStats,
    /// Periods without a valid measurement.
    pub missing_replies: u64,
    /// The calibration, as the log footer prints it (absent when it did not complete).
    pub calibration: Option<String>,
    /// The sign check's result (absent when it did not pass).
    pub sign_check: Option<SignReport>,
    /// Seconds of excitation.
    pub excited_s: f64,
    /// Largest |θ| (rad) measured while the motor was driven.
    pub max_arm: f64,
}

/// The log's `phase` names.
pub mod phase {
    /// The sign-check pulse and the 0 V after it.
    pub const SIGN_CHECK: &str = "sign_check";
    /// Free swing: the kick.
    pub const KICK: &str = "kick";
    /// Free swing: coasting at 0 V.
    pub const COAST: &str = "coast";
}

#[derive(Debug, Clone, Copy)]
enum Stage {
    SignCheck { start_ns: u64 },
    Excite { start_ns: u64 },
}

/// The command law of `rip-rt excite` (and of the sign check alone): the sign check's pulse,
/// then the excitation signal through the arm-centring law.
struct Exciter<'a> {
    // None: the sign check alone (`rip-rt run --swing-up`), done once it has passed.
    excitation: Option<&'a mut Excitation>,
    check: SignCheck,
    sign_report: Option<SignReport>,
    stage: Stage,
    arm_limit: f64,
    quiet: bool,
    // The log's time zero: the first deadline of the sign check.
    t0_ns: u64,
    excited_ns: u64,
    max_arm: f64,
    // The last measured arm angle and its period's deadline, for the arm rate.
    last_arm: Option<(f64, u64)>,
}

impl<'a> Exciter<'a> {
    fn new(
        cfg: &Config,
        excitation: Option<&'a mut Excitation>,
        check_voltage: f64,
        quiet: bool,
        t0_ns: u64,
    ) -> Self {
        let check = SignCheck::new(cfg, check_voltage);
        if !quiet {
            crate::say!(
                "rip-rt: sign check: +{v} V then -{v} V for {} s each, then 0 V",
                crate::sign_check::PULSE_S,
                v = check.voltage(),
            );
        }
        Exciter {
            excitation,
            check,
            sign_report: None,
            stage: Stage::SignCheck { start_ns: t0_ns },
            arm_limit: cfg.safety.arm_limit,
            quiet,
            t0_ns,
            excited_ns: 0,
            max_arm: 0.0,
            last_arm: None,
        }
    }

    /// What to apply this period, and the log's phase name; `None` once the signal is done.
    fn voltage(
        &mut self,
        core: &LoopCore,
        tick: &Tick,
        m: &crate::protocol::Measurement,
    ) -> Result<Option<(f64, &'static str)>, StopReason> {
        let (theta, alpha) = core.angles(m);
        // The arm rate over the time since the last measurement (periods without one between).
        let rate = match self.last_arm.replace((theta, tick.deadline_ns)) {
            Some((before, at)) if tick.deadline_ns > at => {
                (theta - before) / ((tick.deadline_ns - at) as f64 * 1e-9)
            }
            _ => 0.0,
        };
        if let Stage::SignCheck { start_ns } = self.stage {
            self.check.push(theta, alpha);
            let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
            if let Some(v) = self.check.command(t) {
                return Ok(Some((v, phase::SIGN_CHECK)));
            }
            let report = self.check.verdict().map_err(StopReason::SignCheck)?;
            if !self.quiet {
                crate::say!("rip-rt: sign check {report}");
            }
            self.sign_report = Some(report);
            let Some(excitation) = self.excitation.as_deref() else {
                return Ok(None);
            };
            if !self.quiet {
                crate::say!(
                    "rip-rt: {} for {} s",
                    excitation.settings().signal,
                    excitation.settings().duration
                );
            }
            self.stage = Stage::Excite {
                start_ns: tick.deadline_ns,
            };
        }
        let Stage::Excite { start_ns } = self.stage else {
            unreachable!("the sign check ends above")
        };
        let Some(excitation) = self.excitation.as_deref_mut() else {
            unreachable!("without an excitation the run ends with the sign check")
        };
        let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
        self.excited_ns = tick.deadline_ns - start_ns;
        let name = match (excitation.stage(t), excitation.settings().signal) {
            (SignalStage::Done, _) => return Ok(None),
            (SignalStage::Coast, _) => phase::COAST,
            (SignalStage::Signal, Signal::FreeSwing) => phase::KICK,
            (SignalStage::Signal, signal) => signal.name(),
        };
        let e = excitation.value(t);
        Ok(Some((
            excitation.command(e, theta, rate, self.arm_limit),
            name,
        )))
    }
}

impl Law for Exciter<'_> {
    fn driving(&self) -> bool {
        true
    }

    fn command(
        &mut self,
        core: &mut LoopCore,
        tx: &mut [u8; MAX_FRAME],
        tick: &Tick,
        reply: &Reply,
    ) -> Result<Act, StopReason> {
        let t = (tick.deadline_ns - self.t0_ns) as f64 * 1e-9;
        let Some((voltage, phase)) = self.voltage(core, tick, &reply.m)? else {
            return Ok(Act::Done);
        };
        let mut step = core.drive(&reply.m, voltage, t, tx)?;
        self.max_arm = self.max_arm.max(step.theta.abs());
        // Continuous through hanging (π) rather than wrapped there: [0, 2π), 0 still upright.
        if step.alpha < 0.0 {
            step.alpha += std::f64::consts::TAU;
        }
        Ok(Act::Drive(Logged {
            t,
            step,
            phase,
            with_estimate: false,
        }))
    }

    fn missed(
        &mut self,
        _core: &mut LoopCore,
        tick: &Tick,
        last: Option<&Logged>,
    ) -> Option<Logged> {
        last.map(|prev| Logged {
            t: (tick.deadline_ns - self.t0_ns) as f64 * 1e-9,
            ..*prev
        })
    }
}

/// Runs an excitation experiment on `io` (module docs) until the signal is complete or a stop
/// reason arises. Always ends with the stop frame. Stop requests come from
/// [`crate::stop::install_signal_handlers`].
pub fn run(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    excitation: &mut Excitation,
    opts: &ExciteOptions,
    log: Option<&mut LogWriter>,
) -> ExciteReport {
    let guard = StopGuard::new(io.raw());
    let clock = Periodic::starting(cfg.period_ns(), opts.clock);
    io.flush_input();
    let mut driver = Period::new(io, core, cfg, clock, log, opts.quiet);
    let mut exciter = None;
    let (reason, calibration) =
        match check_rest(io, driver.core, cfg, &mut driver.clock, opts.quiet) {
            Err(reason) => (reason, None),
            Ok(cal) => {
                driver.core.calibrate(&cal);
                let t0_ns = driver.clock.next_deadline_ns();
                let law = exciter.insert(Exciter::new(
                    cfg,
                    Some(excitation),
                    opts.check_voltage,
                    opts.quiet,
                    t0_ns,
                ));
                (driver.run(law), Some(cal.to_string()))
            }
        };
    let wiring_checked = exciter.as_ref().is_some_and(|e| e.sign_report.is_some());
    let (reason, _) = driver.bring_to_rest(cfg, reason, wiring_checked);
    let stop_sent = guard.stop();
    drop(guard);
    let (sign_check, excited_s, max_arm) = match exciter {
        Some(x) => (x.sign_report, x.excited_ns as f64 * 1e-9, x.max_arm),
        None => (None, 0.0, 0.0),
    };
    ExciteReport {
        reason,
        stop_sent,
        timing: TimingSummary::from_histograms(
            &driver.jitter,
            &driver.compute,
            driver.clock.missed(),
        ),
        parser: driver.core.parser_stats(),
        missing_replies: driver.missing_total,
        calibration,
        sign_check,
        excited_s,
        max_arm,
    }
}

/// What [`check_signs`] leaves for its caller.
#[derive(Debug)]
pub struct SignCheckRun {
    /// The verdict, or why the check stopped (a [`StopReason::SignCheck`] for a wiring fault).
    pub result: Result<SignReport, StopReason>,
    /// The check's first deadline: the log's time zero.
    pub start_ns: u64,
}

/// The sign check alone on `driver`'s clock, with the driver's per-period rules and
/// `phase::SIGN_CHECK` rows in its log, as `rip-rt run --swing-up` runs it between the
/// calibration and the swing: a rig whose motor or encoders are reversed is refused before
/// anything drives it further than the pulse. The last command sent is the check's 0 V; the
/// caller keeps the driver and owns the stop path.
pub fn check_signs(driver: &mut Period<'_>, cfg: &Config, check_voltage: f64) -> SignCheckRun {
    let start_ns = driver.clock.next_deadline_ns();
    let mut checker = Exciter::new(cfg, None, check_voltage, driver.quiet(), start_ns);
    let reason = driver.run(&mut checker);
    let result = match (reason, checker.sign_report) {
        (StopReason::Finished, Some(report)) => Ok(report),
        (reason, _) => Err(reason),
    };
    SignCheckRun { result, start_ns }
}

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
use crate::config::{Config, MAX_BLIND_MS};
use crate::log::{LogWriter, Row};
use crate::loop_core::{LoopCore, StepOutput, FLAG_DEADLINE_MISS, FLAG_NO_REPLY};
use crate::protocol::{Measurement, ParserStats, MAX_FRAME};
use crate::runner::{exchange, Reply};
use crate::serial::Fd;
use crate::sign_check::{SignCheck, SignReport};
use crate::stop::{requested_stop, Overrun, StopGuard, StopReason};
use crate::timing::{now_ns, Histogram, Periodic, Tick, TimingSummary};

/// Options of one excitation run besides the configuration and the signal.
#[derive(Debug, Clone)]
pub struct ExciteOptions {
    /// Sign-check pulse voltage (V), capped at `safety.voltage_limit`.
    pub check_voltage: f64,
    /// Suppress progress messages on stderr.
    pub quiet: bool,
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

struct Exciter<'a> {
    io: &'a Fd,
    core: &'a mut LoopCore,
    log: Option<&'a mut LogWriter>,
    // None: the sign check alone (`rip-rt run --swing-up`), done once it has passed.
    excitation: Option<&'a mut Excitation>,
    check: SignCheck,
    sign_report: Option<SignReport>,
    arm_limit: f64,
    quiet: bool,
    period_ns: u64,
    reply_timeout_ns: u64,
    watchdog: u32,
    max_step_ns: u64,
    max_misses: u32,
    jitter: Histogram,
    compute: Histogram,
    tx: [u8; MAX_FRAME],
    rx: [u8; 512],
    missing_in_row: u32,
    missing_total: u64,
    misses_in_row: u32,
    last_step: Option<(StepOutput, &'static str)>,
    based_on_ns: u64,
    // The log's time zero: the first deadline of the sign check.
    t0_ns: u64,
    excited_ns: u64,
    max_arm: f64,
    // The last measured arm angle and its period's deadline, for the arm rate.
    last_arm: Option<(f64, u64)>,
}

impl<'a> Exciter<'a> {
    fn new(
        io: &'a Fd,
        core: &'a mut LoopCore,
        cfg: &Config,
        log: Option<&'a mut LogWriter>,
        excitation: Option<&'a mut Excitation>,
        opts: &ExciteOptions,
    ) -> Self {
        let period_ns = cfg.period_ns();
        Exciter {
            io,
            core,
            log,
            excitation,
            check: SignCheck::new(cfg, opts.check_voltage),
            sign_report: None,
            arm_limit: cfg.safety.arm_limit,
            quiet: opts.quiet,
            period_ns,
            reply_timeout_ns: (cfg.loop_.reply_timeout_ms * 1e6).round() as u64,
            watchdog: cfg.loop_.watchdog_periods,
            max_step_ns: (cfg.loop_.max_step_periods * period_ns as f64) as u64,
            max_misses: cfg.loop_.max_consecutive_misses,
            jitter: Histogram::new(),
            compute: Histogram::new(),
            tx: [0; MAX_FRAME],
            rx: [0; 512],
            missing_in_row: 0,
            missing_total: 0,
            misses_in_row: 0,
            last_step: None,
            based_on_ns: 0,
            t0_ns: 0,
            excited_ns: 0,
            max_arm: 0.0,
            last_arm: None,
        }
    }
}

impl Exciter<'_> {
    fn send(&self, n: usize) -> Result<(), StopReason> {
        self.io
            .write_all(&self.tx[..n])
            .map_err(StopReason::DeviceLost)
    }

    /// Sends the sample request and waits for its answer until the reply timeout.
    fn sample(&mut self, tick: &Tick) -> Result<(u16, Option<Reply>), StopReason> {
        exchange(
            self.io,
            self.core,
            &mut self.tx,
            &mut self.rx,
            self.reply_timeout_ns,
            tick.deadline_ns + self.period_ns,
        )
    }

    /// The stall rule of `rip-rt run`: no enabling command on a measurement requested
    /// [`MAX_BLIND_MS`] or more ago.
    fn check_fresh(&self, req_ns: u64) -> Result<(), StopReason> {
        let age_ns = now_ns().saturating_sub(req_ns);
        if age_ns as f64 >= MAX_BLIND_MS * 1e6 {
            return Err(StopReason::Overrun(Overrun::Stall {
                ms: age_ns as f64 * 1e-6,
            }));
        }
        Ok(())
    }

    fn log_row(&mut self, row: Row) -> Result<(), StopReason> {
        match self.log.as_deref_mut() {
            Some(log) => log.push(row).map_err(StopReason::LogError),
            None => Ok(()),
        }
    }

    fn check_period(&mut self, tick: &Tick) -> Result<(), StopReason> {
        if let Some(reason) = requested_stop() {
            return Err(reason);
        }
        if let Some(log) = self.log.as_deref() {
            log.check().map_err(StopReason::LogError)?;
        }
        let absent_ns = tick.skipped * self.period_ns + tick.lateness_ns;
        if absent_ns as f64 >= MAX_BLIND_MS * 1e6 {
            return Err(StopReason::Overrun(Overrun::Stall {
                ms: absent_ns as f64 * 1e-6,
            }));
        }
        Ok(())
    }

    fn no_reply(&mut self, tick: &Tick, seq: u16) -> Result<(), StopReason> {
        self.missing_in_row += 1;
        self.missing_total += 1;
        if self.missing_in_row >= self.watchdog {
            return Err(StopReason::Watchdog(self.missing_in_row));
        }
        let n = self.core.encode_held(&mut self.tx)?;
        if self.core.held_voltage() != 0.0 {
            self.check_fresh(self.based_on_ns)?;
        }
        self.send(n)?;
        if let Some((prev, phase)) = self.last_step {
            let step = StepOutput {
                flags: FLAG_NO_REPLY,
                ..prev
            };
            self.log_row(Row {
                t: (tick.deadline_ns - self.t0_ns) as f64 * 1e-9,
                seq,
                step,
                estimate: None,
                compute_us: 0.0,
                jitter_us: tick.lateness_ns as f64 / 1e3,
                phase,
            })?;
        }
        Ok(())
    }

    /// What to apply this period, and the log's phase name; `None` once the signal is done.
    fn voltage(
        &mut self,
        tick: &Tick,
        stage: &mut Stage,
        m: &Measurement,
    ) -> Result<Option<(f64, &'static str)>, StopReason> {
        let (theta, alpha) = self.core.angles(m);
        // The arm rate over the time since the last measurement (periods without one between).
        let rate = match self.last_arm.replace((theta, tick.deadline_ns)) {
            Some((before, at)) if tick.deadline_ns > at => {
                (theta - before) / ((tick.deadline_ns - at) as f64 * 1e-9)
            }
            _ => 0.0,
        };
        if let Stage::SignCheck { start_ns } = *stage {
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
            *stage = Stage::Excite {
                start_ns: tick.deadline_ns,
            };
        }
        let Stage::Excite { start_ns } = *stage else {
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

    fn period(&mut self, tick: &Tick, stage: &mut Stage) -> Result<(), StopReason> {
        self.check_period(tick)?;
        self.jitter.record(tick.lateness_ns);
        let (seq, reply) = self.sample(tick)?;
        let Some(reply) = reply else {
            return self.no_reply(tick, seq);
        };
        self.missing_in_row = 0;
        let t = (tick.deadline_ns - self.t0_ns) as f64 * 1e-9;
        let Some((voltage, phase)) = self.voltage(tick, stage, &reply.m)? else {
            return Err(StopReason::Finished);
        };
        let mut step = self.core.drive(&reply.m, voltage, t, &mut self.tx)?;
        let compute_ns = now_ns().saturating_sub(reply.rx_ns);
        if compute_ns > self.max_step_ns {
            return Err(StopReason::Overrun(Overrun::Step {
                took_ms: compute_ns as f64 * 1e-6,
                limit_ms: self.max_step_ns as f64 * 1e-6,
            }));
        }
        self.check_fresh(reply.req_ns)?;
        self.based_on_ns = reply.req_ns;
        self.send(step.len)?;
        self.compute.record(compute_ns);
        self.max_arm = self.max_arm.max(step.theta.abs());
        // Continuous through hanging (π) rather than wrapped there: [0, 2π), 0 still upright.
        if step.alpha < 0.0 {
            step.alpha += std::f64::consts::TAU;
        }
        if tick.skipped > 0 {
            step.flags |= FLAG_DEADLINE_MISS;
        }
        self.last_step = Some((step, phase));
        self.log_row(Row {
            t,
            seq,
            step,
            estimate: None,
            compute_us: compute_ns as f64 / 1e3,
            jitter_us: tick.lateness_ns as f64 / 1e3,
            phase,
        })?;
        self.count_overrun(tick)
    }

    /// The consecutive-miss rule of `rip-rt run`.
    fn count_overrun(&mut self, tick: &Tick) -> Result<(), StopReason> {
        let woke_ns = tick.deadline_ns + tick.lateness_ns;
        if now_ns().saturating_sub(woke_ns) > self.period_ns {
            self.misses_in_row += 1;
            if self.misses_in_row >= self.max_misses {
                return Err(StopReason::Overrun(Overrun::Misses(self.misses_in_row)));
            }
        } else {
            self.misses_in_row = 0;
        }
        Ok(())
    }

    fn periods(&mut self, periodic: &mut Periodic) -> StopReason {
        self.t0_ns = periodic.next_deadline_ns();
        let mut stage = Stage::SignCheck {
            start_ns: self.t0_ns,
        };
        if !self.quiet {
            crate::say!(
                "rip-rt: sign check: +{v} V then -{v} V for {} s each, then 0 V",
                crate::sign_check::PULSE_S,
                v = self.check.voltage(),
            );
        }
        loop {
            let tick = periodic.wait();
            if let Err(reason) = self.period(&tick, &mut stage) {
                return reason;
            }
        }
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
    let period_ns = cfg.period_ns();
    let mut periodic = Periodic::new(period_ns, now_ns() + period_ns);
    io.flush_input();
    let mut exciter = Exciter::new(io, core, cfg, log, Some(excitation), opts);
    let (reason, calibration) = match check_rest(io, exciter.core, cfg, &mut periodic, opts.quiet) {
        Err(reason) => (reason, None),
        Ok(cal) => {
            exciter.core.calibrate(&cal);
            (exciter.periods(&mut periodic), Some(cal.to_string()))
        }
    };
    let driven = exciter.last_step.is_some();
    let braking =
        crate::envelope::bring_to_rest(io, exciter.core, cfg, &mut periodic, &reason, driven);
    if !opts.quiet && braking.mode != crate::envelope::BrakeMode::None {
        crate::say!("rip-rt: stop: {braking}");
    }
    let stop_sent = guard.stop();
    drop(guard);
    ExciteReport {
        reason,
        stop_sent,
        timing: TimingSummary::from_histograms(
            &exciter.jitter,
            &exciter.compute,
            periodic.missed(),
        ),
        parser: exciter.core.parser_stats(),
        missing_replies: exciter.missing_total,
        calibration,
        sign_check: exciter.sign_report,
        excited_s: exciter.excited_ns as f64 * 1e-9,
        max_arm: exciter.max_arm,
    }
}

/// What [`check_signs`] leaves for its caller.
#[derive(Debug)]
pub struct SignCheckRun {
    /// The verdict, or why the check stopped (a [`StopReason::SignCheck`] for a wiring fault).
    pub result: Result<SignReport, StopReason>,
    /// The check's first deadline: the log's time zero.
    pub start_ns: u64,
    /// Periods without a valid measurement.
    pub missing_replies: u64,
}

/// The sign check alone on `periodic`'s grid, with this module's per-period rules and
/// `phase::SIGN_CHECK` rows in `log`, as `rip-rt run --swing-up` runs it between the
/// calibration and the swing: a rig whose motor or encoders are reversed is refused before
/// anything drives it further than the pulse. The last command sent is the check's 0 V; the
/// caller keeps the grid and owns the stop frame.
pub fn check_signs(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    periodic: &mut Periodic,
    opts: &ExciteOptions,
    log: Option<&mut LogWriter>,
) -> SignCheckRun {
    let mut checker = Exciter::new(io, core, cfg, log, None, opts);
    let reason = checker.periods(periodic);
    let result = match (reason, checker.sign_report) {
        (StopReason::Finished, Some(report)) => Ok(report),
        (reason, _) => Err(reason),
    };
    SignCheckRun {
        result,
        start_ns: checker.t0_ns,
        missing_replies: checker.missing_total,
    }
}

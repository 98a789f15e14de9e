//! The period driver: the one implementation of what every period of `rip-rt run` and
//! `rip-rt excite` does around its command law, so that a safety rule is written once.
//!
//! Every period, on the run's one clock ([`Periodic`], real time or lockstep):
//!
//! 1. **top of the period**: a stop request (signals), a failed log writer, and, while the
//!    law drives the motor, a loop that did not run for [`MAX_BLIND_MS`] (suspended,
//!    starved: [`Overrun::Stall`]) stop the run; then the law's own bounds ([`Law::check`]:
//!    a duration, a swing-up's time);
//! 2. **exchange**: the sample request and its measurement, waited for up to
//!    `loop.reply_timeout_ms` and never past the next deadline ([`exchange`]);
//! 3. **no measurement**: the previous command again, counted against
//!    `loop.watchdog_periods` ([`StopReason::Watchdog`]) and refused when it would drive on a
//!    measurement requested [`MAX_BLIND_MS`] ago; the law is told the period passed
//!    ([`Law::missed`]);
//! 4. **a measurement**: the law's command ([`Law::command`]): the stop command, or an
//!    enabling command that the driver sends only if its computation took at most
//!    `loop.max_step_periods` ([`Overrun::Step`]) and its measurement is fresh; then the log
//!    row, and `loop.max_consecutive_misses` periods in a row whose own work took longer than
//!    a period stop the run ([`Overrun::Misses`]).
//!
//! The stop path (the active stop of [`crate::envelope`], then the stop frame of
//! [`crate::stop::StopGuard`]) is the caller's, on the same clock ([`Period::clock`]).

pub use crate::exchange::{exchange, Reply};

use crate::config::{Config, MAX_BLIND_MS};
use crate::live::{Bounds, Kind, Live};
use crate::log::{LogWriter, Row};
use crate::loop_core::{LoopCore, StepOutput, FLAG_DEADLINE_MISS, FLAG_NO_REPLY};
use crate::protocol::MAX_FRAME;
use crate::serial::Fd;
use crate::stop::{requested_stop, Overrun, StopReason};
use crate::timing::{ClockMode, Histogram, Periodic, Tick};

/// A row of the log that the law fills in: its time axis, phase name and estimate.
#[derive(Debug, Clone, Copy)]
pub struct Logged {
    /// Seconds on the law's time axis.
    pub t: f64,
    /// The step to log.
    pub step: StepOutput,
    /// The log's `phase`.
    pub phase: &'static str,
    /// Log the controller's state estimate (after [`Law::sent`]).
    pub with_estimate: bool,
}

/// What the law does with a period's measurement.
#[derive(Debug, Clone, Copy)]
pub enum Act {
    /// The stop command (the motor disabled): nothing is logged.
    Stop,
    /// An enabling command, already encoded into the driver's transmit buffer by
    /// [`LoopCore::control`] or [`LoopCore::drive`]; the driver checks and sends it.
    Drive(Logged),
    /// The law is done: the run ends with [`StopReason::Finished`].
    Done,
}

/// What differs between the commands that drive the motor: the command law and its own bounds.
pub trait Law {
    /// Whether the law drives the motor in this period (the stall rule applies, and a held
    /// command is an enabling one).
    fn driving(&self) -> bool;

    /// The law's own bounds at the top of a period (after the driver's rules).
    fn check(&mut self, _core: &LoopCore, _tick: &Tick) -> Result<(), StopReason> {
        Ok(())
    }

    /// The command for a period with a measurement; an enabling command is encoded into `tx`.
    fn command(
        &mut self,
        core: &mut LoopCore,
        tx: &mut [u8; MAX_FRAME],
        tick: &Tick,
        reply: &Reply,
    ) -> Result<Act, StopReason>;

    /// After an enabling command was sent.
    fn sent(&mut self, _core: &mut LoopCore, _tick: &Tick, _logged: &Logged) {}

    /// A period without a measurement (the previous command was held); `last` is the last
    /// logged row. Returns the row to log, if any.
    fn missed(&mut self, core: &mut LoopCore, tick: &Tick, last: Option<&Logged>)
        -> Option<Logged>;
}

/// The driver of one run's periods (module docs): the device, the controller core, the log,
/// the clock and the counters every safety rule needs.
pub struct Period<'a> {
    /// The device.
    pub io: &'a Fd,
    /// The loop's logic.
    pub core: &'a mut LoopCore,
    /// The run's one clock.
    pub clock: Periodic,
    log: Option<&'a mut LogWriter>,
    // The live stream (`loop.live_port`): published beside the log row, never waited for.
    live: Option<Live>,
    quiet: bool,
    period_ns: u64,
    reply_timeout_ns: u64,
    watchdog: u32,
    max_step_ns: u64,
    max_misses: u32,
    /// Wake-up lateness of every period.
    pub jitter: Histogram,
    /// Measurement-to-command time of every enabling command.
    pub compute: Histogram,
    tx: [u8; MAX_FRAME],
    rx: [u8; 512],
    missing_in_row: u32,
    /// Periods without a valid measurement.
    pub missing_total: u64,
    misses_in_row: u32,
    last: Option<Logged>,
    // When the request was sent whose measurement the last enabling command rests on.
    based_on_ns: u64,
}

impl<'a> Period<'a> {
    /// A driver on `clock` with the rules of `cfg`'s `[loop]`.
    pub fn new(
        io: &'a Fd,
        core: &'a mut LoopCore,
        cfg: &Config,
        clock: Periodic,
        log: Option<&'a mut LogWriter>,
        quiet: bool,
    ) -> Self {
        let period_ns = cfg.period_ns();
        Period {
            io,
            core,
            clock,
            log,
            live: Live::for_port(cfg.loop_.live_port, Bounds::of(cfg)),
            quiet,
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
            last: None,
            based_on_ns: 0,
        }
    }

    /// Whether progress messages are suppressed.
    pub fn quiet(&self) -> bool {
        self.quiet
    }

    /// Whether any enabling command was sent.
    pub fn driven(&self) -> bool {
        self.last.is_some()
    }

    /// Brings the arm to rest after the run stopped for `reason`
    /// ([`crate::braking::bring_to_rest`], driven or not as this run was), on this run's
    /// clock, and says how unless quiet (what it does and how long it may take as it begins,
    /// [`crate::braking::stop_announcement`]; after a signal whatever quiet); the caller then
    /// sends the stop frame.
    /// `wiring_checked`: the run has no sign check or its sign check passed. Returns the run's
    /// stop reason: `reason`, or [`StopReason::SignalAgain`] when a second signal cut a
    /// signal's stop short ([`crate::stop::cut_short`]).
    pub fn bring_to_rest(
        &mut self,
        cfg: &Config,
        reason: StopReason,
        wiring_checked: bool,
    ) -> (StopReason, crate::envelope::BrakeReport) {
        let driven = self.driven();
        let mode = crate::envelope::stop_mode(&reason, driven, wiring_checked);
        // After a signal whatever --quiet: the line answers the operator's own Ctrl-C, and the
        // stop that follows is silent for seconds.
        if mode != crate::envelope::BrakeMode::None
            && (!self.quiet || matches!(reason, StopReason::Signal(_)))
        {
            let lowering = crate::braking::lowering_for(self.core, &reason, mode);
            crate::say!("{}", crate::braking::stop_announcement(&reason, lowering));
        }
        let braking = crate::braking::bring_to_rest(
            self.io,
            self.core,
            cfg,
            &mut self.clock,
            &reason,
            driven,
            wiring_checked,
        );
        // A stop cut short is said whatever --quiet, as its start was.
        if braking.cut_short.is_some()
            || (!self.quiet && braking.mode != crate::envelope::BrakeMode::None)
        {
            crate::say!("rip-rt: stop: {braking}");
        }
        // The rig did not move as commanded while it was lowered: said whatever ended the
        // stop, and the run ends as the witness's stop (exit 15) unless a signal cut it short.
        if let Some(fault) = braking.witness {
            crate::say!("rip-rt: stop: the lowering was given up: {fault}");
        }
        let reason = match (braking.cut_short, braking.witness) {
            (Some(sig), _) => crate::stop::cut_short(reason, sig),
            (None, Some(fault)) => StopReason::Witness(fault),
            (None, None) => reason,
        };
        if let Some(live) = self.live.as_mut() {
            let t = self.last.map_or(f64::NAN, |l| l.t);
            live.stop(t, reason.exit_code(), reason.name());
        }
        (reason, braking)
    }

    /// The log, for the caller's own rows.
    pub fn log(&mut self) -> Option<&mut LogWriter> {
        self.log.as_deref_mut()
    }

    /// Runs `law`'s periods until a stop reason arises ([`StopReason::Finished`] when the law
    /// is done).
    pub fn run<L: Law>(&mut self, law: &mut L) -> StopReason {
        loop {
            let tick = self.clock.wait();
            if let Err(reason) = self.period(law, &tick) {
                return reason;
            }
        }
    }

    fn period<L: Law>(&mut self, law: &mut L, tick: &Tick) -> Result<(), StopReason> {
        self.check_period(tick, law.driving())?;
        law.check(self.core, tick)?;
        self.jitter.record(tick.lateness_ns);
        let (seq, reply) = exchange(
            self.io,
            self.core,
            &self.clock,
            &mut self.tx,
            &mut self.rx,
            self.reply_timeout_ns,
        )?;
        let Some(reply) = reply else {
            return self.no_reply(law, tick, seq);
        };
        self.missing_in_row = 0;
        self.core.note_period(
            tick.lateness_ns,
            tick.skipped,
            self.clock.mode() == ClockMode::Lockstep,
            reply.req_ns,
        );
        match law.command(self.core, &mut self.tx, tick, &reply)? {
            Act::Done => Err(StopReason::Finished),
            Act::Stop => {
                let n = self.core.encode_stop(&mut self.tx);
                self.send(n)
            }
            Act::Drive(mut logged) => {
                let compute_ns = self.clock.now_ns().saturating_sub(reply.rx_ns);
                if compute_ns > self.max_step_ns {
                    return Err(StopReason::Overrun(Overrun::Step {
                        took_ms: compute_ns as f64 * 1e-6,
                        limit_ms: self.max_step_ns as f64 * 1e-6,
                    }));
                }
                self.check_fresh(reply.req_ns)?;
                self.based_on_ns = reply.req_ns;
                self.send(logged.step.len)?;
                self.core
                    .note_sent(self.clock.now_ns().saturating_sub(reply.req_ns));
                self.compute.record(compute_ns);
                if tick.skipped > 0 {
                    logged.step.flags |= FLAG_DEADLINE_MISS;
                }
                self.last = Some(logged);
                law.sent(self.core, tick, &logged);
                self.log_row(seq, &logged, compute_ns, tick)?;
                self.count_overrun(tick)
            }
        }
    }

    fn send(&self, n: usize) -> Result<(), StopReason> {
        self.io
            .write_all(&self.tx[..n])
            .map_err(StopReason::DeviceLost)
    }

    /// Refuses an enabling command resting on a measurement requested at `req_ns` when that
    /// is [`MAX_BLIND_MS`] or more ago. The period-counting bounds cannot see a loop that was
    /// suspended (or starved) inside a period, between the request and the command: without
    /// this, its first act on resuming is to drive on a measurement as old as the suspension.
    fn check_fresh(&self, req_ns: u64) -> Result<(), StopReason> {
        let age_ns = self.clock.now_ns().saturating_sub(req_ns);
        if age_ns as f64 >= MAX_BLIND_MS * 1e6 {
            return Err(StopReason::Overrun(Overrun::Stall {
                ms: age_ns as f64 * 1e-6,
            }));
        }
        Ok(())
    }

    fn log_row(
        &mut self,
        seq: u16,
        logged: &Logged,
        compute_ns: u64,
        tick: &Tick,
    ) -> Result<(), StopReason> {
        let estimate = if logged.with_estimate {
            self.core.state_estimate()
        } else {
            None
        };
        if let Some(live) = self.live.as_mut() {
            let mut f = live
                .frame(Kind::Period)
                .with_phase(logged.phase)
                .with_estimate(estimate);
            f.t = logged.t;
            f.seq = u32::from(seq);
            f.theta = logged.step.theta;
            f.alpha = logged.step.alpha;
            f.theta_ref = logged.step.reference;
            f.u_planned = if logged.step.flags & FLAG_NO_REPLY != 0 {
                logged.step.voltage
            } else {
                self.core.planned_voltage()
            };
            f.u_written = logged.step.voltage;
            f.status = logged.step.flags;
            f.compute_us = compute_ns as f64 / 1e3;
            f.jitter_us = tick.lateness_ns as f64 / 1e3;
            live.send(f);
        }
        let Some(log) = self.log.as_deref_mut() else {
            return Ok(());
        };
        let estimate = Row::estimate_from(estimate);
        log.push(Row {
            t: logged.t,
            seq,
            step: logged.step,
            estimate,
            compute_us: compute_ns as f64 / 1e3,
            jitter_us: tick.lateness_ns as f64 / 1e3,
            phase: logged.phase,
        })
        .map_err(StopReason::LogError)
    }

    /// Checks that apply at the top of every period.
    fn check_period(&mut self, tick: &Tick, driving: bool) -> Result<(), StopReason> {
        if let Some(reason) = requested_stop() {
            return Err(reason);
        }
        if let Some(log) = self.log.as_deref() {
            log.check().map_err(StopReason::LogError)?;
        }
        if !driving {
            return Ok(());
        }
        // A loop that did not run (suspended with SIGSTOP, starved of the CPU) has driven
        // blind all that time; past the hard bound its controller state is too stale to go on.
        // Deadlines skipped before the wait, and lateness after it: a stop during the sleep
        // shows as the latter.
        let absent_ns = tick.skipped * self.period_ns + tick.lateness_ns;
        if absent_ns as f64 >= MAX_BLIND_MS * 1e6 {
            return Err(StopReason::Overrun(Overrun::Stall {
                ms: absent_ns as f64 * 1e-6,
            }));
        }
        Ok(())
    }

    /// A period without a measurement: the previous command again (within the staleness
    /// bounds), and the law told that the period passed with it.
    fn no_reply<L: Law>(&mut self, law: &mut L, tick: &Tick, seq: u16) -> Result<(), StopReason> {
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
        if let Some(mut logged) = law.missed(self.core, tick, self.last.as_ref()) {
            logged.step.flags = FLAG_NO_REPLY;
            logged.with_estimate = false;
            self.log_row(seq, &logged, 0, tick)?;
        }
        Ok(())
    }

    /// Counts periods whose own work (wake-up to command sent) took longer than a period.
    /// A late wake-up alone is the scheduler's doing, not the controller's, and is left to the
    /// stall rule.
    fn count_overrun(&mut self, tick: &Tick) -> Result<(), StopReason> {
        let woke_ns = tick.deadline_ns + tick.lateness_ns;
        if self.clock.now_ns().saturating_sub(woke_ns) > self.period_ns {
            self.misses_in_row += 1;
            if self.misses_in_row >= self.max_misses {
                return Err(StopReason::Overrun(Overrun::Misses(self.misses_in_row)));
            }
        } else {
            self.misses_in_row = 0;
        }
        Ok(())
    }
}

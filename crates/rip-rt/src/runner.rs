//! The control loop: every period it requests a sample, waits for the measurement, steps the
//! controller and writes the voltage, on a grid of absolute deadlines, with the safety rules of
//! `docs/rip-rt.md`.
//!
//! A run goes through phases, each deciding what a period does with its measurement:
//!
//! 1. **probe** (before the first period): the controller is timed on synthetic measurements,
//!    motor disabled; a design whose median step does not fit the period is refused
//!    ([`StopReason::TooSlow`]);
//! 2. **arming**: stop commands only, until the pendulum is within `safety.start_tolerance` of
//!    upright (or `safety.wait_upright_s` passed: [`StopReason::NotUpright`]);
//! 3. **balancing**: the controller's enabling commands, until the duration, a stop signal or a
//!    fault; the witness ([`crate::witness`], in [`LoopCore::control`]) stops a rig that does
//!    not move as commanded ([`StopReason::Witness`]).
//!
//! A swing-up supervisor (the controller starts in [`rip_core::Phase::SwingUp`]) replaces
//! arming by the rest check ([`crate::calibrate`]): the rig must be at rest hanging down, and
//! its encoder zeros are taken from that rest; then the sign check of `rip-rt excite`
//! ([`crate::excite::check_signs`]: a small pulse, then 0 V) refuses a rig with a reversed
//! motor or encoder ([`StopReason::SignCheck`]), which the swing would drive away to the arm
//! limit; then the rest check again ([`calibrate::settle`]: the swing never starts from the
//! pulse's aftermath) and the encoder zeros from that rest; then its commands run from the
//! next period, the swing-up's and, after its catch, the
//! balance controller's, on a time axis that starts with the sign check. Each catch starts the
//! reference's clock and `--duration` (a fall stops them); the pendulum-angle rule is the
//! supervisor's ([`LoopCore::control`]), every other rule of balancing holds throughout. The
//! whole run is bounded however often it falls and swings up again: after a fall the
//! swing-ups together may take `swing_up.max_time`, and with `--duration` the run ends
//! `swing_up.max_time + --duration` after the swing's start at the latest (both exit 13).
//!
//! Every way out of [`run`] ends with the stop frame (see [`crate::stop`]). Rules that hold in
//! every period of balancing: no enabling command from a measurement older than
//! `loop.max_step_periods` (compute overrun) and no repeated enabling command more than
//! `loop.watchdog_periods` (and never more than [`MAX_BLIND_MS`]) after the last measurement;
//! `loop.max_consecutive_misses` periods in a row longer than a period, or a loop that did not run for
//! [`MAX_BLIND_MS`] (suspended, starved), stop it.

use crate::calibrate::{self, Calibration};
use crate::config::{Config, MAX_BLIND_MS};
use crate::excite::{self, ExciteOptions};
use crate::log::{LogWriter, Row};
use crate::loop_core::{LoopCore, StepOutput, FLAG_DEADLINE_MISS, FLAG_NO_REPLY};
use crate::protocol::{Measurement, ParserStats, MAX_FRAME};
use crate::serial::{Fd, Readiness};
use crate::sign_check::{SignReport, PULSE_VOLTAGE};
use crate::stop::{requested_stop, Overrun, StopGuard, StopReason};
use crate::timing::{now_ns, Histogram, Periodic, Tick, TimingSummary};

/// Options of one run besides the configuration.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stop after this many seconds of balancing.
    pub duration_s: Option<f64>,
    /// Suppress progress messages on stderr.
    pub quiet: bool,
}

/// The outcome of [`run`].
#[derive(Debug)]
pub struct RunReport {
    /// Why the loop stopped.
    pub reason: StopReason,
    /// Whether the final stop frame was written to the device.
    pub stop_sent: bool,
    /// Timing figures.
    pub timing: TimingSummary,
    /// The controller timed before enabling (absent when the run stopped before the probe).
    pub probe: Option<Probe>,
    /// Parser counters.
    pub parser: ParserStats,
    /// Periods without a valid measurement.
    pub missing_replies: u64,
    /// Seconds of balancing (for a swing-up: since the latest catch).
    pub balanced_s: f64,
    /// The encoder zeros of a run that started hanging (the rest check passed).
    pub calibration: Option<Calibration>,
    /// The sign check before a swing-up (absent when it did not run or did not pass).
    pub sign_check: Option<SignReport>,
    /// Seconds from the start of a swing-up (its sign check, the log's time zero) to its
    /// first catch.
    pub catch_s: Option<f64>,
    /// Catches (more than one after falls with `swing_up.on_fall = "retry"`).
    pub catches: u32,
    /// The witness's largest statistics ([`crate::witness::Witness::peak`]), if it ran.
    pub witness_peak: Option<[f64; 3]>,
}

/// Controller steps timed before enabling the motor ([`probe`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Probe {
    /// Steps timed (after a warm-up step, which is timed only when nothing else could be).
    pub steps: usize,
    /// Of which swing-up steps (a swing-up supervisor; 0 otherwise).
    pub swing_steps: usize,
    /// Their median (µs); with swing-up steps, the larger of the swing-up steps' and the
    /// balance steps' medians.
    pub median_us: f64,
    /// The longest (µs).
    pub max_us: f64,
}

impl std::fmt::Display for Probe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "steps={}", self.steps)?;
        if self.swing_steps > 0 {
            write!(f, " ({} swing-up)", self.swing_steps)?;
        }
        write!(
            f,
            " step_us(median/max)={:.1}/{:.1}",
            self.median_us, self.max_us
        )
    }
}

/// Steps the probe times at most (swing-up steps not counted).
pub const PROBE_STEPS: usize = 20;
/// Swing-up steps the probe times at most, before its balance steps.
pub const PROBE_SWING_STEPS: usize = 10;
/// The probe stops timing once it has spent this long (ns), so that a hopeless design is
/// refused in about a second.
pub const PROBE_TIME_NS: u64 = 1_000_000_000;

/// Step times of one kind.
struct Timings {
    ns: [u64; PROBE_STEPS],
    n: usize,
}

impl Timings {
    fn new() -> Self {
        Self {
            ns: [0; PROBE_STEPS],
            n: 0,
        }
    }

    fn time(&mut self, core: &mut LoopCore, y: [f64; 2], r: [f64; 2]) {
        let t0 = now_ns();
        core.probe_step(y, r);
        self.ns[self.n] = now_ns() - t0;
        self.n += 1;
    }

    /// Median and maximum (ns), sorting the times.
    fn median_max(&mut self) -> Option<(u64, u64)> {
        let times = &mut self.ns[..self.n];
        times.sort_unstable();
        (self.n > 0).then(|| (times[self.n / 2], times[self.n - 1]))
    }
}

/// Times the controller of `core` on synthetic measurements before the motor is enabled, and
/// refuses ([`StopReason::TooSlow`]) when the median step does not fit the time a period
/// leaves after the reply timeout (`loop.period_ms − loop.reply_timeout_ms`). The inputs are
/// the hardest the run will ask of it at once: the pendulum wobbling inside the start
/// tolerance while the arm is a whole reference step away, which saturates the voltage (the
/// MPC's constraints become active).
///
/// A swing-up supervisor is timed first on swing-up steps (the pendulum hanging, where the
/// balance controller's estimator is restarted every sample, and swinging through the
/// estimator window short of the catch, where it runs on the measurements), then led into its
/// catch by a still pendulum near upright (untimed) and timed on balance steps as above, with
/// the reference stepping away after the catch. Both medians must fit. The controller is reset
/// afterwards.
pub fn probe(core: &mut LoopCore, cfg: &Config) -> Result<Probe, StopReason> {
    let result = probe_steps(core, cfg);
    core.reset();
    result
}

fn probe_steps(core: &mut LoopCore, cfg: &Config) -> Result<Probe, StopReason> {
    use std::f64::consts::PI;
    let budget_ns = cfg.period_ns() as f64 - cfg.loop_.reply_timeout_ms * 1e6;
    let supervised = core.supervises_swing_up();
    let wobble = if supervised {
        0.5 * cfg.spec.swing_up.catch_angle
    } else {
        0.5 * cfg.safety.start_tolerance
    };
    let target = [cfg.spec.reference.arm_step, 0.0];
    let mut swing = Timings::new();
    let mut balance = Timings::new();
    let start = now_ns();
    let within_time = || now_ns() - start < PROBE_TIME_NS;
    let stop = || requested_stop().map_or(Ok(()), Err);
    // The first step may set up workspaces: it counts only when it is all there is, i.e.
    // when it alone used up the probe's time.
    let first = if supervised { [0.0, PI] } else { [0.0, wobble] };
    core.probe_step(first, if supervised { [0.0; 2] } else { target });
    let warm_up_ns = now_ns() - start;
    if supervised {
        // Outside the estimator window (hanging) and inside it short of the catch region.
        let near = 0.5 * (cfg.spec.swing_up.catch_angle + cfg.spec.swing_up.estimator_window);
        while swing.n < PROBE_SWING_STEPS && within_time() {
            stop()?;
            let k = swing.n as f64;
            let alpha = if swing.n % 2 == 0 {
                PI - 0.5 * (0.7 * k).cos()
            } else {
                near * (0.9 * k).cos().signum()
            };
            swing.time(core, [0.2 * (0.5 * k).sin(), alpha], [0.0; 2]);
        }
        while core.phase() == rip_core::Phase::SwingUp && within_time() {
            stop()?;
            core.probe_step([0.0, wobble], [0.0; 2]);
        }
    }
    while balance.n < PROBE_STEPS && within_time() {
        stop()?;
        let alpha = wobble * ((balance.n as f64) * 0.7).sin();
        balance.time(core, [0.0, alpha], target);
    }
    let swing_steps = swing.n;
    let mut steps = swing.n + balance.n;
    let (mut median, mut max) = (0u64, 0u64);
    for t in [&mut swing, &mut balance] {
        if let Some((med, mx)) = t.median_max() {
            median = median.max(med);
            max = max.max(mx);
        }
    }
    if steps == 0 {
        (median, max, steps) = (warm_up_ns, warm_up_ns, 1);
    }
    let us = |ns: u64| ns as f64 * 1e-3;
    let probe = Probe {
        steps,
        swing_steps,
        median_us: us(median),
        max_us: us(max),
    };
    if median as f64 > budget_ns {
        return Err(StopReason::TooSlow {
            median_ms: probe.median_us * 1e-3,
            budget_ms: budget_ns * 1e-6,
            steps,
        });
    }
    Ok(probe)
}

/// What a phase does with a period's measurement.
#[derive(Debug, Clone, Copy)]
enum Phase {
    Arming {
        since_ns: u64,
        told: bool,
    },
    /// The controller's commands (balancing, or a swing-up supervisor's swing and balance),
    /// from `start_ns` on.
    Balancing {
        start_ns: u64,
    },
}

/// The state of one run: the device, the controller, the log and the counters.
struct Runner<'a> {
    io: &'a Fd,
    core: &'a mut LoopCore,
    log: Option<&'a mut LogWriter>,
    quiet: bool,
    period_ns: u64,
    reply_timeout_ns: u64,
    watchdog: u32,
    max_step_ns: u64,
    max_misses: u32,
    wait_upright_ns: u64,
    duration_ns: Option<u64>,
    jitter: Histogram,
    compute: Histogram,
    tx: [u8; MAX_FRAME],
    rx: [u8; 512],
    missing_in_row: u32,
    missing_total: u64,
    misses_in_row: u32,
    last_step: Option<StepOutput>,
    balanced_ns: u64,
    // When the experiment (the reference's clock, `--duration`) started: with balancing, or at
    // a swing-up's latest catch (none while it swings).
    experiment_ns: Option<u64>,
    // The controller's phase after the last step, and the swing-up's catches.
    last_phase: rip_core::Phase,
    catch_s: Option<f64>,
    catches: u32,
    // A swing-up's bounds over the whole run (H1: a catch/fall cycle must end): swing-up
    // periods since the start, counted against `swing_up.max_time` once it has fallen, and
    // `swing_up.max_time + --duration` for the whole run.
    falls: u32,
    swing_periods: u64,
    max_swing_s: f64,
    // When the request was sent whose measurement the last enabling command rests on.
    based_on_ns: u64,
}

/// A measurement, when its request was sent and when its bytes were read.
#[derive(Debug, Clone, Copy)]
pub struct Reply {
    /// The measurement.
    pub m: Measurement,
    /// When its sample request was sent (ns, `CLOCK_MONOTONIC`).
    pub req_ns: u64,
    /// When its bytes were read.
    pub rx_ns: u64,
}

/// Sends a sample request on `io` and waits for the measurement answering it, up to
/// `reply_timeout_ns` after the request and never past `cap_ns` (the next deadline, which
/// the next request must keep). `None` when none arrived in time; bytes that are not the
/// answer (stale replies, garbage) are consumed by `core`'s parser.
pub fn exchange(
    io: &Fd,
    core: &mut LoopCore,
    tx: &mut [u8; MAX_FRAME],
    rx: &mut [u8],
    reply_timeout_ns: u64,
    cap_ns: u64,
) -> Result<(u16, Option<Reply>), StopReason> {
    let (seq, n) = core.encode_request(tx);
    let req_ns = now_ns();
    io.write_all(&tx[..n]).map_err(StopReason::DeviceLost)?;
    // Counted from the request, so a late wake-up does not cost a measurement the device
    // answers at once.
    let deadline = (now_ns() + reply_timeout_ns).min(cap_ns);
    loop {
        let now = now_ns();
        if now >= deadline {
            return Ok((seq, None));
        }
        match io.wait_readable(deadline - now) {
            Ok(Readiness::Readable) => {}
            Ok(Readiness::Timeout) => return Ok((seq, None)),
            Ok(Readiness::Interrupted) => continue,
            Err(e) => return Err(StopReason::DeviceLost(e)),
        }
        let got = io.read_available(rx).map_err(StopReason::DeviceLost)?;
        let rx_ns = now_ns();
        if let Some(m) = core.receive(&rx[..got], seq) {
            return Ok((seq, Some(Reply { m, req_ns, rx_ns })));
        }
    }
}

impl Runner<'_> {
    fn send(&self, n: usize) -> Result<(), StopReason> {
        self.io
            .write_all(&self.tx[..n])
            .map_err(StopReason::DeviceLost)
    }

    /// Sends the sample request and waits for its answer until the reply timeout.
    fn sample(&mut self, tick: &Tick) -> Result<(u16, Option<Reply>), StopReason> {
        let cap_ns = tick.deadline_ns + self.period_ns;
        exchange(
            self.io,
            self.core,
            &mut self.tx,
            &mut self.rx,
            self.reply_timeout_ns,
            cap_ns,
        )
    }

    /// Refuses an enabling command resting on a measurement requested at `req_ns` when that
    /// is [`MAX_BLIND_MS`] or more ago. The period-counting bounds cannot see a loop that was
    /// suspended (or starved) inside a period, between the request and the command: without
    /// this, its first act on resuming is to drive on a measurement as old as the suspension.
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

    /// Checks that apply at the top of every period.
    fn check_period(&mut self, tick: &Tick, phase: Phase) -> Result<(), StopReason> {
        if let Some(reason) = requested_stop() {
            return Err(reason);
        }
        if let Some(log) = self.log.as_deref() {
            log.check().map_err(StopReason::LogError)?;
        }
        let Phase::Balancing { .. } = phase else {
            return Ok(());
        };
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
        if let Some(experiment_ns) = self.experiment_ns {
            self.balanced_ns = tick.deadline_ns - experiment_ns;
            if self.duration_ns.is_some_and(|d| self.balanced_ns >= d) {
                return Err(StopReason::Finished);
            }
        }
        self.check_swing_up_run(tick, phase)
    }

    /// A swing-up run as a whole: once the pendulum has fallen after a catch (and the
    /// supervisor swings up again), the swing-ups together may take `swing_up.max_time`, and
    /// with `--duration` the run ends `swing_up.max_time + --duration` after the swing's start
    /// at the latest. The supervisor's own clock bounds each swing-up only.
    fn check_swing_up_run(&self, tick: &Tick, phase: Phase) -> Result<(), StopReason> {
        let Phase::Balancing { start_ns } = phase else {
            return Ok(());
        };
        if !self.core.supervises_swing_up() {
            return Ok(());
        }
        if self.falls > 0
            && self.swing_periods as f64 * self.period_ns as f64 * 1e-9 > self.max_swing_s
        {
            return Err(StopReason::SwingUpRetriesExhausted {
                falls: self.falls,
                max_time: self.max_swing_s,
            });
        }
        if let Some(d) = self.duration_ns {
            let bound_s = self.max_swing_s + d as f64 * 1e-9;
            if (tick.deadline_ns.saturating_sub(start_ns)) as f64 * 1e-9 >= bound_s {
                return Err(StopReason::SwingUpRunTimeout {
                    falls: self.falls,
                    duration: d as f64 * 1e-9,
                    bound: bound_s,
                });
            }
        }
        Ok(())
    }

    /// A period without a measurement: the previous command again (within the staleness
    /// bounds), and the controller told that the period passed with it.
    fn no_reply(&mut self, tick: &Tick, seq: u16, phase: Phase) -> Result<(), StopReason> {
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
        let Phase::Balancing { start_ns } = phase else {
            return Ok(());
        };
        // Without this the controller's next step would treat two periods as one: a rate
        // difference over 2 Ts divided by Ts, an estimator prior one period stale.
        self.core.hold();
        if let Some(prev) = self.last_step {
            let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
            let step = StepOutput {
                flags: FLAG_NO_REPLY,
                reference: self.core.reference_at(t),
                ..prev
            };
            self.log_row(Row {
                t,
                seq,
                step,
                estimate: None,
                compute_us: 0.0,
                jitter_us: tick.lateness_ns as f64 / 1e3,
                phase: step.phase.name(),
            })?;
        }
        Ok(())
    }

    /// Arming: stop commands until the pendulum is upright; returns the next phase.
    fn arm(&mut self, tick: &Tick, reply: &Reply, phase: Phase) -> Result<Phase, StopReason> {
        let Phase::Arming { since_ns, told } = phase else {
            return Ok(phase);
        };
        match self.core.check_start(&reply.m) {
            Ok(()) => {
                self.core.reset();
                if !self.quiet {
                    crate::say!("rip-rt: pendulum upright, balancing");
                }
                self.experiment_ns = Some(tick.deadline_ns);
                Ok(Phase::Balancing {
                    start_ns: tick.deadline_ns,
                })
            }
            Err(reason) => {
                let waited = tick.deadline_ns.saturating_sub(since_ns);
                if matches!(reason, StopReason::AngleLimit { .. }) || waited >= self.wait_upright_ns
                {
                    return Err(reason);
                }
                if !told && !self.quiet {
                    crate::say!(
                        "rip-rt: waiting for the pendulum to be brought upright ({reason})"
                    );
                }
                let n = self.core.encode_stop(&mut self.tx);
                self.send(n)?;
                Ok(Phase::Arming {
                    since_ns,
                    told: true,
                })
            }
        }
    }

    /// Balancing: one controller step and its enabling command.
    fn balance(
        &mut self,
        tick: &Tick,
        seq: u16,
        reply: &Reply,
        start_ns: u64,
    ) -> Result<(), StopReason> {
        let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
        self.core
            .note_latency(reply.rx_ns.saturating_sub(reply.req_ns));
        let mut step = self.core.control(&reply.m, t, &mut self.tx)?;
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
        if tick.skipped > 0 {
            step.flags |= FLAG_DEADLINE_MISS;
        }
        self.last_step = Some(step);
        self.follow_phase(tick, t, step.phase);
        let estimate = Row::estimate_from(self.core.state_estimate());
        self.log_row(Row {
            t,
            seq,
            step,
            estimate,
            compute_us: compute_ns as f64 / 1e3,
            jitter_us: tick.lateness_ns as f64 / 1e3,
            phase: step.phase.name(),
        })
    }

    /// A swing-up's catches and falls. Each catch starts the experiment (the reference's
    /// clock and `--duration`), so that a run that falls and swings up again (`swing_up.on_fall
    /// = "retry"`) still ends with the whole experiment balanced; a fall stops its clock and
    /// returns the reference to 0, so that the next catch holds the arm where it is caught
    /// until the step.
    fn follow_phase(&mut self, tick: &Tick, t: f64, phase: rip_core::Phase) {
        use rip_core::Phase::{Balance, SwingUp};
        match (self.last_phase, phase) {
            (SwingUp, Balance) => {
                self.catches += 1;
                self.catch_s.get_or_insert(t);
                self.experiment_ns = Some(tick.deadline_ns);
                self.core.start_reference_at(t);
                if !self.quiet {
                    crate::say!("rip-rt: caught at t = {t:.2} s, balancing");
                }
            }
            (Balance, SwingUp) => {
                self.falls += 1;
                self.experiment_ns = None;
                self.core.start_reference_at(f64::INFINITY);
                if !self.quiet {
                    crate::say!(
                        "rip-rt: the pendulum left the balance region at t = {t:.2} s; \
                         swinging up again"
                    );
                }
            }
            _ => {}
        }
        if phase == SwingUp {
            self.swing_periods += 1;
        }
        self.last_phase = phase;
    }

    fn periods(&mut self, periodic: &mut Periodic, mut phase: Phase) -> StopReason {
        loop {
            let tick = periodic.wait();
            let result = self.period(&tick, phase);
            match result {
                Ok(next) => phase = next,
                Err(reason) => return reason,
            }
        }
    }

    fn period(&mut self, tick: &Tick, phase: Phase) -> Result<Phase, StopReason> {
        self.check_period(tick, phase)?;
        self.jitter.record(tick.lateness_ns);
        let (seq, reply) = self.sample(tick)?;
        let Some(reply) = reply else {
            self.no_reply(tick, seq, phase)?;
            return Ok(phase);
        };
        self.missing_in_row = 0;
        let phase = self.arm(tick, &reply, phase)?;
        match phase {
            Phase::Arming { .. } => {}
            Phase::Balancing { start_ns } => {
                self.balance(tick, seq, &reply, start_ns)?;
                self.count_overrun(tick)?;
            }
        }
        Ok(phase)
    }

    /// Counts periods whose own work (wake-up to command sent) took longer than a period.
    /// A late wake-up alone is the scheduler's doing, not the controller's, and is left to the
    /// stall rule.
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
}

/// Runs the loop on `io` until a stop reason arises (module docs): the probe, then arming and
/// balancing. Always ends with the stop frame. Stop requests come from
/// [`crate::stop::install_signal_handlers`].
pub fn run(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    opts: &RunOptions,
    log: Option<&mut LogWriter>,
) -> RunReport {
    let guard = StopGuard::new(io.raw());
    let period_ns = cfg.period_ns();
    let core_phase = core.phase();
    let mut runner = Runner {
        io,
        core,
        log,
        quiet: opts.quiet,
        period_ns,
        reply_timeout_ns: (cfg.loop_.reply_timeout_ms * 1e6).round() as u64,
        watchdog: cfg.loop_.watchdog_periods,
        max_step_ns: (cfg.loop_.max_step_periods * period_ns as f64) as u64,
        max_misses: cfg.loop_.max_consecutive_misses,
        wait_upright_ns: (cfg.safety.wait_upright_s * 1e9) as u64,
        duration_ns: opts.duration_s.map(|d| (d * 1e9) as u64),
        jitter: Histogram::new(),
        compute: Histogram::new(),
        tx: [0; MAX_FRAME],
        rx: [0; 512],
        missing_in_row: 0,
        missing_total: 0,
        misses_in_row: 0,
        last_step: None,
        balanced_ns: 0,
        experiment_ns: None,
        last_phase: core_phase,
        catch_s: None,
        catches: 0,
        falls: 0,
        swing_periods: 0,
        max_swing_s: cfg.spec.swing_up.max_time,
        based_on_ns: 0,
    };
    let mut periodic = Periodic::new(period_ns, now_ns() + period_ns);
    let mut calibration = None;
    let mut sign_check = None;
    let (reason, probe) = match probe(runner.core, cfg) {
        Err(reason) => (reason, None),
        Ok(probe) => {
            io.flush_input();
            // The probe may have taken longer than a period: start the grid afresh.
            periodic = Periodic::new(period_ns, now_ns() + period_ns);
            let reason = if runner.core.supervises_swing_up() {
                // Hanging at rest first; the swing starts in the period after the check, on
                // the same grid.
                match calibrate::check_rest(io, runner.core, cfg, &mut periodic, opts.quiet) {
                    Err(reason) => reason,
                    Ok(cal) => {
                        runner.core.calibrate(&cal);
                        calibration = Some(cal);
                        // A reversed motor lead or arm encoder would make the swing drive the
                        // arm away to its limit: the pulse of `rip-rt excite` first.
                        let check_opts = ExciteOptions {
                            check_voltage: PULSE_VOLTAGE,
                            quiet: opts.quiet,
                        };
                        let check = excite::check_signs(
                            io,
                            runner.core,
                            cfg,
                            &mut periodic,
                            &check_opts,
                            runner.log.as_deref_mut(),
                        );
                        runner.missing_total += check.missing_replies;
                        match check.result {
                            Err(reason) => reason,
                            Ok(report) => {
                                sign_check = Some(report);
                                // The pendulum swings after the pulse: at rest again, and the
                                // zeros from that rest, before the swing starts from it.
                                match calibrate::settle(
                                    io,
                                    runner.core,
                                    cfg,
                                    &mut periodic,
                                    opts.quiet,
                                ) {
                                    Err(reason) => reason,
                                    Ok(cal) => {
                                        runner.core.calibrate(&cal);
                                        calibration = Some(cal);
                                        runner.core.reset();
                                        if !opts.quiet {
                                            crate::say!("rip-rt: swinging up");
                                        }
                                        // One time axis for the log: from the check's start.
                                        let start_ns = check.start_ns;
                                        runner.periods(&mut periodic, Phase::Balancing { start_ns })
                                    }
                                }
                            }
                        }
                    }
                }
            } else {
                let since_ns = periodic.next_deadline_ns();
                let arming = Phase::Arming {
                    since_ns,
                    told: false,
                };
                runner.periods(&mut periodic, arming)
            };
            (reason, Some(probe))
        }
    };
    let driven = runner.last_step.is_some();
    let braking =
        crate::envelope::bring_to_rest(io, runner.core, cfg, &mut periodic, &reason, driven);
    if !opts.quiet && braking.mode != crate::envelope::BrakeMode::None {
        crate::say!("rip-rt: stop: {braking}");
    }
    let stop_sent = guard.stop();
    drop(guard);
    RunReport {
        reason,
        stop_sent,
        timing: TimingSummary::from_histograms(&runner.jitter, &runner.compute, periodic.missed()),
        probe,
        parser: runner.core.parser_stats(),
        missing_replies: runner.missing_total,
        balanced_s: runner.balanced_ns as f64 * 1e-9,
        calibration,
        sign_check,
        catch_s: runner.catch_s,
        catches: runner.catches,
        witness_peak: runner.core.witness_peak(),
    }
}

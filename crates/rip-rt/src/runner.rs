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
//! `loop.watchdog_periods` (and never more than [`MAX_BLIND_MS`](crate::config::MAX_BLIND_MS)) after the last measurement;
//! `loop.max_consecutive_misses` periods in a row longer than a period, or a loop that did not run for
//! [`MAX_BLIND_MS`](crate::config::MAX_BLIND_MS) (suspended, starved), stop it.

use crate::calibrate::{self, Calibration};
use crate::config::Config;
use crate::excite;
use crate::log::LogWriter;
use crate::loop_core::{LoopCore, StepOutput};
use crate::onboard;
use crate::period::{Act, Law, Logged, Period, Reply};
use crate::protocol::{ParserStats, MAX_FRAME};
use crate::serial::Fd;
use crate::sign_check::{SignReport, PULSE_VOLTAGE};
use crate::stop::{requested_stop, StopGuard, StopReason};
use crate::timing::{now_ns, ClockMode, Periodic, Tick, TimingSummary};

/// Options of one run besides the configuration.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stop after this many seconds of balancing.
    pub duration_s: Option<f64>,
    /// Suppress progress messages on stderr.
    pub quiet: bool,
    /// The clock of the loop: real time, or lockstep with an emulator (`--lockstep`).
    pub clock: ClockMode,
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
    pub witness_peak: Option<[f64; 5]>,
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

/// The command law of `rip-rt run`: arming, then the controller's commands, with the run's
/// own bounds (`--duration`, `safety.wait_upright_s`, a swing-up's time).
struct RunLaw {
    phase: Phase,
    quiet: bool,
    period_ns: u64,
    wait_upright_ns: u64,
    duration_ns: Option<u64>,
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
}

impl RunLaw {
    fn new(cfg: &Config, opts: &RunOptions, core_phase: rip_core::Phase) -> Self {
        RunLaw {
            phase: Phase::Arming {
                since_ns: 0,
                told: false,
            },
            quiet: opts.quiet,
            period_ns: cfg.period_ns(),
            wait_upright_ns: (cfg.safety.wait_upright_s * 1e9) as u64,
            duration_ns: opts.duration_s.map(|d| (d * 1e9) as u64),
            balanced_ns: 0,
            experiment_ns: None,
            last_phase: core_phase,
            catch_s: None,
            catches: 0,
            falls: 0,
            swing_periods: 0,
            max_swing_s: cfg.spec.swing_up.max_time,
        }
    }

    /// A swing-up run as a whole: once the pendulum has fallen after a catch (and the
    /// supervisor swings up again), the swing-ups together may take `swing_up.max_time`, and
    /// with `--duration` the run ends `swing_up.max_time + --duration` after the swing's start
    /// at the latest. The supervisor's own clock bounds each swing-up only.
    fn check_swing_up_run(&self, core: &LoopCore, tick: &Tick) -> Result<(), StopReason> {
        let Phase::Balancing { start_ns } = self.phase else {
            return Ok(());
        };
        if !core.supervises_swing_up() {
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

    /// Arming: stop commands until the pendulum is upright; `Ok(true)` once it is (the phase
    /// is then balancing).
    fn arm(&mut self, core: &mut LoopCore, tick: &Tick, reply: &Reply) -> Result<bool, StopReason> {
        let Phase::Arming { since_ns, told } = self.phase else {
            return Ok(true);
        };
        match core.check_start(&reply.m) {
            Ok(()) => {
                core.reset();
                if !self.quiet {
                    crate::say!("rip-rt: pendulum upright, balancing");
                }
                self.experiment_ns = Some(tick.deadline_ns);
                self.phase = Phase::Balancing {
                    start_ns: tick.deadline_ns,
                };
                Ok(true)
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
                self.phase = Phase::Arming {
                    since_ns,
                    told: true,
                };
                Ok(false)
            }
        }
    }

    /// A swing-up's catches and falls. Each catch starts the experiment (the reference's
    /// clock and `--duration`), so that a run that falls and swings up again (`swing_up.on_fall
    /// = "retry"`) still ends with the whole experiment balanced; a fall stops its clock and
    /// returns the reference to 0, so that the next catch holds the arm where it is caught
    /// until the step.
    fn follow_phase(&mut self, core: &mut LoopCore, tick: &Tick, t: f64, phase: rip_core::Phase) {
        use rip_core::Phase::{Balance, SwingUp};
        match (self.last_phase, phase) {
            (SwingUp, Balance) => {
                self.catches += 1;
                self.catch_s.get_or_insert(t);
                self.experiment_ns = Some(tick.deadline_ns);
                core.start_reference_at(t);
                if !self.quiet {
                    crate::say!("rip-rt: caught at t = {t:.2} s, balancing");
                }
            }
            (Balance, SwingUp) => {
                self.falls += 1;
                self.experiment_ns = None;
                core.start_reference_at(f64::INFINITY);
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
}

impl Law for RunLaw {
    fn driving(&self) -> bool {
        matches!(self.phase, Phase::Balancing { .. })
    }

    fn check(&mut self, core: &LoopCore, tick: &Tick) -> Result<(), StopReason> {
        if !self.driving() {
            return Ok(());
        }
        if let Some(experiment_ns) = self.experiment_ns {
            self.balanced_ns = tick.deadline_ns - experiment_ns;
            if self.duration_ns.is_some_and(|d| self.balanced_ns >= d) {
                return Err(StopReason::Finished);
            }
        }
        self.check_swing_up_run(core, tick)
    }

    fn command(
        &mut self,
        core: &mut LoopCore,
        tx: &mut [u8; MAX_FRAME],
        tick: &Tick,
        reply: &Reply,
    ) -> Result<Act, StopReason> {
        if !self.arm(core, tick, reply)? {
            return Ok(Act::Stop);
        }
        let Phase::Balancing { start_ns } = self.phase else {
            unreachable!("arming ends above")
        };
        let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
        core.note_latency(reply.rx_ns.saturating_sub(reply.req_ns));
        let step = core.control(&reply.m, t, tx)?;
        Ok(Act::Drive(Logged {
            t,
            step,
            phase: step.phase.name(),
            with_estimate: true,
        }))
    }

    fn sent(&mut self, core: &mut LoopCore, tick: &Tick, logged: &Logged) {
        self.follow_phase(core, tick, logged.t, logged.step.phase);
    }

    fn missed(
        &mut self,
        core: &mut LoopCore,
        tick: &Tick,
        last: Option<&Logged>,
    ) -> Option<Logged> {
        let Phase::Balancing { start_ns } = self.phase else {
            return None;
        };
        // Without this the controller's next step would treat two periods as one: a rate
        // difference over 2 Ts divided by Ts, an estimator prior one period stale.
        core.hold();
        let prev = last?;
        let t = (tick.deadline_ns - start_ns) as f64 * 1e-9;
        let step = StepOutput {
            reference: core.reference_at(t),
            ..prev.step
        };
        Some(Logged {
            t,
            step,
            phase: step.phase.name(),
            with_estimate: false,
        })
    }
}

/// The swing-up's way to its first command: the rest check, the sign check, the rest check
/// again; the law then starts balancing from the sign check's time zero. Returns the stop
/// reason of a check that failed.
fn prepare_swing_up(
    driver: &mut Period<'_>,
    law: &mut RunLaw,
    cfg: &Config,
    calibration: &mut Option<Calibration>,
    sign_check: &mut Option<SignReport>,
) -> Result<(), StopReason> {
    let quiet = driver.quiet();
    // The image for the device's own stop on a silent host, before the checks' grid starts.
    let uploaded = onboard::watchdog::upload(driver.io, cfg);
    driver.clock.restart();
    // Hanging at rest first; the swing starts in the period after the check, on the same grid.
    let cal = calibrate::check_rest(driver.io, driver.core, cfg, &mut driver.clock, quiet)?;
    driver.core.calibrate(&cal);
    *calibration = Some(cal);
    // A reversed motor lead or arm encoder would make the swing drive the arm away to its
    // limit: the pulse of `rip-rt excite` first.
    let check = excite::check_signs(driver, cfg, PULSE_VOLTAGE);
    let report = check.result?;
    *sign_check = Some(report);
    // The pendulum swings after the pulse: at rest again, and the zeros from that rest,
    // before the swing starts from it.
    let cal = calibrate::settle(driver.io, driver.core, cfg, &mut driver.clock, quiet)?;
    driver.core.calibrate(&cal);
    // The wiring is checked and the zeros known: the device may stop the arm itself. The
    // round trip (or a lost ack's repeats) is not a missed period: the grid starts afresh.
    let armed = uploaded.and_then(|()| onboard::watchdog::arm(driver.io, &cal));
    driver.clock.restart();
    *calibration = Some(cal);
    driver.core.reset();
    if !quiet {
        match armed {
            Ok(true) => crate::say!(
                "rip-rt: should this host go silent, the device stops the arm itself (braking \
                 and holding it, the wiring checked)"
            ),
            Ok(false) => crate::say!(
                "rip-rt: should this host go silent, the device shorts the windings (the rig's \
                 stop has no hold law for it to run)"
            ),
            Err(e) => crate::say!(
                "rip-rt: should this host go silent, the device shorts the windings: its own \
                 stop could not be set up ({e})"
            ),
        }
        crate::say!("rip-rt: swinging up");
    }
    // One time axis for the log: from the check's start.
    law.phase = Phase::Balancing {
        start_ns: check.start_ns,
    };
    Ok(())
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
    let mut law = RunLaw::new(cfg, opts, core.phase());
    let clock = Periodic::starting(cfg.period_ns(), opts.clock);
    let mut driver = Period::new(io, core, cfg, clock, log, opts.quiet);
    let mut calibration = None;
    let mut sign_check = None;
    let (reason, probe) = match probe(driver.core, cfg) {
        Err(reason) => (reason, None),
        Ok(probe) => {
            io.flush_input();
            // The probe may have taken longer than a period: start the grid afresh.
            driver.clock.restart();
            let prepared = if driver.core.supervises_swing_up() {
                prepare_swing_up(
                    &mut driver,
                    &mut law,
                    cfg,
                    &mut calibration,
                    &mut sign_check,
                )
            } else {
                law.phase = Phase::Arming {
                    since_ns: driver.clock.next_deadline_ns(),
                    told: false,
                };
                Ok(())
            };
            let reason = match prepared {
                Err(reason) => reason,
                Ok(()) => driver.run(&mut law),
            };
            (reason, Some(probe))
        }
    };
    // A swing-up run drives its sign-check pulse before the wiring is known.
    let wiring_checked = !driver.core.supervises_swing_up() || sign_check.is_some();
    let (reason, _) = driver.bring_to_rest(cfg, reason, wiring_checked);
    let stop_sent = guard.stop();
    drop(guard);
    RunReport {
        reason,
        stop_sent,
        timing: TimingSummary::from_histograms(
            &driver.jitter,
            &driver.compute,
            driver.clock.missed(),
        ),
        probe,
        parser: driver.core.parser_stats(),
        missing_replies: driver.missing_total,
        balanced_s: law.balanced_ns as f64 * 1e-9,
        calibration,
        sign_check,
        catch_s: law.catch_s,
        catches: law.catches,
        witness_peak: driver.core.witness_peak(),
    }
}

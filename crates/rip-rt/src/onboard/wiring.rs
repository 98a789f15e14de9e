//! Before an onboard start: the wiring's sign, checked with the pendulum hanging.
//!
//! The device stops a run on its own account (its limits, a silent host) with the braking and
//! hold laws of the image's stop design only when the start says the wiring's sign is known
//! (`ONBOARD_WIRING_VERIFIED`): a voltage of the wrong sign would drive the arm on, so an
//! unverified device shorts the windings instead. A run whose pendulum hangs at the first
//! measurement gets the host loop's checks before a swing-up: the rest check
//! ([`crate::rest`]: a swinging pendulum could show the sign check's motion by itself), then
//! the sign check ([`crate::sign_check`]: the pulse, driven over the link period by period on
//! the link's own clock, the arm held to `safety.arm_limit`); then it waits, up to
//! `safety.wait_upright_s` (which must then be positive), for the operator to raise the
//! pendulum within `safety.start_tolerance` of upright. One that starts upright is
//! unverified, and says so.

use std::time::Duration;

use rip_protocol::{Command, Measurement, Message, COMMAND_BRAKE, COMMAND_ENABLE};

use super::{sensor, Link, OnboardEnd, Pace};
use crate::config::Config;
use crate::rest::{RestCheck, RestVerdict};
use crate::sign_check::{SignCheck, PULSE_VOLTAGE};
use crate::stop::StopReason;

/// Pendulum angle from hanging (rad) within which the first measurement counts as hanging,
/// so that the sign check runs.
pub const HANGING_RAD: f64 = 0.2;

/// The measurement to start from and whether the wiring's sign was verified (module docs).
///
/// # Errors
/// The run's end: a failed sign check (its fault), a pendulum not raised in time, a signal, a
/// silent device.
pub fn prepare(
    link: &mut Link<'_>,
    cfg: &Config,
    first: Measurement,
    period: Duration,
    lockstep: bool,
) -> Result<(Measurement, bool), OnboardEnd> {
    let sensor = sensor(cfg);
    let angles = |m: &Measurement| sensor.angles([m.arm_counts, m.pendulum_counts]);
    let [_, alpha] = angles(&first);
    if std::f64::consts::PI - alpha.abs() > HANGING_RAD {
        crate::say!(
            "rip-rt: the wiring's sign is unchecked, so a stop the device makes itself (host \
             lost, a limit) shorts the windings; start with the pendulum hanging to have it \
             checked, and the device brakes and holds the arm instead"
        );
        return Ok((first, false));
    }
    let wait = cfg.safety.wait_upright_s;
    if wait <= 0.0 {
        return Err(OnboardEnd::Setup(
            "the pendulum hangs: set safety.wait_upright_s to the seconds you need to raise it \
             after rip-rt has checked the wiring, or start with it upright (the wiring then \
             unchecked)"
                .into(),
        ));
    }
    // The link's own clock: off lockstep a host period is at least 10 ms, whatever the
    // design's.
    let dt = period.as_secs_f64();
    let mut pace = Pace::new(period, lockstep);
    let mut rest = RestCheck::new(cfg);
    let mut k = 0u64;
    let first = loop {
        let m = pace.next(link, None)?;
        match rest.push(k as f64 * dt, m.arm_counts, m.pendulum_counts) {
            Ok(RestVerdict::AtRest(_)) => break m,
            Ok(RestVerdict::Waiting) => k += 1,
            Err(fault) => return Err(OnboardEnd::Host(StopReason::NotAtRest(fault))),
        }
    };
    let mut check = SignCheck::new(cfg, PULSE_VOLTAGE);
    let [theta, alpha] = angles(&first);
    check.push(theta, alpha);
    let mut k = 0u64;
    let verdict = loop {
        let Some(v) = check.command(k as f64 * dt) else {
            break check.verdict();
        };
        let command = Command {
            voltage_mv: (v * 1000.0).round() as i16,
            flags: COMMAND_ENABLE,
        };
        let m = pace
            .next(link, Some(command))
            .inspect_err(|_| brake(link))?;
        let [theta, alpha] = angles(&m);
        if rip_control::stop::past_limit(theta, cfg.safety.arm_limit) {
            brake(link);
            return Err(OnboardEnd::Host(StopReason::AngleLimit {
                which: "arm",
                angle: theta,
                limit: cfg.safety.arm_limit,
            }));
        }
        check.push(theta, alpha);
        k += 1;
    };
    brake(link);
    let report = verdict.map_err(|f| OnboardEnd::Host(StopReason::SignCheck(f)))?;
    crate::say!(
        "rip-rt: sign check {report}; raise the pendulum upright to start (within \
         safety.wait_upright_s = {wait} s)"
    );
    let periods = (wait / dt).ceil() as u64;
    for _ in 0..periods {
        let m = pace.next(link, None)?;
        let [theta, alpha] = angles(&m);
        if alpha.abs() <= cfg.safety.start_tolerance && theta.abs() <= cfg.safety.arm_limit {
            return Ok((m, true));
        }
    }
    let [_, alpha] = link.last_measurement.as_ref().map_or([0.0, alpha], angles);
    Err(OnboardEnd::Host(StopReason::NotUpright {
        angle: alpha,
        tolerance: cfg.safety.start_tolerance,
    }))
}

/// 0 V with the windings shorted: the end of the sign check's pulse, or of a check cut short.
fn brake(link: &mut Link<'_>) {
    let _ = link.send(Message::Command(Command {
        voltage_mv: 0,
        flags: COMMAND_BRAKE,
    }));
}

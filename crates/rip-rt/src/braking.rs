//! The active stop's I/O: after a run stopped, the arm is driven to rest by the braking law of
//! [`crate::envelope`] on the run's clock, then the caller sends the stop frame. The law, the
//! envelope and the stop modes are [`crate::envelope`]'s (free of I/O); this module exchanges
//! with the device.

use crate::config::Config;
use crate::envelope::{
    arm_envelope, brake_for_mode, sample_rates, stop_mode, stop_sequence, BrakeCommand, BrakeMode,
    BrakeReport, StopParts, StopSequence,
};
use crate::exchange::exchange;
use crate::loop_core::LoopCore;
use crate::protocol::{encode, Command, Frame, Message, MAX_FRAME, STATUS_FAULT};
use crate::serial::Fd;
use crate::stop::{next_seq, signal_name, StopReason, StopWatch};
use crate::timing::Periodic;

/// The longest an active stop runs (s), on the stop's clock; then the stop frame goes out
/// regardless ([`rip_control::stop::MAX_STOP_S`], the device's bound too).
pub use rip_control::stop::MAX_STOP_S;

/// The longest the gentle end of a run takes (s): the lowering for up to
/// [`MAX_LOWER_S`](rip_core::envelope::MAX_LOWER_S), then, if it did not bring the pendulum
/// down, the fault's stop for up to [`MAX_STOP_S`].
pub const MAX_GENTLE_STOP_S: f64 = rip_core::envelope::MAX_LOWER_S + MAX_STOP_S;

/// Whether the stop after `reason` in `mode` begins by lowering the pendulum: an orderly end
/// (the duration, a first stop signal) of a run in `phase` [`Balance`](rip_core::Phase::Balance)
/// whose wiring's sign is trusted ([`BrakeMode::Active`]) and whose pendulum was last measured
/// at `last_alpha` within [`LOWER_FROM_RAD`](crate::envelope::LOWER_FROM_RAD) of upright.
/// Faults, a second signal, a fall, a swing-up still swinging and open-loop runs keep the
/// fault's stop. One rule for `rip-rt` and its simulations.
pub fn begins_lowered(
    reason: &StopReason,
    mode: BrakeMode,
    phase: rip_core::Phase,
    last_alpha: Option<f64>,
) -> bool {
    let upright = last_alpha.is_some_and(|alpha| {
        rip_core::swingup::wrap_angle(alpha).abs() <= crate::envelope::LOWER_FROM_RAD
    });
    reason.is_orderly() && mode == BrakeMode::Active && phase == rip_core::Phase::Balance && upright
}

/// The gentle end's law for the stop after `reason` in `mode` on `core`'s rig, when it
/// [`begins_lowered`] and the rig has a lowering designed.
pub fn lowering_for<'a>(
    core: &'a LoopCore,
    reason: &StopReason,
    mode: BrakeMode,
) -> Option<&'a rip_core::envelope::Lowering> {
    let last_alpha = core.last_angles().map(|(_, alpha)| alpha);
    begins_lowered(reason, mode, core.phase(), last_alpha)
        .then(|| core.lowering())
        .flatten()
}

/// The line that says at once what a stop after `reason` does, how long it may take, and what
/// a signal during it does: the stop is silent for up to [`MAX_STOP_S`] otherwise. `lowering`:
/// the gentle end's law when the stop begins with it ([`lowering_for`]).
pub fn stop_announcement(
    reason: &StopReason,
    lowering: Option<&rip_core::envelope::Lowering>,
) -> String {
    let (what, again) = match reason {
        StopReason::Signal(libc::SIGINT) => ("Ctrl-C".to_string(), "Ctrl-C again"),
        StopReason::Signal(sig) => (signal_name(*sig), "Ctrl-C"),
        other => (other.name().to_string(), "Ctrl-C"),
    };
    let doing = match lowering {
        Some(l) => format!(
            "lowering the pendulum and bringing the arm to rest (about {:.0} s, at most \
             {MAX_GENTLE_STOP_S:.0} s)",
            l.seconds.ceil()
        ),
        None => format!("bringing the arm to rest (at most {MAX_STOP_S:.0} s)"),
    };
    format!(
        "rip-rt: {what}: stopping: {doing}; {again} disables the driver at once (the arm may \
         then coast past safety.arm_limit)"
    )
}

/// The witness on a period of the gentle end (measurement `m`; the stop's last command,
/// [`StopSequence::last_volts`]): a fault it finds gives the lowering up for that fault's
/// brake, and is returned.
fn witness_lowering(
    core: &mut LoopCore,
    parts: Option<&StopParts>,
    stop: &mut StopSequence,
    m: &crate::protocol::Measurement,
) -> Option<crate::witness::WitnessFault> {
    let (theta, alpha) = core.angles(m);
    let commanded = stop.last_volts();
    let Err(StopReason::Witness(fault)) = core.witness_stop_period(m, theta, alpha, commanded)
    else {
        return None;
    };
    let mode = crate::envelope::brake_mode(&StopReason::Witness(fault));
    stop.lowering_faulted(brake_for_mode(
        parts,
        mode,
        core.witness_estimate(),
        commanded,
    ));
    Some(fault)
}

/// The stop's own timing for the witness, as the run's periods note theirs.
fn note_timing(
    core: &mut LoopCore,
    periodic: &Periodic,
    tick: &crate::timing::Tick,
    reply: &crate::exchange::Reply,
) {
    core.note_latency(reply.rx_ns.saturating_sub(reply.req_ns));
    core.note_period(
        tick.lateness_ns,
        tick.skipped,
        periodic.mode() == crate::timing::ClockMode::Lockstep,
        reply.req_ns,
    );
}

/// The command frame's content for the stop's `command`.
fn command_of(command: BrakeCommand) -> Command {
    match command {
        BrakeCommand::Volts(v) => Command {
            voltage_mv: (v * 1000.0).round() as i16,
            flags: crate::protocol::COMMAND_ENABLE,
        },
        BrakeCommand::Short => Command::BRAKE,
    }
}

fn send(io: &Fd, command: Command) -> bool {
    let mut out = [0u8; MAX_FRAME];
    let n = encode(
        &Frame {
            seq: next_seq(),
            message: Message::Command(command),
        },
        &mut out,
    );
    io.write_all(&out[..n]).is_ok()
}

/// Brings the arm to rest after the run stopped for `reason` (module docs), on the loop's
/// grid `periodic`; the caller then sends the stop frame. `driven`: whether the run sent an
/// enabling command (without one the arm was never driven, and nothing is sent).
/// `wiring_checked`: whether the wiring's sign is known, i.e. the run has no sign check or
/// its sign check passed ([`stop_mode`]). Returns at once when nothing can or need be braked.
///
/// A stop signal during it ([`StopWatch`]) ends it within a period,
/// [`BrakeReport::cut_short`] naming the signal, so that the caller's stop frame disables the
/// driver at once. The caller says first what the stop does ([`stop_announcement`]).
pub fn bring_to_rest(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    periodic: &mut Periodic,
    reason: &StopReason,
    driven: bool,
    wiring_checked: bool,
) -> BrakeReport {
    let mode = stop_mode(reason, driven, wiring_checked);
    let mut report = BrakeReport {
        mode,
        seconds: 0.0,
        max_rate: 0.0,
        at_rest: mode == BrakeMode::None,
        cut_short: None,
        lowered: false,
        witness: None,
    };
    if mode == BrakeMode::None {
        return report;
    }
    let watch = StopWatch::for_stop(reason);
    // The run's stop, designed when the loop was built: every part of this stop takes it.
    let parts = core.stop_parts().copied();
    let parts = parts.as_ref();
    let brake = brake_for_mode(parts, mode, core.witness_estimate(), core.held_voltage());
    let lowering = lowering_for(core, reason, mode).copied();
    let mut stop = stop_sequence(cfg, parts, brake);
    if let Some(lowering) = &lowering {
        stop = stop.lowering(lowering.law, arm_envelope(cfg, parts), core.held_voltage());
    }
    let reply_timeout_ns = (cfg.loop_.reply_timeout_ms * 1e6).round() as u64;
    let mut last: Option<(f64, f64, u32)> = None;
    // Whether the last period went without a reply (its successor is shorted too).
    let mut blind = false;
    let mut tx = [0u8; MAX_FRAME];
    let mut rx = [0u8; 512];
    // A fresh grid: the run may have stopped in the middle of a period, or after a stall.
    periodic.restart();
    let start_ns = periodic.next_deadline_ns();
    let bound_s = if lowering.is_some() {
        MAX_GENTLE_STOP_S
    } else {
        MAX_STOP_S
    };
    let end_ns = start_ns + (bound_s * 1e9) as u64;
    loop {
        let tick = periodic.wait();
        report.seconds = (tick.deadline_ns - start_ns) as f64 * 1e-9;
        report.mode = stop.mode();
        if tick.deadline_ns >= end_ns {
            return report;
        }
        if let Some(sig) = watch.interrupted() {
            report.cut_short = Some(sig);
            return report;
        }
        // The lowering's time on the stop's clock: periods without a reply count too.
        if stop.is_lowering() && report.seconds >= rip_core::envelope::MAX_LOWER_S {
            stop.give_up_lowering();
        }
        let reply = match exchange(io, core, periodic, &mut tx, &mut rx, reply_timeout_ns) {
            Ok((_, reply)) => reply,
            // The device is gone: nothing more can be sent.
            Err(_) => return report,
        };
        if let Some(reply) = &reply {
            note_timing(core, periodic, &tick, reply);
        }
        let Some(reply) = reply else {
            // Without a fresh measurement the law has no rate: short the windings for this
            // period only. Giving the law up for good left the pendulum free to walk the arm
            // on past the limit once the device answered again.
            blind = true;
            if stop.mode() == BrakeMode::Modelled {
                // The model's arm ran open loop on the law's voltages; the short it did not
                // see leaves it apart from the arm for good.
                stop.short();
            }
            stop.note_short();
            if !send(io, Command::BRAKE) {
                return report;
            }
            continue;
        };
        let sample_ns = reply.req_ns;
        let resumed = std::mem::take(&mut blind);
        if resumed {
            core.witness_restart();
        }
        if reply.m.status & STATUS_FAULT != 0 {
            // A faulted driver opens the windings itself; nothing to drive.
            send(io, Command::BRAKE);
            report.mode = BrakeMode::Short;
            return report;
        }
        let (theta, alpha) = core.angles(&reply.m);
        let now_us = reply.m.device_time_us;
        if resumed {
            // A rate across the gap is the mean over the blind periods, not the arm's rate
            // now: short once more, and resume the law on the next period's difference.
            last = Some((theta, alpha, now_us));
            stop.note_short();
            if !send(io, Command::BRAKE) {
                return report;
            }
            continue;
        }
        let before = last.replace((theta, alpha, now_us));
        let (rate, alpha_rate) = sample_rates(before, theta, alpha, now_us);
        report.max_rate = report.max_rate.max(rate.abs());
        if stop.is_lowering() {
            if let Some(fault) = witness_lowering(core, parts, &mut stop, &reply.m) {
                report.witness = Some(fault);
            }
        }
        let Some(command) = stop.step(theta, rate, alpha, alpha_rate) else {
            report.at_rest = true;
            report.lowered = stop.lowered();
            return report;
        };
        if !send(io, command_of(command)) {
            return report;
        }
        core.note_sent(periodic.now_ns().saturating_sub(sample_ns));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stop_says_how_long_it_may_take_and_what_a_second_ctrl_c_does() {
        let line = stop_announcement(&StopReason::Signal(libc::SIGINT), None);
        assert_eq!(
            line,
            "rip-rt: Ctrl-C: stopping: bringing the arm to rest (at most 8 s); Ctrl-C again \
             disables the driver at once (the arm may then coast past safety.arm_limit)"
        );
        let term = stop_announcement(&StopReason::Signal(libc::SIGTERM), None);
        assert!(term.starts_with("rip-rt: SIGTERM: stopping"), "{term}");
        let fault = stop_announcement(&StopReason::Watchdog(5), None);
        assert!(
            fault.starts_with("rip-rt: watchdog: stopping") && fault.contains("; Ctrl-C disables"),
            "{fault}"
        );
    }
}

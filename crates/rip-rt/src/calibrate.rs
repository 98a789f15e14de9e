//! The rest check and the hanging-down calibration on the device: [`check_rest`] runs the
//! check of [`crate::rest`] (its criteria are documented there) with the loop's safety rules
//! (stop signals, watchdog, driver faults), sending the stop command every period. The caller
//! owns the [`StopGuard`](crate::stop::StopGuard) that sends 0 V on exit.

use crate::config::Config;
use crate::loop_core::LoopCore;
use crate::period::{exchange, Reply};
use crate::protocol::{MAX_FRAME, STATUS_FAULT};
use crate::serial::Fd;
use crate::stop::{requested_stop, StopReason};
use crate::timing::Periodic;

pub use crate::rest::*;

/// Runs the rest check on the device behind `io` on the grid `periodic` (module docs): every
/// period a sample request and the stop command (0 V, driver disabled), until a still window
/// hanging down gives the [`Calibration`] (not yet applied to `core`: see
/// [`LoopCore::calibrate`]). Stops, with the motor never enabled, on a stop signal, a driver
/// fault, `loop.watchdog_periods` periods in a row without a measurement, a rest pose away from
/// hanging, or `calibration.rest_timeout_s` without a still window ([`StopReason::NotAtRest`]).
/// The caller holds the [`StopGuard`](crate::stop::StopGuard).
pub fn check_rest(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    periodic: &mut Periodic,
    quiet: bool,
) -> Result<Calibration, StopReason> {
    if !quiet {
        crate::say!(
            "rip-rt: checking that the rig is at rest hanging down ({} s still, motor disabled)",
            cfg.calibration.rest_window_s
        );
    }
    let check = RestCheck::new(cfg);
    wait_for_rest(io, core, cfg, periodic, check, quiet)
}

/// [`check_rest`] after the sign check's pulse: the same check, bounded by
/// `calibration.settle_timeout_s` instead of `rest_timeout_s` (the pendulum swings after the
/// pulse and needs time to settle).
pub fn settle(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    periodic: &mut Periodic,
    quiet: bool,
) -> Result<Calibration, StopReason> {
    if !quiet {
        crate::say!(
            "rip-rt: waiting for the rig to come to rest after the pulse (at most {} s, motor \
             disabled)",
            cfg.calibration.settle_timeout_s
        );
    }
    let mut check = RestCheck::new(cfg);
    check.cfg.rest_timeout_s = cfg.calibration.settle_timeout_s;
    check.timeout_key = "calibration.settle_timeout_s";
    wait_for_rest(io, core, cfg, periodic, check, quiet)
}

fn wait_for_rest(
    io: &Fd,
    core: &mut LoopCore,
    cfg: &Config,
    periodic: &mut Periodic,
    mut check: RestCheck,
    quiet: bool,
) -> Result<Calibration, StopReason> {
    let reply_timeout_ns = (cfg.loop_.reply_timeout_ms * 1e6).round() as u64;
    let timeout_ns = (check.cfg.rest_timeout_s * 1e9) as u64;
    let mut tx = [0u8; MAX_FRAME];
    let mut rx = [0u8; 512];
    let mut missing_in_row = 0u32;
    let start_ns = periodic.next_deadline_ns();
    loop {
        let tick = periodic.wait();
        if let Some(reason) = requested_stop() {
            return Err(reason);
        }
        let elapsed_ns = tick.deadline_ns - start_ns;
        if elapsed_ns >= timeout_ns {
            return Err(StopReason::NotAtRest(check.timeout_fault()));
        }
        let (_, reply) = exchange(io, core, periodic, &mut tx, &mut rx, reply_timeout_ns)?;
        let n = core.encode_stop(&mut tx);
        io.write_all(&tx[..n]).map_err(StopReason::DeviceLost)?;
        let Some(Reply { m, .. }) = reply else {
            missing_in_row += 1;
            if missing_in_row >= cfg.loop_.watchdog_periods {
                return Err(StopReason::Watchdog(missing_in_row));
            }
            continue;
        };
        missing_in_row = 0;
        if m.status & STATUS_FAULT != 0 {
            return Err(StopReason::DeviceFault(m.status));
        }
        let t = elapsed_ns as f64 * 1e-9;
        match check.push(t, m.arm_counts, m.pendulum_counts) {
            Ok(RestVerdict::Waiting) => {}
            Ok(RestVerdict::AtRest(cal)) => {
                if !quiet {
                    crate::say!("rip-rt: at rest, calibrated: {cal}");
                }
                return Ok(cal);
            }
            Err(fault) => return Err(StopReason::NotAtRest(fault)),
        }
    }
}

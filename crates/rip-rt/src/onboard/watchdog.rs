//! Host mode's device stop: what the device does when this host goes silent while the motor
//! is driven (protocol v3's [`WatchdogStop`]).
//!
//! The device's command watchdog stops the motor 50 ms after the last command. On its own it
//! shorts the windings, which leaves a balancing or swinging pendulum to walk the arm on. A
//! swing-up run checks the wiring's sign before the swing, so the device may then brake and
//! hold the arm as rip-rt's own stop does (`rip_control::stop`, from the onboard image's stop
//! design): before the rest check the host uploads an image whose stop is the configuration's
//! ([`super::image`], with the LQR's design, the smallest, which the device never runs in host
//! mode), and once the sign check passed and the rest after it gave the encoder zeros, it arms
//! the watchdog's stop with those zeros. A device that cannot (protocol v1 or v2, no room,
//! a rig whose stop has no hold law) keeps the short, and the run says so.

use rip_protocol::{Message, WatchdogStop, ACK_OK, ONBOARD_WIRING_VERIFIED};

use super::Link;
use crate::config::Config;
use crate::controllers::ControllerKind;
use crate::rest::Calibration;
use crate::serial::Fd;

/// Uploads the image that carries `cfg`'s stop design to the device on `io` (module docs).
///
/// # Errors
/// The design or image that cannot be built, or the device's refusal or silence.
pub fn upload(io: &Fd, cfg: &Config) -> Result<(), String> {
    let design = super::design(ControllerKind::Lqr, cfg)?;
    let image = super::image(&design, cfg)?;
    let mut link = Link::new(io);
    let uploaded = link.upload(&image);
    io.flush_input();
    uploaded
}

/// Arms the watchdog's stop of the device on `io`, the wiring verified, with the encoder zeros
/// of `cal`: whether the device will brake and hold the arm (otherwise it shorts the windings).
///
/// # Errors
/// The device's refusal or silence.
pub fn arm(io: &Fd, cal: &Calibration) -> Result<bool, String> {
    let stop = WatchdogStop {
        flags: ONBOARD_WIRING_VERIFIED,
        arm_zero: round_counts(cal.arm_zero_counts),
        pendulum_down: round_counts(cal.pendulum_hanging_counts),
    };
    let mut link = Link::new(io);
    let answer = link.request(Message::WatchdogStop(stop));
    io.flush_input();
    match answer? {
        (ACK_OK, laws) => Ok(laws == 1),
        (code, _) => Err(format!("the device refused it (ack code {code})")),
    }
}

/// A calibration's mean count as the device's whole counts (half a count is far below what
/// the stop's laws resolve).
fn round_counts(counts: f64) -> i32 {
    counts
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
}

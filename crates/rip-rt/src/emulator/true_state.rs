//! The emulator's record of the simulated plant: the `--true-state` CSV and the live stream's
//! truth frames.

use std::fs::File;
use std::io::{self, BufWriter, Write};

use super::{Device, EmulatorConfig};

/// Columns of the emulator's true-state record (`rip-rt emulate --true-state`): simulated time
/// (s), the plant's state `θ, θ̇, α, α̇` (rad, rad/s; α from upright, θ unwrapped) straight
/// from the simulation rather than from the encoders, the voltage across the motor's windings
/// and the motor current in the plant's sign convention (V, A), and the bridge's state
/// ([`Device::driver_state`]).
pub const TRUE_STATE_HEADER: &str = "t_s,theta,theta_dot,alpha,alpha_dot,voltage,current,driver";

/// The true-state record (`--true-state`) and the live stream's truth frames (`--live`): a
/// row every `period` of simulated time, each flushed at once so a reader sees the plant while
/// the emulator runs; a last row when it exits.
pub(super) struct TrueState {
    w: Option<BufWriter<File>>,
    live: Option<crate::live::Live>,
    period_ns: u64,
    next_ns: u64,
}

impl TrueState {
    pub(super) fn create(cfg: &EmulatorConfig) -> io::Result<Option<Self>> {
        let live = match cfg.live {
            Some((port, bounds)) => Some(crate::live::Live::open(port, bounds)?),
            None => None,
        };
        let w = match &cfg.true_state {
            Some(path) => {
                let named = |e: io::Error| {
                    io::Error::new(e.kind(), format!("--true-state {}: {e}", path.display()))
                };
                let mut w = BufWriter::new(File::create(path).map_err(named)?);
                writeln!(w, "{TRUE_STATE_HEADER}").map_err(named)?;
                w.flush().map_err(named)?;
                Some(w)
            }
            None => None,
        };
        if w.is_none() && live.is_none() {
            return Ok(None);
        }
        Ok(Some(Self {
            w,
            live,
            period_ns: (cfg.true_state_period_s * 1e9).round() as u64,
            next_ns: 0,
        }))
    }

    /// Writes a row if one is due at the device's time.
    pub(super) fn sample(&mut self, device: &Device) -> io::Result<()> {
        if device.time_ns >= self.next_ns {
            self.next_ns += self.period_ns.max(1);
            if self.next_ns <= device.time_ns {
                // Behind (a stalled machine): the next row is a period from now.
                self.next_ns = device.time_ns + self.period_ns.max(1);
            }
            self.row(device)?;
        }
        Ok(())
    }

    pub(super) fn row(&mut self, device: &Device) -> io::Result<()> {
        if let Some(live) = self.live.as_mut() {
            let x = device.state();
            let mut f = live
                .frame(crate::live::Kind::Truth)
                .with_phase(device.driver_state())
                .with_estimate(Some(&x));
            f.t = device.time_s();
            f.theta = x[0];
            f.alpha = rip_core::trig::wrap_angle(x[2]);
            f.u_written = device.motor_voltage();
            live.send(f);
        }
        match self.w.as_mut() {
            Some(w) => {
                device.write_true_state(w)?;
                w.flush()
            }
            None => Ok(()),
        }
    }
}

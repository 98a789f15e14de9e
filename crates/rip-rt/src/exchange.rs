//! One exchange with the device: the sample request and the measurement answering it. Below
//! the period driver ([`crate::period`]) and the stop path ([`crate::braking`]), which both
//! exchange with the device on the run's clock.

use crate::loop_core::LoopCore;
use crate::protocol::{Measurement, MAX_FRAME, STATUS_LOCKSTEP, STATUS_NO_SAMPLE};
use crate::serial::{Fd, Readiness};
use crate::stop::StopReason;
use crate::timing::{self, ClockMode, Periodic, LOCKSTEP_REPLY_WAIT_NS};

/// A measurement, when its request was sent and when its bytes were read.
#[derive(Debug, Clone, Copy)]
pub struct Reply {
    /// The measurement.
    pub m: Measurement,
    /// When its sample request was sent (ns, on the run's clock).
    pub req_ns: u64,
    /// When its bytes were read.
    pub rx_ns: u64,
}

/// Sends a sample request on `io` and waits for the measurement answering it, up to
/// `reply_timeout_ns` after the request and never past the grid's next deadline (which the
/// next request must keep). `None` when none arrived in time; bytes that are not the answer
/// (stale replies, garbage) are consumed by `core`'s parser.
///
/// In lockstep the emulator answers once it has advanced its plant by a period, and a reply
/// its faults lose is answered by a [`STATUS_NO_SAMPLE`] marker, which ends the wait at once
/// as a period without a measurement; the wait is bounded by [`LOCKSTEP_REPLY_WAIT_NS`] of
/// wall time only against an emulator that hangs. A measurement without [`STATUS_LOCKSTEP`]
/// (a real device, or an emulator in real time) stops the run, since nothing would then keep
/// the loop's pace.
pub fn exchange(
    io: &Fd,
    core: &mut LoopCore,
    clock: &Periodic,
    tx: &mut [u8; MAX_FRAME],
    rx: &mut [u8],
    reply_timeout_ns: u64,
) -> Result<(u16, Option<Reply>), StopReason> {
    let lockstep = clock.mode() == ClockMode::Lockstep;
    let (seq, n) = core.encode_request(tx);
    let req_ns = clock.now_ns();
    io.write_all(&tx[..n]).map_err(StopReason::DeviceLost)?;
    // Counted from the request, so a late wake-up does not cost a measurement the device
    // answers at once.
    let wall_deadline = if lockstep {
        timing::now_ns() + LOCKSTEP_REPLY_WAIT_NS
    } else {
        (timing::now_ns() + reply_timeout_ns).min(clock.next_deadline_ns())
    };
    loop {
        let now = timing::now_ns();
        if now >= wall_deadline {
            return Ok((seq, None));
        }
        match io.wait_readable(wall_deadline - now) {
            Ok(Readiness::Readable) => {}
            Ok(Readiness::Timeout) => return Ok((seq, None)),
            Ok(Readiness::Interrupted) => continue,
            Err(e) => return Err(StopReason::DeviceLost(e)),
        }
        let got = io.read_available(rx).map_err(StopReason::DeviceLost)?;
        let rx_ns = clock.now_ns();
        if let Some(m) = core.receive(&rx[..got], seq) {
            if lockstep && m.status & STATUS_LOCKSTEP == 0 {
                return Err(StopReason::DeviceLost(std::io::Error::new(
                    std::io::ErrorKind::InvalidData,
                    "--lockstep: the device does not run in lockstep (only \
                     `rip-rt emulate --lockstep` does); run without --lockstep",
                )));
            }
            if m.status & STATUS_NO_SAMPLE != 0 {
                return Ok((seq, None));
            }
            return Ok((seq, Some(Reply { m, req_ns, rx_ns })));
        }
    }
}

//! What one period of the loop produced, as the log records it: the step's output and the log's
//! status bits above the device's own. Plain data, shared by the loop ([`crate::loop_core`])
//! and the log ([`crate::log`]) without either depending on the other.

use rip_core::Phase;

/// Log status bit (above the device's 8 status bits): no measurement arrived this period; the
/// previous command was repeated and the controller, instead of being stepped, was told that
/// the period passed with that command ([`LoopCore::hold`](crate::loop_core::LoopCore::hold)).
pub const FLAG_NO_REPLY: u32 = 1 << 8;
/// Log status bit: the controller used its fallback (e.g. the MPC solver failed).
pub const FLAG_FALLBACK: u32 = 1 << 9;
/// Log status bit: the command is at `±safety.voltage_limit`, saturated by the controller (LQR and
/// LQG saturate, the MPC bounds its moves, at that limit) or clamped by the loop.
pub const FLAG_CLAMPED: u32 = 1 << 10;
/// Log status bit: deadlines were missed (skipped) right before this period.
pub const FLAG_DEADLINE_MISS: u32 = 1 << 11;

/// What one control step produced (see [`LoopCore::control`](crate::loop_core::LoopCore::control)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOutput {
    /// Measured arm angle (rad).
    pub theta: f64,
    /// Measured pendulum angle (rad from upright).
    pub alpha: f64,
    /// Arm reference (rad).
    pub reference: f64,
    /// Commanded voltage after clamping (V).
    pub voltage: f64,
    /// Device status bits and `FLAG_*` bits.
    pub flags: u32,
    /// Bytes of the encoded command frame.
    pub len: usize,
    /// The controller's phase after the step: [`Phase::Balance`] for a balance controller;
    /// a swing-up supervisor reports [`Phase::SwingUp`] until its catch.
    pub phase: Phase,
}

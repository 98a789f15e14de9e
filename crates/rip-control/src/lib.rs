//! The run-time controllers of the rotary inverted pendulum, `no_std` and without `alloc`:
//! LQR with its rate filter, LQG (the steady-state Kalman filter in current form), the
//! constrained MPC step on the condensed QP (a dual active-set solver with warm start and a
//! bounded iteration count), the dead-zone and friction compensation, and the swing-up
//! supervisor around any of them ([`swing`]: the energy law, its arm-limit envelope, the catch
//! and the handover). One source for the host (rip-core), `rip-rt` and the firmware.
//!
//! The design (DARE, Kalman design, condensing) is made on the host by rip-core, which fills a
//! [`Design`]; the host uploads its bytes ([`Design::to_bytes`]); the device reads them into
//! its one controller in place ([`Controller::load`]: a design is tens of kilobytes, which a
//! firmware's stack cannot also hold as a temporary) and runs [`Controller::step`] every
//! period.
//!
//! # Number format
//!
//! Everything is generic over [`Real`] (`f64` or `f32`; `f64` is the default). The host runs
//! `f64`. The Cortex-M4F has a single-precision FPU and emulates `f64` in software, so the
//! chip's choice weighs time against the agreement the tests require (1e-9 V in `f64`, 1 mV in
//! `f32`). Measured on the host over a 15 s nonlinear loop of each preset (rip-core's
//! `tests/onboard.rs`), `f32` keeps the LQR within 60 µV of `f64`, but the estimators drift:
//! the paper's LQG ends 12 V apart and the MPCs 17 V and 8 V (the slow Kalman error modes
//! integrate the round-off). The firmware runs `f32` on its FPU (`ControlLaw<f32, _>` in
//! `firmware/src/main.rs`), and that drift is why its moves are checked against this crate's
//! own `f32` controller on the host, fed the same counts (the processor-in-the-loop check of
//! `firmware/README.md`), not against the host's `f64` run. The bytes always carry `f64`; a
//! `Design<f32>` rounds them once when it reads them. Transcendentals (`exp`, `sqrt`, `pow`)
//! come from `libm` on both sides.
//!
//! # Capacities
//!
//! Fixed arrays, sized for the paper's MPC (P = 50, m = 3, 5 augmented states, one soft
//! output bound: 107 rows; at 1 kHz the same QP with the prediction on a 10 ms grid, rip-core's
//! `prediction_step`) and for a 1 kHz design on a 5 ms grid (P = 100, also 0.5 s):
//! [`MAX_NX`] = 8, [`MAX_NY`] = 2, [`MAX_NU`] = 1, [`MAX_CONTROL_HORIZON`] = 4,
//! [`MAX_PREDICTION_HORIZON`] = 100, so at most [`MAX_NZ`] = 5 QP variables and [`MAX_NCON`] =
//! 409 rows. A [`Controller`] holds its own copy of the design.
//!
//! # LQR
//!
//! The rates of `q ∈ {θ, α}` are the backward difference through a first-order low-pass (the
//! zero-order-hold discretisation of `ω_c / (s + ω_c)`), spanning the `n − 1` periods
//! [held](Controller::hold) since the last angle:
//!
//! ```text
//! d[k] = (q[k] − q[k−n]) / (n Ts),   q̇̂[k] = aⁿ q̇̂[k−n] + (1 − aⁿ) d[k],   a = e^{−2π f_c Ts}
//! u[k] = sat(−K (x̂[k] − x_ref) − k_i x_i[k]),   x_ref = [θ_ref, 0, α_ref, 0]
//! x_i[k+1] = x_i[k] + Ts (θ_ref − θ[k])   unless that deepens a saturation
//! ```
//!
//! With [`Design::cancels_input_disturbance`] the LQR also estimates a disturbance `d` at the
//! plant input (`x[k+1] = A x + B (u + d)`) from how `x̂` departs from the 4-state model's
//! prediction, and cancels it (rip-core's `Lqr` docs give the observer's bandwidth):
//!
//! ```text
//! d̂[k] = d̂[k−1] + g (x̂[k] − x̂⁻[k]),   u[k] = sat(… − d̂[k]),   x̂⁻[k+1] = A x̂[k] + B (u[k] + d̂[k])
//! ```
//!
//! `d̂` is zero after a reset, a seed or an observed sample (bumpless, as the integrator); a
//! held period carries `x̂⁻` over with the model.
//!
//! # Estimator (LQG and MPC)
//!
//! ```text
//! e[k]     = y[k]/s_y − C x̂[k|k−1]
//! x̂[k|k]   = x̂[k|k−1] + M e[k]
//! x̂[k+1|k] = A x̂[k|k−1] + B_u u[k] + L e[k]
//! ```
//!
//! The LQG applies the LQR law to the first four states of `x̂[k|k]`. With
//! [`Design::cancels_input_disturbance`] its estimator's last state is a disturbance `d` at
//! the plant input (`x[k+1] = A x + B (u + d)`, a random walk: what the compensation leaves of
//! a dead zone, friction or breakaway torque), and the law cancels its estimate:
//! `u = −K (x̂ − x_ref) − d̂`.
//! With [`Design::regulates_outputs`] the law acts on the estimated outputs instead of the
//! plant part alone: each angle's state takes on what the estimator's extra states add to that
//! output (`θ̂ + s_θ Σ_{j≥4} C[0,j] x̂_j`), as the MPC's cost does. With the paper's output
//! disturbance, the integrated white noise that the estimator cannot tell from a slow arm
//! motion, the plant part alone drifts with it and carries the arm along; the estimated output
//! does not.
//!
//! # MPC
//!
//! With `x = x̂[k|k]`, `u⁻ = u(k−1)` and a constant reference `r`, the condensed QP over
//! `z = [Δu(k) … Δu(k+m−1), ε]` (rip-core's `mpc` module docs give the cost and rows) is
//!
//! ```text
//! minimise ½ zᵀ H z + fᵀ z   s.t.   A_c z ≤ b
//! f = f0 + F_x x + F_u u⁻ − F_r r,      b = b0 + B_x x + B_u u⁻
//! ```
//!
//! solved by the dual active-set method of the [`qp`] module. The move is
//! `u(k) = sat(u⁻ + Δu(k))`. When the solver hits the design's iteration bound (or fails
//! numerically), the fallback law applies: the unconstrained minimiser `−H⁻¹ f` with its
//! blocked inputs clamped to the bounds; it is reported in [`Move::status`] and counted in
//! [`Stats`]. A discarded measurement applies the previous plan's next move. The iteration
//! bound is what makes the step's time bounded: [`Design::worst_step_instructions_at`] models
//! the worst step on the Cortex-M4F, and [`Design::fitting_iterations`] gives the largest bound
//! that fits half the period (the host uploads no larger one, and the device refuses a design
//! that [`Design::check_step_budget`] rejects).
//!
//! # Compensation
//!
//! `w = v + V_f σ(θ̇̂/ω_s)`, `u = clamp(w + V_d σ(w/v_s), u_min, u_max)`, `σ = clamp(·, −1, 1)`;
//! the law plans within `[u_min + V_d + V_f, u_max − V_d − V_f]` and the estimator is fed `v`.
//!
//! # Byte layout (version 4)
//!
//! Little-endian throughout; every real is an IEEE-754 `f64` (8 bytes); matrices row-major,
//! only their used `rows × cols` entries.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `"RIPD"` |
//! | 4 | 2 | layout version `u16` = 4 (3 lacked flag bit 1) |
//! | 6 | 1 | kind: 1 LQR, 2 LQG, 3 MPC |
//! | 7 | 1 | flags: bit 0 [`Design::cancels_input_disturbance`] (LQR, LQG), bit 1 [`Design::regulates_outputs`] (LQG); the others 0 |
//! | 8 | 4 | total length `u32`, CRC included |
//! | 12 | 8 | `ts` |
//! | 20 | 16 | `input_bounds` `[u_min, u_max]` |
//! | 36 | 32 | compensation `[V_d, V_f, v_s, ω_s]` |
//! | 68 | 32 | `k` (4) |
//! | 100 | 8 | `integral_gain` |
//! | LQR: 108 | 8 | `rate_cutoff_hz` (`+∞` allowed) |
//! | LQR with flag bit 0: 116 | 8·16 + 8·4 + 8·4 | `a` (4×4), `b` (4), `disturbance_gain` (4) |
//! | LQG/MPC: 108 | 2 + 2 | `nx` = n, `ny` (`u16`) |
//! | | 8·n² | `a` |
//! | | 8·n | `b` |
//! | | 8·ny·n | `c` |
//! | | 8·n·ny | `l` |
//! | | 8·n·ny | `m` |
//! | | 8·ny | `output_scales` |
//! | MPC only | 5 × 2 | `P`, `m`, hard input rows, soft rows, `max_iterations` (`u16`); nz = m + 1, ncon = input + soft + 1 |
//! | | 8·nz² | `h` |
//! | | 8·nz | `f0` |
//! | | 8·nz·n | `fx` |
//! | | 8·nz | `fu` |
//! | | 8·nz·ny | `fr` |
//! | | 8·ncon·nz | `ac` |
//! | | 8·ncon | `b0` |
//! | | 8·ncon·n | `bx` |
//! | | 8·ncon | `bu` |
//! | end − 4 | 4 | CRC-32 (IEEE, [`crc32`]) of every byte before it |
//!
//! The paper's MPC (n = 5, P = 50, m = 3, 107 rows) encodes in 10 454 bytes, its LQG in 612
//! and its LQR in 120 (312 with its input-disturbance observer).

#![no_std]
#![forbid(unsafe_code)]
// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

mod controller;
mod design;
pub mod qp;
mod real;
pub mod stop;
pub mod swing;

pub use controller::{Controller, Measurement, Move, Phase, RateFilter, Stats, Status};
pub use design::{
    CompensationDesign, Design, DesignError, Kind, HEADER_LEN, LAYOUT_VERSION, MAGIC,
    MAX_CONTROL_HORIZON, MAX_NCON, MAX_NU, MAX_NX, MAX_NY, MAX_NZ, MAX_PREDICTION_HORIZON,
    MAX_QP_ITERATIONS, NX_PLANT, STEP_BUDGET_INSTRUCTIONS_PER_US,
};
pub use real::Real;
/// CRC-32 (IEEE 802.3) of the design's bytes: the wire protocol's own, so an image checked by
/// the host, the device and the upload frames is checked by one function.
pub use rip_protocol::crc32;

/// The actuator limit (mV): the motor's rated ±12 V, the paper's hard input bound
/// `|u| ≤ 12 V`. The one definition of the number: rip-core's `paper::INPUT_LIMIT` (the default
/// of every clamp on the voltage), the device's default limit and the firmware board's are this.
pub const INPUT_LIMIT_MV: u16 = 12_000;
/// [`INPUT_LIMIT_MV`] in volts.
pub const INPUT_LIMIT: f64 = INPUT_LIMIT_MV as f64 / 1000.0;

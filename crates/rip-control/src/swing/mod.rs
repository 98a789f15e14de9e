//! Swing-up from rest and catch: an energy-pumping law (Åström & Furuta, "Swinging up a
//! pendulum by energy control", Automatica 36(2), 2000) that keeps the arm inside its limit,
//! and a supervisor, [`SwingSupervisor`], that hands over to a balance controller (LQR, LQG or
//! MPC, unchanged; anything that implements [`Balance`]) inside a catch region, bumplessly.
//!
//! This is the per-step part, `no_std` and allocation-free; the design (the derived constants
//! below, the unstable mode, the reference LQR of the predicted catch) is made on the host by
//! rip-core's `swingup` module from its `SwingUpSettings` and the nominal plant, which fill a
//! [`SwingParams`].
//!
//! Conventions are rip-core's plant's: `x = [θ, θ̇, α, α̇]`, α = 0 upright and ±π hanging.
//! Measured angles may be unwrapped or wrapped; the pendulum angle is wrapped to (−π, π]
//! ([`wrap_angle`]) wherever its value, not only its sine and cosine, matters.
//!
//! # Energy pumping (Åström & Furuta, section 3)
//!
//! The pendulum's own energy relative to upright rest is
//!
//! ```text
//! E = ½ J_α α̇² + G (cos α − 1),          J_α = J_p + m_p l_p²/4,   G = m_p g l_p/2
//! ```
//!
//! (`E = 0` upright at rest, `−2G` hanging at rest). From the pendulum's equation of motion
//! ([`ArmModel`]: `J_α α̈ = m₁₂ cos α θ̈ + J_α sin α cos α θ̇² + G sin α − d_p α̇`),
//!
//! ```text
//! dE/dt = m₁₂ cos α α̇ θ̈ + J_α sin α cos α α̇ θ̇² − d_p α̇²
//! ```
//!
//! so the arm acceleration `θ̈` drives the energy with the sign of `α̇ cos α`; the other two terms
//! are second order while the arm moves slowly, and friction is made up for by the feedback.
//! The pumping law (their eq. (8) with a saturated gain) is
//!
//! ```text
//! ε = (E_t(α) − E)/G                                                                   (1)
//! a_pump = a_p · sat(k_E ε) · s(α̇ cos α),   s(v) = sat(v / w), s(0) = 1
//! ```
//!
//! The target is the upright energy raised by a small margin `δ G` plus the viscous loss still
//! to come on the way up: along the homoclinic orbit `½ J_α α̇² = G (1 − cos α)` the pendulum
//! loses `d_p ∫ |α̇| dα` between `α` and upright, so
//!
//! ```text
//! E_t(α) = δ G + D (1 − cos(α/2)),     D = 4 d_p √(G/J_α)                             (1a)
//! ```
//!
//! (`D` is the loss from hanging to upright, α wrapped to (−π, π]). Without it the pendulum
//! arrives short of upright on a damped rig, and a margin `δ` large enough to make up for that
//! brings it over the top too fast to be caught: `D` is 0.35 G on rip-core's `paper` preset
//! and 0.14 G on `qube_servo2`.
//!
//! With `a_pump` in place of `θ̈`, `dE/dt = m₁₂ a_p sat(k_E ε) |α̇ cos α| s(·)/… ≥ 0` while
//! `E < E_t` and `≤ 0` above it: `E → E_t`, the homoclinic orbit through upright (raised by a
//! small margin `δ` so that the pendulum reaches upright in finite time). `s(0) = 1` starts a
//! pendulum that hangs perfectly still. `a_p` is a fraction of the stall acceleration
//! `a_s = (k_t/R_m) U / (J₀ + J_α)` (rip-core's `SwingUpSettings`).
//!
//! # Keeping the arm centred and inside its limit
//!
//! A critically damped spring pulls the arm towards 0 (the middle of its travel):
//! `a_c = −ω_c² θ − 2 ω_c θ̇`, and `a_w = a_pump + a_c` is the wanted acceleration.
//!
//! The arm limit `θ_L` is enforced by a braking envelope (a control-barrier function). With a
//! deceleration `a_b` kept in reserve, the arm can still stop before `+θ_L` exactly when
//!
//! ```text
//! h⁺ = v⁺(θ) − θ̇ ≥ 0,     v⁺(θ) = √(2 a_b (θ_L − θ)⁺)                                  (2)
//! ```
//!
//! (`v⁺` is the speed from which braking at `a_b` stops at `θ_L`, [`envelope_speed`]). Along
//! the boundary `θ̇ = v⁺`, `dv⁺/dt = −a_b θ̇ / v⁺ = −a_b`. Requiring `dh⁺/dt ≥ −λ h⁺` gives
//! the upper bound
//!
//! ```text
//! θ̈ ≤ a_hi = λ (v⁺ − θ̇) − a_b · clamp(θ̇ / v⁺, 0, 1)                                    (3)
//! ```
//!
//! (the factor is `θ̇/v⁺` inside the envelope, where it is exact, and capped at 1 outside, where
//! the `λ` term already brakes harder; it is 0 while the arm moves away from the limit). The
//! mirror image gives `θ̈ ≥ a_lo = −λ (v⁻ + θ̇) + a_b · clamp(−θ̇ / v⁻, 0, 1)`,
//! `v⁻ = √(2 a_b (θ_L + θ)⁺)`. The law applies `a = clamp(a_w, a_lo, a_hi)`. Far from the
//! limits the bounds are loose and the pumping acts unchanged; near one they dominate.
//! If `θ̈ = a` is achieved, `h⁺ ≥ 0` and `h⁻ ≥ 0` are invariant (Nagumo / comparison lemma on
//! `ḣ ≥ −λh`) and, as `v^± → 0` at `±θ_L`, `|θ| ≤ θ_L` for all time from any start inside the
//! envelope (an arm at rest inside the limit is inside it). The envelope's `θ_L`
//! ([`SwingParams::envelope_limit`]) is the arm limit less one period at the envelope's top
//! speed `√(2 a_b θ_L)` (at least 0.05 rad), because the loop samples and the rig is not the
//! model.
//!
//! `θ̈ = a` is achieved as long as the voltage it needs stays within `±U`: the law inverts the
//! nominal equations of motion, which are affine in `u`,
//!
//! ```text
//! u = (a − θ̈(x, 0)) / (θ̈(x, 1) − θ̈(x, 0)),   clamped to ±U                                (4)
//! ```
//!
//! on the model's smooth part ([`ArmModel`]: no dead zone, no Coulomb friction): the voltage
//! `v` the smooth model needs, which the compensation (applied around the whole supervisor)
//! turns into the voltage the rig needs. Inverting the dead zone here instead would divide by
//! its slope, which is 0 at rest when `V_d ≥ 1 V`.
//!
//! At the boundary `a = −a_b` with `a_b = 0.5 a_s` by default: half the stall acceleration is
//! kept for back-EMF at the envelope's top speed `√(4 a_b θ_L)`, the pendulum's reaction on the
//! arm and ±10 % model error. rip-core's simulation tests check `|θ| ≤ θ_L` over perturbed
//! plants.
//!
//! # Last rise (opt-in)
//!
//! The pumping leaves the arm turning when the pendulum arrives, so the catch starts with the
//! arm's rate to stop as well as the pendulum's. With [`SwingParams::rise_damping`] `k_r > 0`
//! the arm is stopped on the way up instead. A torque on the arm alone changes the rates in
//! the ratio `Δα̇/Δθ̇ = −M₁₂/M₂₂ = r` (the mass matrix `M` of the equations of motion;
//! `r = Δα̈/Δθ̈` between two voltages), so stopping the arm leaves the pendulum with
//!
//! ```text
//! E' = ½ J_α (α̇ − r θ̇)² + G (cos α − 1)                                               (5)
//! ```
//!
//! and `α̇ − r θ̇ = p_α / M₂₂` (the pendulum's generalised momentum) does not depend on `θ̈` at
//! all: braking changes `E'` only through the arm's rate, which it takes to 0. The law then
//! regulates `E'` instead of `E` in (1), and on the last rise (the pendulum in the upper half,
//! `cos α > 0`, moving towards upright, `α α̇ < 0`, with `|k_E ε| < 1`) replaces the centring
//! spring by `a_c = −k_r θ̇`: the arm comes to rest while the pendulum arrives with the energy
//! of (1a). The barrier (3) bounds it as before.
//!
//! # Supervisor and catch
//!
//! [`SwingSupervisor`] drives a balance controller and moves through [`SwingPhase`]s:
//!
//! - **SwingUp**: applies (1)–(4) on its own estimate (angles and filtered differences,
//!   [`SwingParams::rate_cutoff_hz`], the filter of the LQR's rates with the pendulum's
//!   difference wrapped, so that a wrapped encoder's jump of 2π changes nothing). The balance
//!   controller follows along: within [`SwingParams::estimator_window`] of upright its
//!   estimator runs on the measurements and the applied voltage ([`Balance::observe`]);
//!   further out, where its linear model does not hold, it is restarted every sample from the
//!   swing-up's estimate ([`Balance::seed`]). The MPC's previous move is therefore the
//!   swing-up's last voltage.
//! - **catch** when `|α| ≤ catch_angle`, `|α̇| ≤ catch_rate`, `|θ̇| ≤ catch_arm_rate`, the
//!   arm's stopping point is within `catch_arm_angle`, and the upright's unstable mode is small
//!   enough for the voltage bound: with the nominal model linearised about upright,
//!   `ẋ = A x + b u`, and `wᵀ A = λ wᵀ` (`λ > 0`, `w_α = 1`), `z = wᵀ x` obeys
//!   `ż = λ z + (wᵀ b) u`, which `|u| ≤ U` can return to 0 only while `|z| < |wᵀ b| U / λ`;
//!   the catch needs `|z| ≤ catch_mode_fraction · |wᵀ b| U / λ` ([`UnstableMode`]). A
//!   pendulum that is close to upright but falling away from it (or rising too fast) is not
//!   caught. The balance controller computes the move of that same sample. The arm reference
//!   starts at the arm's angle at the catch, `θ_c` (a step from there to the external
//!   reference would be a step of up to `catch_arm_angle` on top of any the user asks for),
//!   and moves back to the external reference at [`SwingParams::reference_return_rate`] (0 by
//!   default: held there) until the external reference changes from the value it had at the
//!   catch. A change that comes while the way back is still going (a return rate above 0)
//!   moves the reference towards the new value by at most the change itself, and what is
//!   left goes on at the return rate: passed through at once, the change would carry the
//!   arm's remaining offset with it (a 1 rad step 1 s after a catch at −0.37 rad became a
//!   1.37 rad step and threw an LQG's pendulum out of the balance region). Once back, or with
//!   the reference held (rate 0), the external reference is passed through from that change
//!   on (so a later 0 → 1 rad step is tracked as given).
//! - **Predicted catch** (opt-in, [`SwingParams::prediction`]): the fixed arm windows
//!   (`catch_arm_rate`, `catch_arm_angle`) are replaced by a prediction. From the swing-up's
//!   estimate `x`, the nominal model without dead zone and Coulomb friction is simulated (RK4)
//!   over the prediction horizon under a reference LQR holding the arm where it is,
//!
//!   ```text
//!   u_k = sat_U(−K (x_k − [θ_c, 0, 0, 0]ᵀ)),   K = dlqr(A_d, b_d, diag(25, 0, 50, 0), 0.1)
//!   ```
//!
//!   (`A_d, b_d` the upright linearisation sampled at `T_s`; rip-core's `[lqr]` section's
//!   default weights), and the state is caught when every predicted sample keeps
//!   `|α_k| ≤ balance_angle − m` and both `|θ_k|` and the arm's stopping point braked at the
//!   bound within `arm_limit − m` (`m` the catch margin; [`CatchPrediction`]). It is the part
//!   of the LQR's region of attraction that respects the balance region, found by simulation
//!   instead of a level set, so an arm that is off centre or still turning is caught when the
//!   balance controller can stop it in time, and not otherwise. The prediction runs only on
//!   samples that meet the pendulum's conditions (a few per arrival) and allocates nothing.
//! - **Balance**: the balance controller runs on `[θ, wrap(α)]`. For
//!   [`SwingParams::handover_time`] after the catch its estimator is restarted every sample,
//!   after it has computed its move, from the swing-up's estimate and that move
//!   ([`Balance::seed`]), so a Kalman filter does not have to follow the catch transient,
//!   which its linear model does not describe. Leaving the balance region is a fall: swing up
//!   again or stop ([`OnFall`]). The region ends at `|α| > balance_angle` and where the arm's
//!   stopping point, braked at the voltage bound ([`StoppingModel::stopping_point`], one
//!   period of latency with the balance controller's last voltage acting, the whole
//!   deceleration counted on), leaves `±arm_limit`, not only at `|θ| > arm_limit`: an arm that
//!   reaches the limit still moving cannot be stopped there, while one handed to the swing-up
//!   law with its stopping point inside is braked by the law's barrier (3), which asks for
//!   more than the voltage bound gives outside its own envelope, so it brakes at the bound.
//! - **Stopped** ([`SwingStop`]): after [`SwingParams::max_time`] in the swing-up, or a fall
//!   with [`OnFall::Stop`]. The output is 0 V from then on.
//!
//! # Planned swing-up (opt-in)
//!
//! Given a plan (rip-core's `swingup::plan`: a trajectory from hanging to upright at rest on
//! the nominal model, one [`PlanPoint`] per period, with the time-varying LQR gain that tracks
//! it), a swing-up that starts from hanging (its first sample within [`PLAN_START_ANGLE`] of
//! hanging, and its rates within [`PLAN_START_RATE`] of the plan's over the first
//! [`PLAN_SETTLE_SAMPLES`]: the estimate has no rate at its first sample) follows it instead of
//! pumping: at its `k`-th period
//!
//! ```text
//! u = sat_U(u_k − K_k (x − x_k)),   the pendulum's error wrapped,
//! ```
//!
//! `u_k` alone on a period without a usable measurement. `k` is the plan's clock, one sample
//! per period, held ones included, **retimed** on each measured period: of the points within
//! [`PLAN_RETIME_SAMPLES`] of the clock, the one nearest the measured pendulum in its phase
//! plane is followed,
//!
//! ```text
//! k ← argmin_{|j − k| ≤ 1} (α − α_j)² + (J_α/G)(α̇ − α̇_j)²
//! ```
//!
//! (the rate's error scaled by the pendulum's own time constant `√(J_α/G)`; the clock's own
//! point where none is strictly nearer), so the plan runs at 0, 1 or 2 samples per period. A rig whose pendulum swings
//! faster or slower than the nominal model's drifts from a plan timed by the clock alone, and
//! the tracking law then pulls it back to the plan's time against its own swing, swing after
//! swing; retimed, the law tracks the plan's path at the pendulum's own pace (a path
//! following in place of a trajectory following; the transverse-dynamics view of orbit
//! stabilisation, Shiriaev, Perram & Canudas-de-Wit, IEEE TAC 50(8), 2005). Under ±10 % model
//! error on the tuned `paper` preset (1 000 runs, LQR) the retimed plan is caught on the
//! first arrival in 83.5 % of runs (74.4 % by the clock) and passes over the top at most
//! twice in 99.5 % (96.8 %); `qube_servo2`'s one-swing plan goes from 89.5 to 90.7 % on the
//! first arrival. It is not retimed over its first [`PLAN_SETTLE_SAMPLES`], where its rates
//! are checked, nor at its last point, and it is left for the energy law once it is more than
//! [`PLAN_MAX_LAG_SHARE`] of its length behind its clock. The catch is tested only once the plan's pendulum is within `catch_angle` of
//! upright (the plan carries it there; a catch tested earlier would take an arrival the plan
//! is not yet braking for). The plan is left for the energy law when the estimate strays from
//! it (pendulum or arm more than [`PLAN_ABORT_ANGLE`] off), when the arm passes the envelope's
//! limit `θ_L`, or when the arm's stopping point braked at `a_b` is past `θ_L` and more than
//! [`PLAN_ABORT_ANGLE`] from the plan's own (the plan brakes the arm harder than
//! `a_b`: its own stopping point by `a_b` may lie past the limit while the plan stays inside
//! it). The envelope's barrier (3) holds only from states inside the envelope, and a plan left
//! while the arm's stopping point at `a_b` is past the limit leaves it outside: the arm is then
//! braked with the whole bound, `u = −U sgn θ̇`, until that stopping point is back inside or
//! the arm turns back, and the energy law takes over from there. At the plan's end the energy
//! law or the catch takes over. A swing-up after a fall, or from anywhere else, pumps.
//!
//! Every step is allocation-free (the crate has no allocator); its time is bounded by the
//! predicted catch's horizon, [`CatchPrediction::steps`] RK4 samples.

use crate::controller::{Controller, Measurement, Status};
use crate::design::{MAX_NY, NX_PLANT};
use crate::real::Real;

#[inline]
fn c<R: Real>(v: f64) -> R {
    R::from_f64(v)
}

/// `a` wrapped to (−π, π]: the one angle wrap of the plant, the simulation, the swing-up,
/// `rip-rt` and the firmware.
///
/// ```text
/// w = a − 2π round(a / 2π),   w + 2π if w ≤ −π
/// ```
#[inline]
pub fn wrap_angle<R: Real>(a: R) -> R {
    let pi: R = c(core::f64::consts::PI);
    let tau: R = c(core::f64::consts::TAU);
    let w = a - tau * (a / tau).round();
    if w <= -pi {
        w + tau
    } else {
        w
    }
}

/// The speed (rad/s) from which a constant deceleration `a_b` (rad/s²) stops within `room`
/// (rad): `√(2 a_b room⁺)`, the envelope (2) of the module docs.
#[inline]
pub fn envelope_speed<R: Real>(a_b: R, room: R) -> R {
    // `room > 0` rather than `max`: a NaN room gives 0 as `f64::max` would.
    let room = if room > R::ZERO { room } else { R::ZERO };
    (c::<R>(2.0) * a_b * room).sqrt()
}

mod law;
mod model;
mod supervisor;

pub use crate::stop::StoppingModel;
pub use law::*;
pub use model::*;
pub use supervisor::*;

#[cfg(test)]
mod retime_tests;
#[cfg(test)]
pub(crate) mod tests;

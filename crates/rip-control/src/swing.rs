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
//!   catch; from that change on the external reference is passed through (so a later
//!   0 → 1 rad step is tracked as given, from the arm's place rather than from `θ_c`).
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

/// The smooth part of the nominal equations of motion (no dead zone, no Coulomb friction):
/// rip-core's plant model with its lumped coefficients,
///
/// ```text
/// M(α) q̈ = f(x, u),   q = (θ, α)
/// M₁₁ = J₀ + J_α sin²α,   M₁₂ = −m₁₂ cos α,   M₂₂ = J_α
/// f₁ = b u − c θ̇ − 2 J_α sin α cos α θ̇ α̇ − m₁₂ sin α α̇²
/// f₂ = −d_p α̇ + J_α sin α cos α θ̇² + G sin α
/// ```
///
/// `θ̈` is affine in `u`, which the law's voltage (4) inverts, and RK4 on it is the predicted
/// catch's simulation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmModel<R: Real = f64> {
    /// `J₀ = J_r + m_r l_r²/4 + m_p l_r²` (kg·m²), the arm's inertia with the pendulum along it.
    pub j0: R,
    /// `J_α = J_p + m_p l_p²/4` (kg·m²), the pendulum's inertia about its joint.
    pub ja: R,
    /// `m₁₂ = m_p l_r l_p / 2` (kg·m²).
    pub m12: R,
    /// `G = m_p g l_p / 2` (N·m).
    pub grav: R,
    /// `b = k_t / R_m` (N·m/V).
    pub b: R,
    /// `c = d_r + k_t k_m / R_m` (N·m·s/rad): viscous friction and back-EMF of the arm.
    pub c_arm: R,
    /// `d_p` (N·m·s/rad), the pendulum joint's viscous friction.
    pub dp: R,
}

impl<R: Real> ArmModel<R> {
    /// `(θ̈, α̈)` at `x` with `u` (V).
    #[inline]
    pub fn accelerations(&self, x: &[R; 4], u: R) -> [R; 2] {
        let (s, co) = (x[2].sin(), x[2].cos());
        let (td, ad) = (x[1], x[3]);
        let ja = self.ja;
        let two: R = c(2.0);
        let m11 = self.j0 + ja * s * s;
        let m12 = -self.m12 * co;
        let m22 = ja;
        let f1 =
            self.b * u - self.c_arm * td - two * ja * s * co * td * ad - self.m12 * s * ad * ad;
        let f2 = -self.dp * ad + ja * s * co * td * td + self.grav * s;
        let det = m11 * m22 - m12 * m12;
        [(m22 * f1 - m12 * f2) / det, (m11 * f2 - m12 * f1) / det]
    }

    /// `ẋ` at `x` with `u` (V).
    #[inline]
    pub fn derivative(&self, x: &[R; 4], u: R) -> [R; 4] {
        let [thdd, addd] = self.accelerations(x, u);
        [x[1], thdd, x[3], addd]
    }

    /// Advances `x` by `dt` (s) with `substeps` (at least 1) classical RK4 steps, `u` held.
    pub fn advance(&self, x: &mut [R; 4], u: R, dt: R, substeps: u32) {
        let n = substeps.max(1);
        let h = dt / c(f64::from(n));
        let half: R = c(0.5);
        let shifted = |x: &[R; 4], k: &[R; 4], a: R| -> [R; 4] {
            [
                x[0] + k[0] * a,
                x[1] + k[1] * a,
                x[2] + k[2] * a,
                x[3] + k[3] * a,
            ]
        };
        for _ in 0..n {
            let k1 = self.derivative(x, u);
            let k2 = self.derivative(&shifted(x, &k1, half * h), u);
            let k3 = self.derivative(&shifted(x, &k2, half * h), u);
            let k4 = self.derivative(&shifted(x, &k3, h), u);
            let w = h / c(6.0);
            for i in 0..4 {
                x[i] += (k1[i] + (k2[i] + k3[i]) * c(2.0) + k4[i]) * w;
            }
        }
    }
}

/// The arm's stopping model: how far the arm still travels when braked at the voltage bound
/// (rip-core's `envelope` module docs derive it),
///
/// ```text
/// d(ω) = ω / k − (a₀ / k²) ln(1 + k ω / a₀)                   (→ ω² / (2 a₀) as k → 0)
/// D(ω, u_a) = ω τ + ½ a_l τ² + d(ω + a_l τ),   a_l = (b / J_min) clamp(u_a, 0, U)
/// ```
///
/// with `u_a` the voltage acting along the motion during the latency `τ`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StoppingModel<R: Real = f64> {
    /// `a₀ = f b U / J` (rad/s²).
    pub a0: R,
    /// `k = f c / J` (1/s).
    pub k: R,
    /// `b / J_min` (rad/s² per V), the drive's acceleration per volt at the least inertia.
    pub drive_per_volt: R,
    /// `τ` (s).
    pub latency: R,
    /// The voltage bound `U` (V).
    pub voltage: R,
}

impl<R: Real> StoppingModel<R> {
    /// The braking distance `d(ω)` from speed `omega` (rad/s, its magnitude is used), without
    /// the latency.
    pub fn braking_distance(&self, omega: R) -> R {
        let w = omega.abs();
        let x = self.k * w / self.a0;
        if x < c(1e-6) {
            // The series of d: ω²/(2a₀) (1 − (2/3) x + …).
            w * w / (c::<R>(2.0) * self.a0) * (R::ONE - c::<R>(2.0) * x / c(3.0))
        } else {
            w / self.k - self.a0 / (self.k * self.k) * x.ln_1p()
        }
    }

    /// The stopping distance `D(ω, u_a)` (rad), latency included, with `along` (V) the
    /// voltage applied along the motion during the latency (clamped to `[0, U]`).
    pub fn stopping_distance_with(&self, omega: R, along: R) -> R {
        let w = omega.abs();
        let tau = self.latency;
        let a = self.drive_per_volt * along.clamp(R::ZERO, self.voltage);
        w * tau + c::<R>(0.5) * a * tau * tau + self.braking_distance(w + a * tau)
    }

    /// Where the arm at `theta` moving at `rate` stops with `applied` (V) acting during the
    /// latency: `θ + sgn(θ̇) D(|θ̇|, sgn(θ̇) u_a)`.
    pub fn stopping_point(&self, theta: R, rate: R, applied: R) -> R {
        let along = if rate >= R::ZERO { applied } else { -applied };
        theta + rate.signum() * self.stopping_distance_with(rate, along)
    }
}

/// The unstable mode of the nominal model linearised about upright (module docs, "catch"):
/// `z = wᵀ x` with `wᵀ A = λ wᵀ`, `λ > 0`, `w_α = 1`, which `|u| ≤ U` can bring back to 0
/// exactly while `|z| < |wᵀ b| U / λ`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct UnstableMode<R: Real = f64> {
    /// The left eigenvector `w`, normalised to `w_α = 1`.
    pub w: [R; 4],
    /// `|wᵀ b| U / λ`, the largest `|z|` the voltage bound recovers.
    pub recoverable: R,
}

impl<R: Real> UnstableMode<R> {
    /// `|wᵀ x| / (|wᵀ b| U / λ)` (α wrapped): below 1 the voltage bound can still stop the fall.
    #[inline]
    pub fn load(&self, x: &[R; 4]) -> R {
        let z = self.w[0] * x[0] + self.w[1] * x[1] + self.w[2] * x[2] + self.w[3] * x[3];
        z.abs() / self.recoverable
    }
}

/// The predicted catch (module docs, "Predicted catch"): the nominal closed loop under the
/// reference LQR `K`, simulated [`steps`](Self::steps) samples ahead.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CatchPrediction<R: Real = f64> {
    /// The reference LQR's gain on `x − [θ_c, 0, 0, 0]`.
    pub k: [R; 4],
    /// Samples predicted: `⌈horizon / T_s⌉`.
    pub steps: u32,
    /// RK4 substeps per sample.
    pub substeps: u32,
    /// `arm_limit − m` (rad): where the predicted arm and its stopping point must stay.
    pub arm_room: R,
    /// `balance_angle − m` (rad): where the predicted pendulum must stay.
    pub pendulum_room: R,
    /// The stopping model of the smooth nominal plant, latency one period, the whole
    /// deceleration counted on.
    pub stopping: StoppingModel<R>,
}

impl<R: Real> CatchPrediction<R> {
    /// Whether the reference LQR on `model` (period `ts`, inputs within `±u_max`), holding the
    /// arm at `theta_ref` from `x` (α wrapped), keeps `|α|` within `pendulum_room` and the arm
    /// and its stopping point within `arm_room` over the horizon.
    pub fn recoverable(
        &self,
        model: &ArmModel<R>,
        ts: R,
        u_max: R,
        x: &[R; 4],
        theta_ref: R,
    ) -> bool {
        let mut x = *x;
        for _ in 0..self.steps {
            let e = [x[0] - theta_ref, x[1], x[2], x[3]];
            let v = -(self.k[0] * e[0] + self.k[1] * e[1] + self.k[2] * e[2] + self.k[3] * e[3]);
            let u = v.clamp(-u_max, u_max);
            let stop = self.stopping.stopping_point(x[0], x[1], u);
            if !(x[2].abs() <= self.pendulum_room
                && x[0].abs() <= self.arm_room
                && stop.abs() <= self.arm_room)
            {
                return false;
            }
            model.advance(&mut x, u, ts, self.substeps);
        }
        true
    }
}

/// What the supervisor does when the pendulum leaves the balance region after a catch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OnFall {
    /// Swing up again (the swing-up clock restarts).
    #[default]
    Retry,
    /// Stop with [`SwingStop::LeftBalanceRegion`] and 0 V.
    Stop,
}

/// The swing-up's parameters: plain numbers, filled on the host from the settings and the
/// nominal plant (rip-core's `swingup` module), every one the symbol of the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SwingParams<R: Real = f64> {
    /// Sample time `T_s` (s), the balance controller's.
    pub ts: R,
    /// The smooth nominal model the voltage (4) inverts; `J_α` and `G` of the energy are its.
    pub model: ArmModel<R>,
    /// `U` (V): the largest voltage the swing-up applies.
    pub max_voltage: R,
    /// `δ G` (J): the target energy at upright.
    pub upright_target: R,
    /// `D = 4 d_p √(G/J_α)` (J): the viscous loss from hanging to upright, (1a).
    pub dissipation: R,
    /// `a_p` (rad/s²), the pumping acceleration.
    pub pump: R,
    /// `a_b` (rad/s²), the deceleration the envelope reserves.
    pub brake: R,
    /// `k_E`, the energy gain of (1).
    pub energy_gain: R,
    /// `w` (rad/s), the width of the smoothed sign `s`.
    pub pump_width: R,
    /// `ω_c` (rad/s), the centring spring's.
    pub arm_centering: R,
    /// `k_r` (1/s), the last rise's arm damping; 0 off.
    pub rise_damping: R,
    /// `λ` (1/s), the barrier's rate.
    pub barrier_rate: R,
    /// `θ_L` of the envelope (rad): the arm limit less the sampling margin.
    pub envelope_limit: R,
    /// `f_c` (Hz) of the swing-up's rate filter.
    pub rate_cutoff_hz: R,
    /// `|α|` (rad) within which the balance estimator runs on the measurements.
    pub estimator_window: R,
    /// Catch: largest `|α|` (rad), also of `α + α̇ · catch_lookahead`.
    pub catch_angle: R,
    /// Catch: the look-ahead (s) of the pendulum angle.
    pub catch_lookahead: R,
    /// Catch: largest share of the recoverable unstable mode.
    pub catch_mode_fraction: R,
    /// Catch: largest `|α̇|` (rad/s).
    pub catch_rate: R,
    /// Catch without prediction: largest `|θ̇|` (rad/s).
    pub catch_arm_rate: R,
    /// Catch without prediction: largest `|θ + θ̇|θ̇|/(2 a_b)|` (rad).
    pub catch_arm_angle: R,
    /// The upright's unstable mode.
    pub mode: UnstableMode<R>,
    /// The predicted catch, in place of the fixed arm windows; `None` off.
    pub prediction: Option<CatchPrediction<R>>,
    /// Balance region: largest `|α|` (rad).
    pub balance_angle: R,
    /// Balance region: largest `|θ|` and arm stopping point (rad).
    pub arm_limit: R,
    /// The arm's stopping model of the balance region.
    pub stopping: StoppingModel<R>,
    /// Time (s) after the catch during which the balance estimator is seeded.
    pub handover_time: R,
    /// Rate (rad/s) at which the held arm reference returns to the external one.
    pub reference_return_rate: R,
    /// Longest swing-up (s).
    pub max_time: R,
    /// What a fall does.
    pub on_fall: OnFall,
}

/// The share `clamp(v / v_env, 0, 1)` of the braking deceleration the envelope's boundary
/// needs at speed `v` towards a limit whose envelope speed is `v_env` (module docs, (3)).
#[inline]
fn toward<R: Real>(v: R, v_env: R) -> R {
    if v <= R::ZERO {
        R::ZERO
    } else if v >= v_env {
        R::ONE
    } else {
        v / v_env
    }
}

impl<R: Real> SwingParams<R> {
    /// The pendulum's own energy relative to upright rest, `E = ½ J_α α̇² + G (cos α − 1)` (J).
    #[inline]
    pub fn energy(&self, x: &[R; 4]) -> R {
        let m = &self.model;
        c::<R>(0.5) * m.ja * x[3] * x[3] + m.grav * (x[2].cos() - R::ONE)
    }

    /// The pendulum's energy once an impulse on the arm has stopped it, (5):
    /// `E' = ½ J_α (α̇ − r θ̇)² + G (cos α − 1)`, `r = Δα̈/Δθ̈` between two voltages.
    pub fn stopped_energy(&self, x: &[R; 4]) -> R {
        // A change of voltage is a torque on the arm alone, so two evaluations of the
        // equations of motion give r = −M₁₂/M₂₂, as `voltage` inverts them.
        let d0 = self.model.accelerations(x, R::ZERO);
        let d1 = self.model.accelerations(x, R::ONE);
        let ratio = (d1[1] - d0[1]) / (d1[0] - d0[0]);
        if !ratio.is_finite() {
            return self.energy(x);
        }
        let rate = x[3] - ratio * x[1];
        let m = &self.model;
        c::<R>(0.5) * m.ja * rate * rate + m.grav * (x[2].cos() - R::ONE)
    }

    /// The target energy (J) at pendulum angle `alpha` (wrapped), (1a):
    /// `E_t(α) = δ G + D (1 − cos(α/2))`.
    #[inline]
    pub fn target(&self, alpha: R) -> R {
        self.upright_target + self.dissipation * (R::ONE - (c::<R>(0.5) * alpha).cos())
    }

    /// The arm acceleration (rad/s²) the law asks for at `x` (α wrapped): the pumping (1), the
    /// centring spring or the last rise's damping, clamped to the envelope's bounds (3).
    pub fn acceleration(&self, x: &[R; 4]) -> R {
        let (theta, theta_dot, alpha, alpha_dot) = (x[0], x[1], x[2], x[3]);
        let rising = self.rise_damping > R::ZERO;
        // With the last-rise brake the arm is stopped before the catch, and what the pendulum
        // then has is its energy once the arm is at rest (module docs, "Last rise").
        let energy = if rising {
            self.stopped_energy(x)
        } else {
            self.energy(x)
        };
        let eps = (self.target(alpha) - energy) / self.model.grav;
        let v = alpha_dot * alpha.cos();
        // At exact rest (a quantised, noise-free reading of a still pendulum) v is 0 and a
        // smoothed sign would never start the swing: push one way until it moves.
        let sign = if v == R::ZERO {
            R::ONE
        } else {
            (v / self.pump_width).clamp(-R::ONE, R::ONE)
        };
        let drive = self.energy_gain * eps;
        let pump = self.pump * drive.clamp(-R::ONE, R::ONE) * sign;
        let last_rise =
            alpha.cos() > R::ZERO && alpha * alpha_dot < R::ZERO && drive.abs() < R::ONE && rising;
        let wc = self.arm_centering;
        let centre = if last_rise {
            -self.rise_damping * theta_dot
        } else {
            -wc * wc * theta - c::<R>(2.0) * wc * theta_dot
        };
        let wanted = pump + centre;
        let b = self.brake;
        let lambda = self.barrier_rate;
        let v_up = envelope_speed(b, self.envelope_limit - theta);
        let v_down = envelope_speed(b, self.envelope_limit + theta);
        let hi = lambda * (v_up - theta_dot) - b * toward(theta_dot, v_up);
        let lo = -lambda * (v_down + theta_dot) + b * toward(-theta_dot, v_down);
        if lo <= hi {
            wanted.clamp(lo, hi)
        } else {
            // Outside the envelope on both sides at once: only possible beyond a limit tighter
            // than one braking distance; split the difference.
            c::<R>(0.5) * (lo + hi)
        }
    }

    /// The voltage (V) that gives the arm acceleration `a` at `x` on the smooth model, (4),
    /// clamped to `±U`; 0 where the inversion is not finite.
    pub fn voltage(&self, x: &[R; 4], a: R) -> R {
        let at_zero = self.model.accelerations(x, R::ZERO)[0];
        let per_volt = self.model.accelerations(x, R::ONE)[0] - at_zero;
        let u = (a - at_zero) / per_volt;
        if u.is_finite() {
            u.clamp(-self.max_voltage, self.max_voltage)
        } else {
            R::ZERO
        }
    }

    /// Whether the estimate `x` is in the catch region (module docs, "catch").
    pub fn in_catch_region(&self, x: &[R; 4]) -> bool {
        let arm_stop = x[0] + x[1] * x[1].abs() / (c::<R>(2.0) * self.brake);
        let pendulum = x[2].abs() <= self.catch_angle
            && self.mode.load(x) <= self.catch_mode_fraction
            && (x[2] + x[3] * self.catch_lookahead).abs() <= self.catch_angle
            && x[3].abs() <= self.catch_rate;
        pendulum
            && match &self.prediction {
                Some(p) => p.recoverable(&self.model, self.ts, self.max_voltage, x, x[0]),
                None => x[1].abs() <= self.catch_arm_rate && arm_stop.abs() <= self.catch_arm_angle,
            }
    }

    /// Whether the estimate `x` is in the balance region, with `applied` (V) the balance
    /// controller's last voltage acting during the stop's latency (module docs, "Balance").
    pub fn in_balance_region(&self, x: &[R; 4], applied: R) -> bool {
        let limit = self.arm_limit;
        let stop = self.stopping.stopping_point(x[0], x[1], applied);
        x[2].abs() <= self.balance_angle && x[0].abs() <= limit && stop.abs() <= limit
    }
}

/// The swing-up's own estimate: angles and filtered-difference rates `[θ, θ̇, α, α̇]`, α
/// wrapped; the LQR's rate filter (crate docs, "LQR") with the pendulum's difference wrapped.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SwingRates<R: Real> {
    ts: R,
    a: R,
    x: [R; 4],
    started: bool,
    held: u32,
}

impl<R: Real> SwingRates<R> {
    fn new(ts: R, cutoff_hz: R) -> Self {
        let two_pi: R = c(2.0 * core::f64::consts::PI);
        Self {
            ts,
            a: (-(two_pi * cutoff_hz * ts)).exp(),
            x: [R::ZERO; 4],
            started: false,
            held: 0,
        }
    }

    /// Takes the angles `[θ, α]`; `false` (estimate kept, the period counted as held) when
    /// they are not finite.
    fn update(&mut self, y: [R; 2]) -> bool {
        if !(y[0].is_finite() && y[1].is_finite()) {
            self.hold();
            return false;
        }
        let alpha = wrap_angle(y[1]);
        if self.started {
            let periods = self.held.saturating_add(1);
            let dt = c::<R>(f64::from(periods)) * self.ts;
            let a = self.a.powu(periods);
            let d_theta = (y[0] - self.x[0]) / dt;
            let d_alpha = wrap_angle(alpha - self.x[2]) / dt;
            self.x[1] = a * self.x[1] + (R::ONE - a) * d_theta;
            self.x[3] = a * self.x[3] + (R::ONE - a) * d_alpha;
        } else {
            self.started = true;
        }
        self.held = 0;
        self.x[0] = y[0];
        self.x[2] = alpha;
        true
    }

    fn hold(&mut self) {
        if self.started {
            self.held = self.held.saturating_add(1);
        }
    }

    fn reset(&mut self) {
        self.x = [R::ZERO; 4];
        self.started = false;
        self.held = 0;
    }
}

/// The balance controller the supervisor hands over to: what [`SwingSupervisor`] needs of
/// it. rip-control's [`Controller`] implements it; rip-core adapts its own controllers.
pub trait Balance<R: Real> {
    /// What a balance step reports, passed through in [`SwingStatus::Balance`].
    type Status;
    /// One balance sample on the angles `[θ, α]` (α wrapped) and the reference `[θ_ref,
    /// α_ref]`: the voltage written and the step's status.
    fn step(&mut self, angles: [R; 2], reference: [R; 2]) -> (R, Self::Status);
    /// A sample whose voltage `u` the swing-up chose: the estimator runs on `angles`.
    fn observe(&mut self, angles: [R; 2], u: R);
    /// Restarts the estimator at the plant state `x` with `u` the voltage just written.
    fn seed(&mut self, x: [R; 4], u: R);
    /// A period without a measurement, the plant receiving `u`.
    fn hold(&mut self, u: R);
    /// Back to the initial state.
    fn reset(&mut self);
}

impl<R: Real> Balance<R> for Controller<R> {
    type Status = Status;

    fn step(&mut self, angles: [R; 2], reference: [R; 2]) -> (R, Status) {
        let mut m = Measurement {
            angles: [R::ZERO; MAX_NY],
            reference: [R::ZERO; MAX_NY],
        };
        m.angles[..2].copy_from_slice(&angles);
        m.reference[..2].copy_from_slice(&reference);
        let mv = Controller::step(self, m);
        (mv.voltage, mv.status)
    }

    fn observe(&mut self, angles: [R; 2], u: R) {
        let mut y = [R::ZERO; MAX_NY];
        y[..2].copy_from_slice(&angles);
        Controller::observe(self, y, u);
    }

    fn seed(&mut self, x: [R; 4], u: R) {
        let mut s = [R::ZERO; NX_PLANT];
        s[..4].copy_from_slice(&x);
        Controller::seed(self, s, u);
    }

    fn hold(&mut self, u: R) {
        Controller::hold(self, u);
    }

    fn reset(&mut self) {
        Controller::reset(self);
    }
}

/// Why the supervisor gave up ([`SwingPhase::Stopped`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwingStop {
    /// No catch within [`SwingParams::max_time`].
    Timeout,
    /// A fall with [`OnFall::Stop`].
    LeftBalanceRegion,
}

/// Where the supervisor is (module docs, "Supervisor and catch").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwingPhase {
    /// Pumping energy by the law (1)–(4).
    SwingUp,
    /// The balance controller in charge.
    Balance,
    /// 0 V from now on.
    Stopped(SwingStop),
}

/// What one supervisor step did, besides its voltage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwingStatus<S> {
    /// The law's voltage (or 0 V stopped), from a usable measurement.
    Nominal,
    /// A swing-up sample with an unusable measurement: the estimate is kept and the balance
    /// controller told the period was held.
    Held,
    /// The balance controller's step and its status.
    Balance(S),
}

/// The swing-up supervisor (module docs): the law, the catch, the handover and the balance
/// region's fall test, driving a [`Balance`] controller passed in at every call.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwingSupervisor<R: Real = f64> {
    params: SwingParams<R>,
    rates: SwingRates<R>,
    phase: SwingPhase,
    /// Samples spent in the current swing-up.
    swing_samples: u32,
    /// Samples since the catch (0 while swinging up).
    balance_samples: u32,
    /// The arm reference held since the catch, and the external one at the catch.
    hold_reference: Option<(R, R)>,
    /// The last voltage the swing-up applied.
    u_swing: R,
    /// The last voltage the balance controller applied: it acts during the stop's latency.
    u_balance: R,
}

impl<R: Real> SwingSupervisor<R> {
    /// The supervisor with `params`, swinging up from its first sample.
    pub fn new(params: SwingParams<R>) -> Self {
        Self {
            rates: SwingRates::new(params.ts, params.rate_cutoff_hz),
            params,
            phase: SwingPhase::SwingUp,
            swing_samples: 0,
            balance_samples: 0,
            hold_reference: None,
            u_swing: R::ZERO,
            u_balance: R::ZERO,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &SwingParams<R> {
        &self.params
    }

    /// The phase.
    pub fn phase(&self) -> SwingPhase {
        self.phase
    }

    /// The swing-up's own estimate `[θ, θ̇, α, α̇]` (α wrapped).
    pub fn estimate(&self) -> [R; 4] {
        self.rates.x
    }

    /// Whether the estimate has had a usable measurement since the start or the last reset
    /// (the law writes 0 V until it has).
    pub fn started(&self) -> bool {
        self.rates.started
    }

    /// One period: the measured angles `y = [θ, α]` (non-finite: unusable) and the external
    /// reference `r = [θ_ref, α_ref]`; the voltage to write and what the step did.
    pub fn step<B: Balance<R>>(
        &mut self,
        balance: &mut B,
        y: [R; 2],
        r: [R; 2],
    ) -> (R, SwingStatus<B::Status>) {
        let usable = self.rates.update(y);
        match self.phase {
            SwingPhase::Stopped(_) => (R::ZERO, SwingStatus::Nominal),
            SwingPhase::SwingUp => {
                if usable && self.params.in_catch_region(&self.rates.x) {
                    self.phase = SwingPhase::Balance;
                    self.balance_samples = 0;
                    self.u_balance = self.u_swing;
                    self.hold_reference = Some((self.rates.x[0], r[0]));
                    self.balance_step(balance, y, r)
                } else {
                    self.swing(balance, y, usable)
                }
            }
            SwingPhase::Balance => {
                if !usable || self.params.in_balance_region(&self.rates.x, self.u_balance) {
                    return self.balance_step(balance, y, r);
                }
                match self.params.on_fall {
                    OnFall::Stop => self.stop(SwingStop::LeftBalanceRegion),
                    OnFall::Retry => {
                        self.phase = SwingPhase::SwingUp;
                        self.swing_samples = 0;
                        self.hold_reference = None;
                        self.swing(balance, y, usable)
                    }
                }
            }
        }
    }

    /// A period without a measurement, the plant receiving `u`.
    pub fn hold<B: Balance<R>>(&mut self, balance: &mut B, u: R) {
        self.rates.hold();
        if self.phase == SwingPhase::SwingUp {
            self.swing_samples = self.swing_samples.saturating_add(1);
        }
        balance.hold(u);
    }

    /// Back to swinging up from scratch; `balance` reset too.
    pub fn reset<B: Balance<R>>(&mut self, balance: &mut B) {
        balance.reset();
        self.rates.reset();
        self.phase = SwingPhase::SwingUp;
        self.swing_samples = 0;
        self.balance_samples = 0;
        self.hold_reference = None;
        self.u_swing = R::ZERO;
        self.u_balance = R::ZERO;
    }

    fn stop<S>(&mut self, cause: SwingStop) -> (R, SwingStatus<S>) {
        self.phase = SwingPhase::Stopped(cause);
        (R::ZERO, SwingStatus::Nominal)
    }

    /// One swing-up sample: the law's voltage, the balance estimator kept in step, the clock.
    fn swing<B: Balance<R>>(
        &mut self,
        balance: &mut B,
        y: [R; 2],
        usable: bool,
    ) -> (R, SwingStatus<B::Status>) {
        let p = &self.params;
        self.swing_samples = self.swing_samples.saturating_add(1);
        if c::<R>(f64::from(self.swing_samples)) * p.ts > p.max_time {
            return self.stop(SwingStop::Timeout);
        }
        let x = self.rates.x;
        let u = if self.rates.started {
            p.voltage(&x, p.acceleration(&x))
        } else {
            R::ZERO
        };
        self.u_swing = u;
        if !usable {
            balance.hold(u);
            return (u, SwingStatus::Held);
        }
        if x[2].abs() <= p.estimator_window {
            balance.observe([y[0], wrap_angle(y[1])], u);
        } else {
            balance.seed(x, u);
        }
        (u, SwingStatus::Nominal)
    }

    fn balance_step<B: Balance<R>>(
        &mut self,
        balance: &mut B,
        y: [R; 2],
        r: [R; 2],
    ) -> (R, SwingStatus<B::Status>) {
        let ts = self.params.ts;
        let theta_ref = match self.hold_reference {
            Some((held, at_catch)) if r[0] == at_catch => {
                // Back to the external reference at a bounded rate (module docs, "catch").
                let step = self.params.reference_return_rate * ts;
                let next = held + (at_catch - held).clamp(-step, step);
                self.hold_reference = Some((next, at_catch));
                next
            }
            Some(_) => {
                self.hold_reference = None;
                r[0]
            }
            None => r[0],
        };
        let (u, status) = balance.step([y[0], wrap_angle(y[1])], [theta_ref, r[1]]);
        self.u_balance = u;
        // The handover (module docs, "Balance"): the swing-up's estimate carries the balance
        // controller's estimator through the catch transient.
        self.balance_samples = self.balance_samples.saturating_add(1);
        if c::<R>(f64::from(self.balance_samples)) * ts <= self.params.handover_time {
            balance.seed(self.rates.x, u);
        }
        (u, SwingStatus::Balance(status))
    }
}

#[cfg(test)]
mod tests;

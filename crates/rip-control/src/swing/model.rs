//! The nominal arm and pendulum the law and the predicted catch plan with: the equations of motion, the stopping model and the catch's prediction.

use super::*;

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

    /// The stopping distance `D(ω, U)` (rad): the full voltage along the motion during the
    /// latency.
    pub fn stopping_distance(&self, omega: R) -> R {
        self.stopping_distance_with(omega, self.voltage)
    }

    /// Where the arm at `theta` moving at `rate` stops with `applied` (V) acting during the
    /// latency: `θ + sgn(θ̇) D(|θ̇|, sgn(θ̇) u_a)`.
    pub fn stopping_point(&self, theta: R, rate: R, applied: R) -> R {
        let along = if rate >= R::ZERO { applied } else { -applied };
        theta + rate.signum() * self.stopping_distance_with(rate, along)
    }

    /// The largest speed (rad/s) from which the arm stops within `room` (rad) with `along`
    /// (V) during the latency; 0 when even an arm at rest could not. `D` increases with `ω`:
    /// a bisection of 60 steps between 0 and the first doubling of 1 rad/s that is too fast
    /// (at most 10⁶ rad/s), so its work is bounded whatever the model.
    pub fn max_speed(&self, room: R, along: R) -> R {
        let d = |w: R| self.stopping_distance_with(w, along);
        if d(R::ZERO) >= room {
            return R::ZERO;
        }
        let mut hi = R::ONE;
        while d(hi) < room && hi < c(1e6) {
            hi *= c(2.0);
        }
        let mut lo = R::ZERO;
        for _ in 0..60 {
            let mid = c::<R>(0.5) * (lo + hi);
            if d(mid) < room {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
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

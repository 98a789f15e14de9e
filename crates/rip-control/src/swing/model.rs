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
    /// `M₁₁ = J₀ + J_α sin²α` (kg·m²): the arm's inertia about its axis with the pendulum at
    /// `alpha` (rad).
    #[inline]
    pub fn arm_inertia(&self, alpha: R) -> R {
        let s = alpha.sin();
        self.j0 + self.ja * s * s
    }

    /// `H = M₁₁ θ̇ − m₁₂ cos α α̇` (N·m·s): the arm's angular momentum about its axis at arm
    /// rate `rate`, pendulum angle `alpha` and rate `alpha_rate`, which only the motor's
    /// torque and the arm's friction change (rip-core's `Plant::arm_momentum`).
    #[inline]
    pub fn arm_momentum(&self, rate: R, alpha: R, alpha_rate: R) -> R {
        self.arm_inertia(alpha) * rate - self.m12 * alpha.cos() * alpha_rate
    }

    /// `(θ̈, α̈)` at `x` with `u` (V).
    #[inline]
    pub fn accelerations(&self, x: &[R; 4], u: R) -> [R; 2] {
        let (s, co) = (x[2].sin(), x[2].cos());
        let (td, ad) = (x[1], x[3]);
        let ja = self.ja;
        let two: R = c(2.0);
        let m11 = self.arm_inertia(x[2]);
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

//! The energy-pumping law with its arm-limit barrier, and the rate estimator it runs on.
//! The derivation is in the [module docs](super).

use crate::envelope::envelope_speed;
use crate::plant::{Plant, State};

use super::settings::SwingUpSettings;
use super::wrap_angle;

/// Angles and filtered-difference rates `[θ, θ̇, α, α̇]`, α wrapped to (−π, π].
///
/// The same filter as the LQR's (`q̇̂[k] = a q̇̂[k−1] + (1 − a)(q[k] − q[k−n])/(n Ts)`,
/// `a = e^{−2π f_c Ts}`), except that the pendulum's difference is wrapped, so a measurement
/// that jumps by 2π (a wrapped encoder) changes nothing.
#[derive(Debug, Clone)]
pub(crate) struct RateEstimator {
    ts: f64,
    a: f64,
    x: State,
    started: bool,
    held: u32,
}

impl RateEstimator {
    pub(crate) fn new(ts: f64, cutoff_hz: f64) -> Self {
        Self {
            ts,
            a: (-2.0 * std::f64::consts::PI * cutoff_hz * ts).exp(),
            x: State::zeros(),
            started: false,
            held: 0,
        }
    }

    /// Takes the angles `y = [θ, α]`; `false` (estimate kept, the period counted as held)
    /// when they are unusable.
    pub(crate) fn update(&mut self, y: &[f64]) -> bool {
        if !(y[0].is_finite() && y[1].is_finite()) {
            self.hold();
            return false;
        }
        let alpha = wrap_angle(y[1]);
        if self.started {
            let periods = self.held.saturating_add(1);
            let dt = f64::from(periods) * self.ts;
            let a = self.a.powi(i32::try_from(periods).unwrap_or(i32::MAX));
            let d_theta = (y[0] - self.x[0]) / dt;
            let d_alpha = wrap_angle(alpha - self.x[2]) / dt;
            self.x[1] = a * self.x[1] + (1.0 - a) * d_theta;
            self.x[3] = a * self.x[3] + (1.0 - a) * d_alpha;
        } else {
            self.started = true;
        }
        self.held = 0;
        self.x[0] = y[0];
        self.x[2] = alpha;
        true
    }

    pub(crate) fn hold(&mut self) {
        if self.started {
            self.held = self.held.saturating_add(1);
        }
    }

    pub(crate) fn started(&self) -> bool {
        self.started
    }

    pub(crate) fn state(&self) -> &State {
        &self.x
    }

    pub(crate) fn reset(&mut self) {
        self.x = State::zeros();
        self.started = false;
        self.held = 0;
    }
}

/// Least distance (rad) inside `arm_limit` at which the braking envelope ends: the
/// continuous-time argument of the module docs holds for the nominal model, while the loop
/// samples every `Ts` and the rig differs from the model by some percent. The envelope ends
/// one period at its top speed `√(2 a_b θ_L)` inside the limit, and at least this far.
const ENVELOPE_MARGIN: f64 = 0.05;

/// The swing-up law's constants, computed once from the nominal plant and the settings.
#[derive(Debug, Clone)]
pub(crate) struct EnergyLaw {
    plant: Plant,
    /// `J_α`, the pendulum's inertia about its joint.
    ja: f64,
    /// `G = m_p g l_p / 2`.
    grav: f64,
    /// Target energy at upright, `δ G`.
    target: f64,
    /// `D = 4 d_p √(G/J_α)`: the viscous loss of the pendulum from hanging to upright along
    /// the homoclinic orbit (module docs, eq. (1a)).
    dissipation: f64,
    pump: f64,
    brake: f64,
    gain: f64,
    width: f64,
    wc: f64,
    rise_damping: f64,
    lambda: f64,
    arm_limit: f64,
    u_max: f64,
}

impl EnergyLaw {
    pub(crate) fn new(plant: &Plant, s: &SwingUpSettings, ts: f64) -> Self {
        let p = plant.params();
        let ja = p.jp + p.mp * p.lp * p.lp / 4.0;
        let j0 = p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr;
        let grav = p.mp * p.g * p.lp / 2.0;
        let stall = p.kt / p.rm * s.max_voltage / (j0 + ja);
        let brake = s.brake_fraction * stall;
        let top_speed = envelope_speed(brake, s.arm_limit);
        let margin = (top_speed * ts).max(ENVELOPE_MARGIN).min(0.5 * s.arm_limit);
        // The law plans the voltage the smooth model needs; the dead zone and the arm's
        // Coulomb friction are the compensation's to invert (module docs, eq. (4)). Inverting
        // them here instead divides by the slope of the dead zone, 0 at rest when
        // `V_d ≥ 1 V`, which left the law at 0 V with the pendulum hanging still.
        let smooth = Plant::new(crate::plant::FurutaParams {
            vd: 0.0,
            cr: 0.0,
            cp: 0.0,
            ..*p
        })
        .unwrap_or(*plant);
        Self {
            plant: smooth,
            ja,
            grav,
            target: s.energy_margin * grav,
            dissipation: 4.0 * p.dp * (grav / ja).sqrt(),
            pump: s.pump_fraction * grav / ja,
            brake,
            gain: s.energy_gain,
            width: s.pump_width,
            wc: s.arm_centering,
            rise_damping: s.rise_damping,
            lambda: s.barrier_rate,
            arm_limit: s.arm_limit - margin,
            u_max: s.max_voltage,
        }
    }

    /// The pendulum's own energy relative to upright rest, `E = ½ J_α α̇² + G (cos α − 1)`.
    pub(crate) fn energy(&self, x: &State) -> f64 {
        0.5 * self.ja * x[3] * x[3] + self.grav * (x[2].cos() - 1.0)
    }

    /// The pendulum's energy once an impulse on the arm has stopped it (module docs, eq. (5)):
    /// `E' = ½ J_α α̇'² + G (cos α − 1)`, `α̇' = α̇ − r θ̇`, `r = Δα̈/Δθ̈` the pendulum's
    /// response per unit of the arm's to a torque on the arm alone.
    pub(crate) fn stopped_energy(&self, x: &State) -> f64 {
        // The ratio r = −M₁₂/M₂₂ taken from two evaluations of the equations of motion, as
        // `voltage` inverts them: a change of voltage is a torque on the arm alone.
        let d0 = self.plant.derivative(x, 0.0, 0.0);
        let d1 = self.plant.derivative(x, 1.0, 0.0);
        let ratio = (d1[3] - d0[3]) / (d1[1] - d0[1]);
        if !ratio.is_finite() {
            return self.energy(x);
        }
        let rate = x[3] - ratio * x[1];
        0.5 * self.ja * rate * rate + self.grav * (x[2].cos() - 1.0)
    }

    /// The target energy at pendulum angle `alpha` (wrapped): `δ G` plus what viscous friction
    /// takes on the way from `alpha` to upright, `E_t(α) = δ G + D (1 − cos(α/2))`.
    pub(crate) fn target(&self, alpha: f64) -> f64 {
        self.target + self.dissipation * (1.0 - (0.5 * alpha).cos())
    }

    /// `G = m_p g l_p / 2` (J).
    pub(crate) fn gravity(&self) -> f64 {
        self.grav
    }

    /// The braking deceleration `a_b` (rad/s²).
    pub(crate) fn brake(&self) -> f64 {
        self.brake
    }

    /// The arm acceleration the law asks for at `x` (module docs, steps 1–3).
    pub(crate) fn acceleration(&self, x: &State) -> f64 {
        let (theta, theta_dot, alpha, alpha_dot) = (x[0], x[1], x[2], x[3]);
        // With the last-rise brake the arm is stopped before the catch, and what the pendulum
        // then has is its energy once the arm is at rest (module docs, "Last rise").
        let energy = if self.rise_damping > 0.0 {
            self.stopped_energy(x)
        } else {
            self.energy(x)
        };
        let eps = (self.target(alpha) - energy) / self.grav;
        let v = alpha_dot * alpha.cos();
        // At exact rest (a quantised, noise-free reading of a still pendulum) v is 0 and a
        // smoothed sign would never start the swing: push one way until it moves.
        let sign = if v == 0.0 {
            1.0
        } else {
            (v / self.width).clamp(-1.0, 1.0)
        };
        let pump = self.pump * (self.gain * eps).clamp(-1.0, 1.0) * sign;
        let last_rise = alpha.cos() > 0.0
            && alpha * alpha_dot < 0.0
            && (self.gain * eps).abs() < 1.0
            && self.rise_damping > 0.0;
        let centre = if last_rise {
            -self.rise_damping * theta_dot
        } else {
            -self.wc * self.wc * theta - 2.0 * self.wc * theta_dot
        };
        let wanted = pump + centre;
        let b = self.brake;
        let v_up = envelope_speed(b, self.arm_limit - theta);
        let v_down = envelope_speed(b, self.arm_limit + theta);
        let hi = self.lambda * (v_up - theta_dot) - b * toward(theta_dot, v_up);
        let lo = -self.lambda * (v_down + theta_dot) + b * toward(-theta_dot, v_down);
        if lo <= hi {
            wanted.clamp(lo, hi)
        } else {
            // Outside the envelope on both sides at once: only possible beyond a limit tighter
            // than one braking distance; split the difference.
            0.5 * (lo + hi)
        }
    }

    /// The voltage that gives the arm acceleration `a` at `x` on the nominal model without its
    /// dead zone and Coulomb friction, clamped to `±U`. `θ̈` is affine in `u`, so two
    /// evaluations of the equations of motion invert it.
    pub(crate) fn voltage(&self, x: &State, a: f64) -> f64 {
        let at_zero = self.plant.derivative(x, 0.0, 0.0)[1];
        let per_volt = self.plant.derivative(x, 1.0, 0.0)[1] - at_zero;
        let u = (a - at_zero) / per_volt;
        if u.is_finite() {
            u.clamp(-self.u_max, self.u_max)
        } else {
            0.0
        }
    }
}

/// The share `clamp(v / v_env, 0, 1)` of the braking deceleration the envelope's boundary
/// needs at speed `v` towards a limit whose envelope speed is `v_env` (module docs).
#[inline]
fn toward(v: f64, v_env: f64) -> f64 {
    if v <= 0.0 {
        0.0
    } else if v >= v_env {
        1.0
    } else {
        v / v_env
    }
}

/// The unstable mode of the nominal model linearised about upright (module docs, "Catch"):
/// `z = wᵀ x` with `wᵀ A = λ wᵀ`, `λ > 0`, normalised to `w_α = 1`, so that
/// `ż = λ z + (wᵀ b) u`; with `|u| ≤ U` it can be brought back to 0 exactly while
/// `|z| < |wᵀ b| U / λ` (`recoverable`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct UnstableMode {
    w: [f64; 4],
    recoverable: f64,
}

impl UnstableMode {
    pub(crate) fn new(plant: &Plant, u_max: f64) -> Option<Self> {
        let (a, b) = plant.linearize_upright();
        let lambda = crate::linalg::eigenvalues(&a)
            .iter()
            .filter(|e| e.im.abs() < 1e-9 * (1.0 + e.re.abs()))
            .map(|e| e.re)
            .fold(f64::NAN, f64::max);
        if !(lambda.is_finite() && lambda > 0.0) {
            return None;
        }
        // The left eigenvector spans the null space of Aᵀ − λI: the right singular vector of
        // its smallest singular value.
        let shifted = a.transpose() - crate::linalg::Mat::identity(4, 4) * lambda;
        let svd = shifted.try_svd(false, true, f64::EPSILON, 400)?;
        let v_t = svd.v_t?;
        let k = svd.singular_values.imin();
        let row = v_t.row(k);
        if row[2].abs() < 1e-12 {
            return None;
        }
        let w = [row[0] / row[2], row[1] / row[2], 1.0, row[3] / row[2]];
        let wb: f64 = (0..4).map(|i| w[i] * b[(i, 0)]).sum();
        let recoverable = wb.abs() * u_max / lambda;
        recoverable.is_finite().then_some(Self { w, recoverable })
    }

    /// `|z| / (|wᵀ b| U / λ)` at `x` (α wrapped): below 1 the voltage bound can still stop the
    /// fall.
    pub(crate) fn load(&self, x: &State) -> f64 {
        let z: f64 = (0..4).map(|i| self.w[i] * x[i]).sum();
        z.abs() / self.recoverable
    }
}

//! The energy-pumping law with its centring spring and braking envelope (module docs, (1)–(4)).

use super::*;

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

    /// Where the arm at `theta` moving at `rate` stops braked at `a_b`: `θ + θ̇|θ̇|/(2 a_b)`.
    #[inline]
    pub fn braked_stop(&self, theta: R, rate: R) -> R {
        theta + rate * rate.abs() / (c::<R>(2.0) * self.brake)
    }

    /// Whether the estimate `x` is in the catch region (module docs, "catch").
    pub fn in_catch_region(&self, x: &[R; 4]) -> bool {
        let arm_stop = self.braked_stop(x[0], x[1]);
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

//! Compensation of the motor drive's voltage dead zone and the arm's Coulomb friction, defined
//! once for every controller (LQR, LQG, MPC and the swing-up supervisor) and every place that
//! runs one (`riprs.simulate`, `riprs compare`, campaigns, `rip-rt`).
//!
//! The controllers are designed on the smooth part of the plant (see [`crate::plant`]): they
//! compute the voltage `v` that the linear model should receive. The rig, however, applies
//! `z(u) = u − clamp(u, −V_d, V_d)` and loses the torque `C_r sgn(θ̇)` to friction, i.e. the
//! voltage `V_f sgn(θ̇)` with `V_f = C_r R_m / k_t`. The compensation inverts both before the
//! voltage is written:
//!
//! ```text
//! w = v + V_f σ(θ̇̂ / ω_s)            friction feed-forward on the arm-rate estimate
//! u = w + V_d σ(w / v_s)              dead-zone inverse
//! u ← clamp(u, u_min, u_max)          the bounds hold on the voltage actually applied
//! σ(s) = clamp(s, −1, 1)              a continuous sign
//! ```
//!
//! so that `z(u) − V_f sgn(θ̇) = v` whenever `|w| ≥ v_s` and `|θ̇| ≥ ω_s`. The sign is
//! continuous (a ramp of width `v_s` volts and `ω_s` rad/s) instead of a jump: an exact
//! `sgn` would switch by `2 V_d` on every zero crossing of the command, and the measurement
//! noise makes those crossings many at rest, which is chatter. A ramp (rather than `tanh`)
//! needs no floating-point library, so the law runs unchanged without `std`: it is
//! rip-control's ([`rip_control::CompensationDesign`]), the code the device runs too.
//!
//! The controller itself plans with the bounds shrunk by the largest correction,
//! `[u_min + V_d + V_f, u_max − V_d − V_f]` ([`Compensation::inner_bounds`]), so that the
//! final clamp never cuts the voltage it planned with, and the estimators (Kalman filter, MPC
//! prediction) are fed `v`, the voltage the linear model sees. A held or externally chosen
//! input `u` is mapped back to `v = z(u) − V_f σ(θ̇̂/ω_s)` ([`Compensation::effective`]).
//!
//! With `V_d = V_f = 0` (every preset, the paper's rig) there is nothing to compensate and the
//! controller assembly builds the controllers without it, bit for bit as before.
//!
//! The pendulum's Coulomb friction is not compensated: the motor does not act on that joint.

use crate::controller::{Controller, Phase, StepStatus};

/// Why a [`Compensation`] cannot be built: the parameter and its value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InvalidCompensation {
    /// The parameter's name (`dead_zone`, `arm_friction`, `voltage_scale`, `velocity_scale`,
    /// `input_bounds`).
    pub name: &'static str,
    /// The refused value.
    pub value: f64,
    /// What it must be.
    pub reason: &'static str,
}

impl core::fmt::Display for InvalidCompensation {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}: {}, got {}", self.name, self.reason, self.value)
    }
}

impl std::error::Error for InvalidCompensation {}

/// The compensation law (module docs): allocation-free, no floating-point library.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensation {
    dead_zone: f64,
    friction_voltage: f64,
    voltage_scale: f64,
    velocity_scale: f64,
    u_min: f64,
    u_max: f64,
}

impl Compensation {
    /// A compensation of the dead zone `dead_zone` (V) and of the arm's Coulomb friction
    /// `friction_voltage` (V, `C_r R_m / k_t`), with sign ramps of width `voltage_scale` (V)
    /// and `velocity_scale` (rad/s), writing voltages in `[u_min, u_max]`.
    ///
    /// # Errors
    /// Negative or non-finite corrections, non-positive scales, bounds that are not finite
    /// with `u_min < u_max`, or corrections that leave no room inside the bounds.
    pub fn new(
        dead_zone: f64,
        friction_voltage: f64,
        voltage_scale: f64,
        velocity_scale: f64,
        (u_min, u_max): (f64, f64),
    ) -> Result<Self, InvalidCompensation> {
        let bad = |name, value, reason| {
            Err(InvalidCompensation {
                name,
                value,
                reason,
            })
        };
        if !(dead_zone.is_finite() && dead_zone >= 0.0) {
            return bad(
                "dead_zone",
                dead_zone,
                "must be finite and non-negative (V)",
            );
        }
        if !(friction_voltage.is_finite() && friction_voltage >= 0.0) {
            return bad(
                "arm_friction",
                friction_voltage,
                "must be finite and non-negative",
            );
        }
        if !(voltage_scale.is_finite() && voltage_scale > 0.0) {
            return bad("voltage_scale", voltage_scale, "must be positive (V)");
        }
        if !(velocity_scale.is_finite() && velocity_scale > 0.0) {
            return bad("velocity_scale", velocity_scale, "must be positive (rad/s)");
        }
        if !(u_min.is_finite() && u_max.is_finite() && u_min < u_max) {
            return bad("input_bounds", u_max - u_min, "need finite u_min < u_max");
        }
        let margin = dead_zone + friction_voltage;
        if !(u_min + margin < 0.0 && 0.0 < u_max - margin) {
            return bad(
                "dead_zone",
                margin,
                "dead zone plus friction voltage must leave room inside the input bounds",
            );
        }
        Ok(Self {
            dead_zone,
            friction_voltage,
            voltage_scale,
            velocity_scale,
            u_min,
            u_max,
        })
    }

    /// The dead zone compensated (V).
    pub fn dead_zone(&self) -> f64 {
        self.dead_zone
    }

    /// The friction voltage compensated (V).
    pub fn friction_voltage(&self) -> f64 {
        self.friction_voltage
    }

    /// The widths of the sign ramps: `(voltage_scale` (V), `velocity_scale` (rad/s)).
    pub fn scales(&self) -> (f64, f64) {
        (self.voltage_scale, self.velocity_scale)
    }

    /// The bounds of the voltage actually written.
    pub fn bounds(&self) -> (f64, f64) {
        (self.u_min, self.u_max)
    }

    /// The bounds the controller plans `v` within (module docs): the written bounds shrunk by
    /// `V_d + V_f`, so that the compensated voltage stays inside them.
    pub fn inner_bounds(&self) -> (f64, f64) {
        let m = self.dead_zone + self.friction_voltage;
        (self.u_min + m, self.u_max - m)
    }

    /// A planner's own voltage limit (such as the swing-up law's `max_voltage`) inside
    /// [`inner_bounds`](Self::inner_bounds), so that it too plans with what the rig can get.
    pub fn planned_limit(&self, max_voltage: f64) -> f64 {
        let (lo, hi) = self.inner_bounds();
        max_voltage.min(hi).min(-lo)
    }

    /// The voltage to write for the controller's `v`, at the arm-rate estimate `arm_rate`
    /// (module docs). A non-finite rate counts as zero.
    #[inline]
    pub fn apply(&self, v: f64, arm_rate: f64) -> f64 {
        self.unclamped(v, arm_rate).clamp(self.u_min, self.u_max)
    }

    #[inline]
    fn unclamped(&self, v: f64, arm_rate: f64) -> f64 {
        self.as_control().unclamped(v, arm_rate)
    }

    /// The law as rip-control runs it (one definition for the host and the device).
    #[inline]
    fn as_control(&self) -> rip_control::CompensationDesign<f64> {
        rip_control::CompensationDesign {
            dead_zone: self.dead_zone,
            friction_voltage: self.friction_voltage,
            voltage_scale: self.voltage_scale,
            velocity_scale: self.velocity_scale,
        }
    }

    /// The voltage the linear model sees when `u` is written at the arm rate `arm_rate`:
    /// `z(u) − V_f σ(θ̇̂/ω_s)`, the inverse of [`apply`](Self::apply) outside the ramps.
    #[inline]
    pub fn effective(&self, u: f64, arm_rate: f64) -> f64 {
        self.as_control().effective(u, arm_rate)
    }
}

/// A controller whose every written voltage is compensated ([`Compensation`]): it plans `v`
/// with the inner controller (built with [`Compensation::inner_bounds`]), writes
/// [`Compensation::apply`] of it, and hands the inner controller's estimator `v` for the
/// inputs it wrote and [`Compensation::effective`] of any other input.
///
/// The arm-rate estimate is the inner controller's [`state_estimate`](Controller::state_estimate)
/// (`x̂[1]`), zero when it has none.
#[derive(Debug, Clone)]
pub struct Compensated<C> {
    inner: C,
    law: Compensation,
    /// The last written voltage and the `v` it was computed from.
    last_written: f64,
    last_planned: f64,
}

impl<C: Controller> Compensated<C> {
    /// Wraps `inner` (whose input bounds should be `law.inner_bounds()`).
    pub fn new(inner: C, law: Compensation) -> Self {
        Self {
            inner,
            law,
            last_written: 0.0,
            last_planned: 0.0,
        }
    }

    /// The compensation law.
    pub fn law(&self) -> &Compensation {
        &self.law
    }

    /// The wrapped controller.
    pub fn inner(&self) -> &C {
        &self.inner
    }

    fn arm_rate(&self) -> f64 {
        match self.inner.state_estimate() {
            Some(x) if x.len() > 1 => x[1],
            _ => 0.0,
        }
    }

    /// The `v` behind a written `u`: exactly the planned one when `u` is what this wrapper
    /// wrote last, otherwise the law's inverse at the rate `rate`.
    fn planned_for(&self, u: f64, rate: f64) -> f64 {
        if u == self.last_written {
            self.last_planned
        } else if u.is_finite() {
            self.law.effective(u, rate)
        } else {
            u
        }
    }
}

impl<C: Controller> Controller for Compensated<C> {
    fn n_outputs(&self) -> usize {
        self.inner.n_outputs()
    }

    fn n_inputs(&self) -> usize {
        self.inner.n_inputs()
    }

    fn step(&mut self, y: &[f64], r: &[f64], u: &mut [f64]) -> StepStatus {
        let status = self.inner.step(y, r, u);
        let v = u[0];
        if matches!(self.inner.phase(), Phase::Stopped(_)) {
            // A stopped supervisor writes 0 V; nothing to compensate.
            return status;
        }
        let rate = self.arm_rate();
        let raw = self.law.unclamped(v, rate);
        let written = raw.clamp(self.law.u_min, self.law.u_max);
        u[0] = written;
        // A clamped voltage (a planner that ignores the inner bounds, such as a swing-up law
        // at its own limit) is not what the estimator was told: tell it what the rig gets.
        self.last_planned = if raw == written {
            v
        } else {
            self.law.effective(written, rate)
        };
        self.last_written = written;
        status
    }

    fn hold(&mut self, u: &[f64]) {
        let v = [self.planned_for(u[0], self.arm_rate())];
        self.inner.hold(&v);
    }

    fn observe(&mut self, y: &[f64], u: &[f64]) {
        let v = [self.planned_for(u[0], self.arm_rate())];
        self.inner.observe(y, &v);
    }

    fn seed(&mut self, x: &[f64], u: &[f64]) {
        let rate = x.get(1).copied().unwrap_or(0.0);
        let v = [self.planned_for(u[0], rate)];
        self.inner.seed(x, &v);
    }

    fn phase(&self) -> Phase {
        self.inner.phase()
    }

    fn reset(&mut self) {
        self.inner.reset();
        self.last_written = 0.0;
        self.last_planned = 0.0;
    }

    fn state_estimate(&self) -> Option<&[f64]> {
        self.inner.state_estimate()
    }

    fn sample_time(&self) -> Option<f64> {
        self.inner.sample_time()
    }

    fn swing_up_report(&self) -> Option<crate::swing_report::SwingUpReport> {
        self.inner.swing_up_report()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::dead_zone;

    fn law() -> Compensation {
        Compensation::new(0.4, 0.35, 0.05, 0.05, (-12.0, 12.0)).unwrap()
    }

    #[test]
    fn outside_the_ramps_the_rig_receives_the_planned_voltage() {
        // The rig's own nonlinearity, written independently: dead zone then Coulomb loss.
        let c = law();
        for &v in &[-8.0, -1.0, -0.2, 0.2, 0.9, 6.0] {
            for &rate in &[-2.0, -0.06, 0.06, 3.0] {
                let u = c.apply(v, rate);
                let w = v + 0.35 * f64::signum(rate);
                if w.abs() < 0.05 {
                    continue;
                }
                let seen = dead_zone(u, 0.4) - 0.35 * f64::signum(rate);
                assert!((seen - v).abs() < 1e-12, "v {v} rate {rate}: {seen}");
                assert!((c.effective(u, rate) - v).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn the_written_voltage_is_continuous_and_bounded() {
        let c = law();
        let (lo, hi) = c.inner_bounds();
        assert!((lo + 11.25).abs() < 1e-12 && (hi - 11.25).abs() < 1e-12);
        let mut prev = c.apply(-12.0, 0.0);
        let n = 200_000;
        for i in 1..=n {
            let v = -12.0 + 24.0 * f64::from(i) / f64::from(n);
            let u = c.apply(v, 0.0);
            // Lipschitz with slope at most 1 + V_d / v_s = 9 over a step of 1.2e-4 V.
            assert!((u - prev).abs() <= 9.0 * 24.0 / f64::from(n) + 1e-12, "{v}");
            assert!((-12.0..=12.0).contains(&u));
            prev = u;
        }
        // Planned within the inner bounds, the written voltage is never clamped.
        for &rate in &[-1.0, 0.0, 1.0] {
            assert!(c.apply(hi, rate) <= 12.0 && c.apply(lo, rate) >= -12.0);
            assert!((c.apply(hi, 1.0) - 12.0).abs() < 1e-12);
        }
        assert_eq!(c.apply(0.0, f64::NAN), 0.0);
    }

    #[test]
    fn bad_parameters_are_named() {
        let b = (-12.0, 12.0);
        let name = |r: Result<Compensation, InvalidCompensation>| r.unwrap_err().name;
        assert_eq!(
            name(Compensation::new(-0.1, 0.0, 0.05, 0.05, b)),
            "dead_zone"
        );
        assert_eq!(
            name(Compensation::new(0.1, f64::NAN, 0.05, 0.05, b)),
            "arm_friction"
        );
        assert_eq!(
            name(Compensation::new(0.1, 0.0, 0.0, 0.05, b)),
            "voltage_scale"
        );
        assert_eq!(
            name(Compensation::new(0.1, 0.0, 0.05, -1.0, b)),
            "velocity_scale"
        );
        assert_eq!(
            name(Compensation::new(0.1, 0.0, 0.05, 0.05, (1.0, 1.0))),
            "input_bounds"
        );
        assert_eq!(
            name(Compensation::new(7.0, 6.0, 0.05, 0.05, b)),
            "dead_zone"
        );
    }
}

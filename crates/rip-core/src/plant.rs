//! The nonlinear rotary inverted pendulum (Furuta pendulum) driven by a DC motor.
//!
//! # Convention
//!
//! State `x = [θ, θ̇, α, α̇]` (the paper's order): arm angle θ (rad, positive counter-clockwise
//! seen from above, the direction a positive voltage turns the motor), arm rate, pendulum angle
//! α (rad, **0 = upright**), pendulum rate. α is positive when the pendulum leans *against*
//! the direction of positive arm rotation, i.e. the way an upright pendulum falls when the arm
//! accelerates positively. With this choice a positive voltage accelerates both θ and α
//! positively about the upright equilibrium, as the all-positive `B_d` of the paper's eq. (3)
//! requires. Input: motor voltage `u` (V). Outputs: `[θ, α]`.
//!
//! # Equations of motion (Euler–Lagrange)
//!
//! Both links are uniform rods pivoted at one end: arm of mass `mr`, length `lr` (motor axis to
//! pendulum joint) and centroidal inertia `jr`; pendulum of mass `mp`, length `lp`, centre of
//! mass at `lp/2`, centroidal inertia `jp` (about axes perpendicular to the rod; the rod's own
//! axial inertia is neglected). With
//!
//! ```text
//! J₀ = jr + mr lr²/4 + mp lr²      arm-axis inertia at α = 0 (parallel-axis theorem)
//! Jα = jp + mp lp²/4               pendulum inertia about its joint
//! m₁₂ = mp lr lp/2                 coupling,   G = mp g lp/2   gravity stiffness
//! ```
//!
//! the kinetic and potential energies are
//!
//! ```text
//! T = ½ (J₀ + Jα sin²α) θ̇² − m₁₂ cos α θ̇ α̇ + ½ Jα α̇²,      V = G cos α
//! ```
//!
//! and Lagrange's equations with viscous friction `dr`, `dp`, Coulomb friction `cr`, `cp`, the
//! cable's torque `τ_c` and the motor torque give
//!
//! ```text
//! (J₀ + Jα sin²α) θ̈ − m₁₂ cos α α̈ + 2 Jα sin α cos α θ̇ α̇ + m₁₂ sin α α̇²
//!                                            = τ − dr θ̇ − cr sgnₛ(θ̇) + τ_c + τ_d
//! −m₁₂ cos α θ̈ + Jα α̈ − Jα sin α cos α θ̇² − G sin α = −dp α̇ − cp sgnₛ(α̇)
//! τ = kt (z(u) − km θ̇) / rm
//! ```
//!
//! (`τ_d`: an external torque disturbance on the arm). These are the equations of the Quanser
//! QUBE-Servo 2 workbook and of Cazzolato & Prime, "On the dynamics of the Furuta pendulum"
//! (J. Control Sci. Eng., 2011), with the pendulum's `sin²α` inertia term kept and the arm's
//! parallel-axis term included (see [`FurutaParams::qube_servo2`]).
//!
//! `sin α` and `cos α` are evaluated together once per evaluation of the right-hand side, by
//! [`crate::trig::sin_cos`] (within 2 ulp of the correctly rounded values). The same
//! operations run over several pendulums at once in [`Plant::advance_lanes`], which the
//! compiler can map to SIMD lanes without changing a bit of any pendulum's trajectory.
//!
//! # Coulomb friction and the voltage dead zone
//!
//! Coulomb friction is a torque of constant size `cr` (arm) or `cp` (pendulum) against the
//! joint's motion. Its sign function is smoothed,
//!
//! ```text
//! sgnₛ(v) = tanh(v / v_c),   v_c = COULOMB_VELOCITY_SCALE = 0.05 rad/s
//! ```
//!
//! so that the right-hand side stays smooth: RK4 keeps its order, and the sensitivities an
//! identification differentiates exist everywhere. Below `v_c` the friction acts as a viscous
//! damping of slope `c/v_c` (holding a joint nearly still, like stiction); from `2 v_c` on it is
//! within 4 % of its full size. That slope is the stiffest term of the model, and
//! [`Plant::max_rk4_substep`] accounts for it.
//!
//! Optionally ([`Plant::with_arm_breakaway`]) the arm's friction rises above the Coulomb level
//! at low speed, to a breakaway torque `cs ≥ cr` (stiction, a Stribeck curve):
//!
//! ```text
//! F_r(θ̇) = (cr + (cs − cr) e^{−(θ̇/v_s)²}) sgnₛ(θ̇),   v_s = STRIBECK_VELOCITY = 0.1 rad/s
//! ```
//!
//! so that a torque below `cs` holds the arm nearly still and the friction drops to `cr` once
//! it moves: what a compensation of `cr` alone does not know.
//!
//! The motor driver does not move the motor below a threshold voltage `vd` (the QUBE-Servo 3's
//! default dead band is 0.65 V); the applied voltage is the dead-zone function
//!
//! ```text
//! z(u) = u − clamp(u, −vd, vd)  =  0 for |u| ≤ vd,   u − vd sgn(u) beyond.
//! ```
//!
//! With `cr = cp = vd = 0` (every preset) both terms vanish exactly and the model is the
//! smooth one above, bit for bit.
//!
//! # The cable
//!
//! The encoder and motor wiring of a bench rig runs from the base to the arm and bends as the
//! arm turns: a spring on the arm about the angle at which it hangs relaxed. That angle is the
//! arm's zero (a rig is zeroed at rest, where the cable holds it), so the cable's torque is
//!
//! ```text
//! τ_c = −kc θ          (cable_torque)
//! ```
//!
//! with `kc` (N·m/rad, `[plant] Kc`) its stiffness; an identification of a QUBE-Servo 3 measured
//! 2.384·10⁻³ N·m/rad. Only the stiffness is modelled: a hysteresis or a Coulomb-like part of
//! the cable would be indistinguishable, in the logs riprs fits and in the paper's RMSE, from
//! the arm's own Coulomb friction `cr`, which the model has. `kc = 0` (every preset) leaves the
//! equations above bit for bit.
//!
//! # Linearisation about upright
//!
//! With `M = [J₀ −m₁₂; −m₁₂ Jα]` and `c = dr + kt km/rm`, `b = kt/rm`:
//!
//! ```text
//! [θ̈; α̈] = M⁻¹ ([−kc θ − c θ̇ + b u; G α − dp α̇])
//! ```
//!
//! which, for `kc = 0`, is the structure
//! `ẋ = [0 1 0 0; 0 a₁₁ a₁₂ a₁₃; 0 0 0 1; 0 a₃₁ a₃₂ a₃₃] x + [0 b₁ 0 b₃]ᵀu`
//! of [`crate::paper::continuous_model`]; the cable adds the arm-spring column
//! `a₁₀ = −kc (M⁻¹)₀₀ = −kc Jα / det M`, `a₃₀ = −kc (M⁻¹)₁₀ = −kc m₁₂ / det M`. Being smooth,
//! the cable is part of the model the controllers are designed on. [`Plant::linearize`]
//! returns the exact Jacobian at any state and input of the plant *without* its Coulomb
//! friction and dead zone, of which this is the special case. Those two are left out on
//! purpose: at rest they are not differentiable (the smoothing slope `c/v_c` is a numerical
//! device, not a damping the controller can rely on, and `z′(0) = 0` inside the dead zone
//! would say that the motor cannot move the arm at all). The controllers are designed on this smooth part; friction and
//! dead zone act on them as the disturbances they are.

use nalgebra::{SMatrix, SVector};

use crate::error::{Result, RipError};
use crate::linalg::spectral_radius;
use crate::linalg::{c2d, Mat};

mod params;
pub use params::{FurutaParams, Lumped, Param};

/// Most RK4 substeps per control period.
pub const MAX_SUBSTEPS: usize = 100_000;

/// Extent of classical RK4's stability region along the negative real axis (`|h λ| ≤ 2.785`),
/// rounded down.
const RK4_STABILITY_LIMIT: f64 = 2.78;

/// Velocity scale `v_c` (rad/s) of the smoothed sign `tanh(v / v_c)` of the Coulomb friction
/// (module docs).
pub const COULOMB_VELOCITY_SCALE: f64 = 0.05;

/// Velocity scale `v_s` (rad/s) of the Stribeck decay from the breakaway torque to the Coulomb
/// level (module docs).
pub const STRIBECK_VELOCITY: f64 = 0.1;

/// The dead-zone function `z(u) = u − clamp(u, −vd, vd)` (module docs); `z(u) = u` exactly
/// when `vd = 0`.
#[inline]
pub fn dead_zone(u: f64, vd: f64) -> f64 {
    u - u.clamp(-vd, vd)
}

/// The cable's torque on the arm, `τ_c = −kc θ` (N·m) at arm angle `theta` (module docs, "The
/// cable"): the one definition the simulator, the emulator, the identification and the
/// linearisation use. Exactly 0 when `kc = 0`.
#[inline(always)]
pub fn cable_torque(theta: f64, kc: f64) -> f64 {
    -kc * theta
}

/// State vector `[θ, θ̇, α, α̇]`.
pub type State = SVector<f64, 4>;

/// Largest number of RK4 steps one [`Plant::integrate`] call may take (about a second of
/// computation), so that a call from Python, which cannot be interrupted while it runs,
/// always ends soon.
pub const MAX_INTEGRATION_STEPS: usize = 10_000_000;

/// Fails unless `1 ≤ substeps ≤` [`MAX_SUBSTEPS`].
pub fn check_substeps(substeps: usize) -> Result<()> {
    if substeps == 0 || substeps > MAX_SUBSTEPS {
        return Err(RipError::invalid(
            "substeps",
            format!("must be between 1 and {MAX_SUBSTEPS}, got {substeps}"),
        ));
    }
    Ok(())
}

/// Fails unless `dt` is positive and finite and `substeps` is in range.
pub fn check_step(dt: f64, substeps: usize) -> Result<()> {
    if !(dt.is_finite() && dt > 0.0) {
        return Err(RipError::invalid(
            "dt",
            format!("must be positive and finite, got {dt}"),
        ));
    }
    check_substeps(substeps)
}

fn check_finite_scalar(name: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(RipError::NonFinite { name: name.into() })
    }
}

fn check_finite_state(name: &str, x: &State) -> Result<()> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(RipError::NonFinite { name: name.into() })
    }
}

fn diverged(dt: f64, substeps: usize) -> RipError {
    RipError::Diverged {
        reason: format!(
            "the state overflowed integrating with dt = {dt:e} s in {substeps} substeps; the step \
             or the input is too large for the plant"
        ),
    }
}

/// The nonlinear plant: validated parameters and the lumped coefficients of the equations of
/// motion (module docs). Cheap to copy; every method is allocation-free except the
/// `Mat`-returning discretisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plant {
    params: FurutaParams,
    j0: f64,
    ja: f64,
    m12: f64,
    grav: f64,
    /// Motor torque per volt, `kt/rm`.
    b: f64,
    /// Arm damping including back-EMF, `dr + kt km/rm`.
    c_arm: f64,
    dp: f64,
    /// Coulomb friction of arm and pendulum, `cr`, `cp`.
    coulomb: [f64; 2],
    vd: f64,
    /// The arm's breakaway torque above `cr` (stiction, module docs), `cs − cr`; 0 for none.
    stiction: f64,
    /// The cable's stiffness `kc` (module docs).
    kc: f64,
    /// [`max_rk4_substep`](Self::max_rk4_substep), computed once: it takes two eigenvalue
    /// problems, far more than a checked step itself.
    max_substep: f64,
}

impl Plant {
    /// Validates `params` and precomputes the lumped coefficients.
    pub fn new(params: FurutaParams) -> Result<Self> {
        params.validate()?;
        let p = params;
        let l = p.lumped();
        let mut plant = Self {
            params,
            j0: l.j0,
            ja: l.ja,
            m12: l.m12,
            grav: l.grav,
            b: p.kt / p.rm,
            c_arm: p.dr + p.kt * p.km / p.rm,
            dp: p.dp,
            coulomb: [p.cr, p.cp],
            vd: p.vd,
            stiction: 0.0,
            kc: p.kc,
            max_substep: f64::INFINITY,
        };
        plant.max_substep = plant.rk4_stability_limit();
        Ok(plant)
    }

    /// The same plant with the arm's friction rising to the breakaway torque `cs` (N·m) at
    /// rest (stiction, module docs); `cs = 0` for none.
    ///
    /// # Errors
    /// `cs` not finite, negative, or positive but below the Coulomb level `cr`.
    pub fn with_arm_breakaway(mut self, cs: f64) -> Result<Self> {
        if !(cs.is_finite() && (cs == 0.0 || cs >= self.coulomb[0])) {
            return Err(RipError::invalid(
                "arm_breakaway",
                format!(
                    "must be 0 or finite and at least cr = {}, got {cs}",
                    self.coulomb[0]
                ),
            ));
        }
        self.stiction = if cs == 0.0 { 0.0 } else { cs - self.coulomb[0] };
        self.max_substep = self.rk4_stability_limit();
        Ok(self)
    }

    /// The arm's breakaway torque (N·m), 0 without stiction.
    pub fn arm_breakaway(&self) -> f64 {
        if self.stiction == 0.0 {
            0.0
        } else {
            self.coulomb[0] + self.stiction
        }
    }

    /// The QUBE-Servo 2 preset ([`FurutaParams::qube_servo2`]).
    pub fn qube_servo2() -> Self {
        Self::new(FurutaParams::qube_servo2()).expect("the preset is valid")
    }

    /// The preset fitted to the paper's model ([`FurutaParams::paper`]).
    pub fn paper() -> Self {
        Self::new(FurutaParams::paper()).expect("the preset is valid")
    }

    /// The physical parameters.
    pub fn params(&self) -> &FurutaParams {
        &self.params
    }

    /// The smooth part of this model ([`FurutaParams::smooth`], and no stiction).
    pub fn smooth(&self) -> Result<Plant> {
        Plant::new(self.params.smooth())
    }

    /// The smooth part of these equations of motion (no dead zone, no Coulomb friction or
    /// stiction) in the `no_std` form the swing-up law inverts and the predicted catch
    /// integrates ([`rip_control::swing::ArmModel`]): this plant's own lumped coefficients.
    pub fn arm_model(&self) -> rip_control::swing::ArmModel {
        rip_control::swing::ArmModel {
            j0: self.j0,
            ja: self.ja,
            m12: self.m12,
            grav: self.grav,
            b: self.b,
            c_arm: self.c_arm,
            dp: self.dp,
        }
    }

    /// Motor torque `τ = kt (z(u) − km θ̇) / rm` (N·m) at state `x` and voltage `u`, `z` the
    /// dead zone.
    #[inline]
    pub fn motor_torque(&self, x: &State, u: f64) -> f64 {
        self.params.kt * (dead_zone(u, self.vd) - self.params.km * x[1]) / self.params.rm
    }

    /// Mass matrix entries `(M₁₁, M₁₂, M₂₂)` and the generalized forces `(f₁, f₂)` such that
    /// `M [θ̈; α̈] = [f₁; f₂]`, without Coulomb friction and dead zone.
    #[inline]
    fn mass_and_forces(&self, x: &State, u: f64, tau_d: f64) -> ([f64; 3], [f64; 2]) {
        let c = Coefficients::gather([self]);
        let (m, f) = c.mass_and_forces(&lanes_of([x]), &[u], &[tau_d]);
        (m.map(|v| v[0]), f.map(|v| v[0]))
    }

    /// `ẋ = f(x, u, τ_d)`: the equations of motion of the module docs, `τ_d` (N·m) being an
    /// external torque on the arm.
    #[inline]
    pub fn derivative(&self, x: &State, u: f64, tau_d: f64) -> State {
        let c = Coefficients::gather([self]);
        let d = c.derivative(&lanes_of([x]), &[u], &[tau_d]);
        State::new(d[0][0], d[1][0], d[2][0], d[3][0])
    }

    /// `ẋ` of the smooth part of the model (no Coulomb friction, no dead zone), which
    /// [`linearize`](Self::linearize) differentiates.
    #[inline]
    fn smooth_derivative(&self, x: &State, u: f64) -> State {
        let (m, f) = self.mass_and_forces(x, u, 0.0);
        let [thdd, addd] = solve([m[0]], [m[1]], [m[2]], [f[0]], [f[1]]);
        State::new(x[1], thdd[0], x[3], addd[0])
    }

    /// One classical fourth-order Runge–Kutta step of length `h` with `u`, `τ_d` held.
    #[inline]
    pub fn rk4_step(&self, x: &mut State, u: f64, tau_d: f64, h: f64) {
        let c = Coefficients::gather([self]);
        let mut z = lanes_of([&*x]);
        c.rk4_step(&mut z, &[u], &[tau_d], h);
        *x = State::new(z[0][0], z[1][0], z[2][0], z[3][0]);
    }

    /// Advances `x` by `dt` with `substeps` RK4 steps under a zero-order-held input.
    #[inline]
    pub fn advance(&self, x: &mut State, u: f64, tau_d: f64, dt: f64, substeps: usize) {
        let mut xs = [*x];
        Self::advance_lanes([self], &mut xs, &[u], &[tau_d], dt, substeps);
        *x = xs[0];
    }

    /// [`advance`](Self::advance) of `L` pendulums at once, pendulum `l` on `plants[l]` from
    /// `x[l]` with `u[l]`, `tau_d[l]`: the same operations in the same order per pendulum, so
    /// each result has exactly the bits `plants[l].advance(...)` gives, but evaluated lane by
    /// lane over structure-of-arrays state so that the compiler can use SIMD.
    #[inline(always)]
    pub fn advance_lanes<const L: usize>(
        plants: [&Plant; L],
        x: &mut [State; L],
        u: &[f64; L],
        tau_d: &[f64; L],
        dt: f64,
        substeps: usize,
    ) {
        let c = Coefficients::gather(plants);
        let n = substeps.max(1);
        let h = dt / n as f64;
        let mut z = lanes_of(x.each_ref());
        for _ in 0..n {
            c.rk4_step(&mut z, u, tau_d, h);
        }
        for (l, xl) in x.iter_mut().enumerate() {
            *xl = State::new(z[0][l], z[1][l], z[2][l], z[3][l]);
        }
    }

    /// [`advance`](Self::advance) with every argument checked and the work bounded: `x`, `u`,
    /// `tau_d` finite, `dt` positive and finite, `1 ≤ substeps ≤` [`MAX_SUBSTEPS`]. A state that
    /// overflows is [`RipError::Diverged`], never returned.
    pub fn step_checked(
        &self,
        x: &State,
        u: f64,
        tau_d: f64,
        dt: f64,
        substeps: usize,
    ) -> Result<State> {
        check_finite_state("x", x)?;
        check_finite_scalar("u", u)?;
        check_finite_scalar("torque", tau_d)?;
        check_step(dt, substeps)?;
        self.check_rk4_stability(dt, substeps)?;
        let mut next = *x;
        self.advance(&mut next, u, tau_d, dt, substeps);
        if !next.iter().all(|v| v.is_finite()) {
            return Err(diverged(dt, substeps));
        }
        Ok(next)
    }

    /// The open-loop trajectory `x(0), x(dt), …, x(N dt)` under the zero-order-held inputs
    /// `u[0..N]` (`N + 1` states), `substeps` RK4 steps per interval. Checks as
    /// [`step_checked`](Self::step_checked), and bounds the total work:
    /// `N · substeps ≤` [`MAX_INTEGRATION_STEPS`].
    pub fn integrate(&self, x0: &State, u: &[f64], dt: f64, substeps: usize) -> Result<Vec<State>> {
        check_finite_state("x0", x0)?;
        check_step(dt, substeps)?;
        self.check_rk4_stability(dt, substeps)?;
        if u.iter().any(|v| !v.is_finite()) {
            return Err(RipError::NonFinite { name: "u".into() });
        }
        let work = u.len().saturating_mul(substeps);
        if work > MAX_INTEGRATION_STEPS {
            return Err(RipError::invalid(
                "u",
                format!(
                    "{} intervals × {substeps} substeps = {work} RK4 steps; at most \
                     {MAX_INTEGRATION_STEPS} per call",
                    u.len()
                ),
            ));
        }
        let mut out = Vec::with_capacity(u.len() + 1);
        let mut x = *x0;
        out.push(x);
        for &uk in u {
            self.advance(&mut x, uk, 0.0, dt, substeps);
            if !x.iter().all(|v| v.is_finite()) {
                return Err(diverged(dt, substeps));
            }
            out.push(x);
        }
        Ok(out)
    }

    /// Longest RK4 substep (s) inside classical RK4's stability region for this plant:
    /// `h · ρ(A_c) ≤ 2.78`, the region's extent along the negative real axis, with `ρ(A_c)` the
    /// largest spectral radius of the linearisations about upright and hanging. A longer substep
    /// does not approximate the pendulum at all: the fastest (damping and back-EMF) mode is
    /// amplified by the integrator itself, and the state grows to finite nonsense before it
    /// overflows.
    ///
    /// At rest the smoothed Coulomb friction adds the damping slopes `cr/v_c`, `cp/v_c` (module
    /// docs), usually the stiffest terms of a plant that has them; they are included.
    pub fn max_rk4_substep(&self) -> f64 {
        self.max_substep
    }

    /// [`max_rk4_substep`](Self::max_rk4_substep) from the linearisations' eigenvalues.
    fn rk4_stability_limit(&self) -> f64 {
        #[cfg(test)]
        tests::LIMIT_EVALUATIONS.with(|n| n.set(n.get() + 1));
        let hanging = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
        let rho = [State::zeros(), hanging]
            .iter()
            .map(|x| {
                let (mut a, _) = self.linearize(x, 0.0);
                let ([m11, m12, m22], _) = self.mass_and_forces(x, 0.0, 0.0);
                let det = m11 * m22 - m12 * m12;
                let minv = [[m22 / det, -m12 / det], [-m12 / det, m11 / det]];
                // At rest the arm's friction is at its breakaway level.
                let rest = [self.coulomb[0] + self.stiction, self.coulomb[1]];
                let slope = rest.map(|c| c / COULOMB_VELOCITY_SCALE);
                for (row, i) in [(1usize, 0usize), (3, 1)] {
                    a[(row, 1)] -= minv[i][0] * slope[0];
                    a[(row, 3)] -= minv[i][1] * slope[1];
                }
                spectral_radius(&Mat::from_fn(4, 4, |i, j| a[(i, j)]))
            })
            .fold(0.0, f64::max);
        RK4_STABILITY_LIMIT / rho
    }

    /// Fails, naming `dt`, when `dt / substeps` exceeds [`max_rk4_substep`](Self::max_rk4_substep).
    fn check_rk4_stability(&self, dt: f64, substeps: usize) -> Result<()> {
        let h = dt / substeps as f64;
        let h_max = self.max_rk4_substep();
        if h > h_max {
            return Err(RipError::invalid(
                "dt",
                format!(
                    "dt / substeps = {h:.3e} s is beyond RK4's stability limit for this plant \
                     ({h_max:.3e} s); use more substeps or a shorter dt"
                ),
            ));
        }
        Ok(())
    }

    /// Angular momentum about the arm's (vertical) axis (kg m²/s), `H = ∂T/∂θ̇ =
    /// (J₀ + J_α sin²α) θ̇ − m₁₂ cos α α̇` (the first row of the module docs' mass matrix
    /// times the rates). Gravity and the pendulum's reaction act in planes through that axis,
    /// so only the arm's torques change it: `Ḣ = τ_m − d_r θ̇ − c_r sgn θ̇ + τ_c + τ_d`. An arm
    /// whose rate is braked to 0 under a swinging pendulum keeps whatever `H` the pendulum
    /// holds, and walks at `H / (J₀ + J_α sin²α)` on average once nothing holds it.
    pub fn arm_momentum(&self, x: &State) -> f64 {
        let (s, c) = crate::trig::sin_cos(x[2]);
        (self.j0 + self.ja * s * s) * x[1] - self.m12 * c * x[3]
    }

    /// The arm's inertia about its axis with the pendulum at `alpha` (kg m²), `J₀ + J_α
    /// sin²α`: [`arm_momentum`](Self::arm_momentum) per unit arm rate.
    pub fn arm_inertia(&self, alpha: f64) -> f64 {
        let s = crate::trig::sin_cos(alpha).0;
        self.j0 + self.ja * s * s
    }

    /// The pendulum's energy from hanging to upright, `2 m_p g L_p/2` (J): the span of the
    /// potential of [`energy`](Self::energy).
    pub fn swing_energy(&self) -> f64 {
        2.0 * self.grav
    }

    /// Total mechanical energy `T + V` (J), with `V = G cos α` (module docs). Conserved when
    /// `km = dr = dp = cr = cp = kc = 0` and `u = τ_d = 0` (the cable's potential `kc θ²/2` is
    /// not counted: the swing-up's energy is the pendulum's).
    pub fn energy(&self, x: &State) -> f64 {
        let (s, c) = crate::trig::sin_cos(x[2]);
        let (td, ad) = (x[1], x[3]);
        0.5 * (self.j0 + self.ja * s * s) * td * td - self.m12 * c * td * ad
            + 0.5 * self.ja * ad * ad
            + self.grav * c
    }

    /// Exact Jacobians `A = ∂f/∂x`, `B = ∂f/∂u` at `(x, u)` (with `τ_d = 0`) of the plant
    /// without Coulomb friction and dead zone (module docs: those are left to act on the
    /// controllers as disturbances).
    ///
    /// With `q̈ = M(α)⁻¹ F(x, u)`, the derivative is `∂q̈/∂z = M⁻¹ (∂F/∂z − (∂M/∂z) q̈)`, where
    /// only α enters `M`: `∂M₁₁/∂α = 2 Jα sin α cos α`, `∂M₁₂/∂α = m₁₂ sin α`. At an equilibrium
    /// (`θ̇ = α̇ = 0`, `α ∈ {0, π}`, `u = 0`) this is the linearised model; elsewhere it is the
    /// first-order Taylor model about a moving point.
    pub fn linearize(&self, x: &State, u: f64) -> (SMatrix<f64, 4, 4>, SVector<f64, 4>) {
        let (s, c) = crate::trig::sin_cos(x[2]);
        let (td, ad) = (x[1], x[3]);
        let ([m11, m12, m22], _) = self.mass_and_forces(x, u, 0.0);
        let det = m11 * m22 - m12 * m12;
        let minv = [[m22 / det, -m12 / det], [-m12 / det, m11 / det]];
        let acc = self.smooth_derivative(x, u);
        let (thdd, addd) = (acc[1], acc[3]);
        let c2 = c * c - s * s;
        // ∂F/∂z for z = (θ̇, α, α̇, u); θ enters only through the cable (below).
        let df1 = [
            -self.c_arm - 2.0 * self.ja * s * c * ad,
            -2.0 * self.ja * c2 * td * ad - self.m12 * c * ad * ad,
            -2.0 * self.ja * s * c * td - 2.0 * self.m12 * s * ad,
            self.b,
        ];
        let df2 = [
            2.0 * self.ja * s * c * td,
            self.ja * c2 * td * td + self.grav * c,
            -self.dp,
            0.0,
        ];
        // Only the α column carries the −(∂M/∂α) q̈ term.
        let dm11 = 2.0 * self.ja * s * c;
        let dm12 = self.m12 * s;
        let mut g1 = df1;
        let mut g2 = df2;
        g1[1] -= dm11 * thdd + dm12 * addd;
        g2[1] -= dm12 * thdd;
        let mut a = SMatrix::<f64, 4, 4>::zeros();
        a[(0, 1)] = 1.0;
        a[(2, 3)] = 1.0;
        // θ enters F only through the cable, ∂F₁/∂θ = ∂τ_c/∂θ = −kc (module docs); without one
        // the column stays an exact +0, as the paper's structure has it.
        if self.kc != 0.0 {
            let dcable = cable_torque(1.0, self.kc);
            a[(1, 0)] = minv[0][0] * dcable;
            a[(3, 0)] = minv[1][0] * dcable;
        }
        let cols = [1usize, 2, 3];
        for (k, &col) in cols.iter().enumerate() {
            a[(1, col)] = minv[0][0] * g1[k] + minv[0][1] * g2[k];
            a[(3, col)] = minv[1][0] * g1[k] + minv[1][1] * g2[k];
        }
        let b = SVector::<f64, 4>::new(
            0.0,
            minv[0][0] * g1[3] + minv[0][1] * g2[3],
            0.0,
            minv[1][0] * g1[3] + minv[1][1] * g2[3],
        );
        (a, b)
    }

    /// The continuous-time linearisation about upright, `(A_c, B_c)` as dynamic matrices.
    pub fn linearize_upright(&self) -> (Mat, Mat) {
        let (a, b) = self.linearize(&State::zeros(), 0.0);
        (
            Mat::from_fn(4, 4, |i, j| a[(i, j)]),
            Mat::from_fn(4, 1, |i, _| b[i]),
        )
    }

    /// Zero-order-hold discretisation (period `ts`) of the linearisation at `(x, u)`.
    pub fn linearize_discrete(&self, x: &State, u: f64, ts: f64) -> Result<(Mat, Mat)> {
        let (a, b) = self.linearize(x, u);
        c2d(
            &Mat::from_fn(4, 4, |i, j| a[(i, j)]),
            &Mat::from_fn(4, 1, |i, _| b[i]),
            ts,
        )
    }
}

/// A state per lane, structure of arrays: `z[i][l]` is component `i` of pendulum `l`.
type Lanes<const L: usize> = [[f64; L]; 4];

#[inline(always)]
fn lanes_of<const L: usize>(x: [&State; L]) -> Lanes<L> {
    std::array::from_fn(|i| std::array::from_fn(|l| x[l][i]))
}

/// `M q̈ = f` solved for `(θ̈, α̈)` in every lane.
#[inline(always)]
fn solve<const L: usize>(
    m11: [f64; L],
    m12: [f64; L],
    m22: [f64; L],
    f1: [f64; L],
    f2: [f64; L],
) -> [[f64; L]; 2] {
    let mut out = [[0.0; L]; 2];
    for l in 0..L {
        let det = m11[l] * m22[l] - m12[l] * m12[l];
        out[0][l] = (m22[l] * f1[l] - m12[l] * f2[l]) / det;
        out[1][l] = (m11[l] * f2[l] - m12[l] * f1[l]) / det;
    }
    out
}

/// The lumped coefficients of [`Plant`] of `L` pendulums, one lane each: the one definition of
/// the equations of motion, which one pendulum evaluates with `L = 1`.
#[derive(Clone, Copy)]
struct Coefficients<const L: usize> {
    j0: [f64; L],
    ja: [f64; L],
    m12: [f64; L],
    grav: [f64; L],
    b: [f64; L],
    c_arm: [f64; L],
    dp: [f64; L],
    cr: [f64; L],
    stiction: [f64; L],
    cp: [f64; L],
    vd: [f64; L],
    kc: [f64; L],
}

impl<const L: usize> Coefficients<L> {
    #[inline(always)]
    fn gather(p: [&Plant; L]) -> Self {
        Self {
            j0: p.map(|p| p.j0),
            ja: p.map(|p| p.ja),
            m12: p.map(|p| p.m12),
            grav: p.map(|p| p.grav),
            b: p.map(|p| p.b),
            c_arm: p.map(|p| p.c_arm),
            dp: p.map(|p| p.dp),
            cr: p.map(|p| p.coulomb[0]),
            stiction: p.map(|p| p.stiction),
            cp: p.map(|p| p.coulomb[1]),
            vd: p.map(|p| p.vd),
            kc: p.map(|p| p.kc),
        }
    }

    /// `(M₁₁, M₁₂, M₂₂)` and `(f₁, f₂)` of the module docs without Coulomb friction and dead
    /// zone (the cable included), per lane.
    #[inline(always)]
    fn mass_and_forces(
        &self,
        x: &Lanes<L>,
        u: &[f64; L],
        tau_d: &[f64; L],
    ) -> ([[f64; L]; 3], [[f64; L]; 2]) {
        let (s, c) = crate::trig::sin_cos_lanes(&x[2]);
        let mut m = [[0.0; L]; 3];
        let mut f = [[0.0; L]; 2];
        for l in 0..L {
            let (s, c, td, ad) = (s[l], c[l], x[1][l], x[3][l]);
            let ja = self.ja[l];
            m[0][l] = self.j0[l] + ja * s * s;
            m[1][l] = -self.m12[l] * c;
            m[2][l] = ja;
            f[0][l] = self.b[l] * u[l] - self.c_arm[l] * td
                + cable_torque(x[0][l], self.kc[l])
                + tau_d[l]
                - 2.0 * ja * s * c * td * ad
                - self.m12[l] * s * ad * ad;
            f[1][l] = -self.dp[l] * ad + ja * s * c * td * td + self.grav[l] * s;
        }
        (m, f)
    }

    /// `ẋ` of every lane ([`Plant::derivative`]).
    #[inline(always)]
    fn derivative(&self, x: &Lanes<L>, u: &[f64; L], tau_d: &[f64; L]) -> Lanes<L> {
        let mut applied = [0.0; L];
        for l in 0..L {
            applied[l] = dead_zone(u[l], self.vd[l]);
        }
        let (m, [mut f1, mut f2]) = self.mass_and_forces(x, &applied, tau_d);
        // Skipped at zero so that the frictionless presets cost (and compute) what they did.
        if self.cr.iter().chain(&self.stiction).any(|c| *c != 0.0) {
            for l in 0..L {
                if self.cr[l] != 0.0 || self.stiction[l] != 0.0 {
                    let mut level = self.cr[l];
                    if self.stiction[l] != 0.0 {
                        // The breakaway torque's Stribeck decay (module docs).
                        let s = x[1][l] / STRIBECK_VELOCITY;
                        level += self.stiction[l] * (-s * s).exp();
                    }
                    f1[l] -= level * (x[1][l] / COULOMB_VELOCITY_SCALE).tanh();
                }
            }
        }
        if self.cp.iter().any(|c| *c != 0.0) {
            for l in 0..L {
                if self.cp[l] != 0.0 {
                    f2[l] -= self.cp[l] * (x[3][l] / COULOMB_VELOCITY_SCALE).tanh();
                }
            }
        }
        let [thdd, addd] = solve(m[0], m[1], m[2], f1, f2);
        [x[1], thdd, x[3], addd]
    }

    /// One RK4 step of every lane ([`Plant::rk4_step`]).
    #[inline(always)]
    fn rk4_step(&self, x: &mut Lanes<L>, u: &[f64; L], tau_d: &[f64; L], h: f64) {
        let shifted = |x: &Lanes<L>, k: &Lanes<L>, a: f64| -> Lanes<L> {
            std::array::from_fn(|i| std::array::from_fn(|l| x[i][l] + k[i][l] * a))
        };
        let k1 = self.derivative(x, u, tau_d);
        let k2 = self.derivative(&shifted(x, &k1, 0.5 * h), u, tau_d);
        let k3 = self.derivative(&shifted(x, &k2, 0.5 * h), u, tau_d);
        let k4 = self.derivative(&shifted(x, &k3, h), u, tau_d);
        let w = h / 6.0;
        for i in 0..4 {
            for l in 0..L {
                x[i][l] += (k1[i][l] + (k2[i][l] + k3[i][l]) * 2.0 + k4[i][l]) * w;
            }
        }
    }
}

#[cfg(test)]
mod tests;

//! The complete controller design the host computes and the device runs ([`Design`]), its
//! validation, and its byte layout ([`Design::to_bytes`], [`Design::from_bytes`]; the layout is
//! documented in the crate docs).

use crate::real::Real;

mod layout;

/// Most plant inputs: the rig has one motor.
pub const MAX_NU: usize = 1;
/// Most outputs (arm and pendulum angle).
pub const MAX_NY: usize = 2;
/// Most estimator states: the four plant states and up to four disturbance states.
pub const MAX_NX: usize = 8;
/// Most moves of the MPC's control horizon `m`.
pub const MAX_CONTROL_HORIZON: usize = 4;
/// Most steps of the MPC's prediction horizon `P`.
pub const MAX_PREDICTION_HORIZON: usize = 100;
/// Most QP variables `m·nu + 1` (the moves and the slack `ε`).
pub const MAX_NZ: usize = MAX_CONTROL_HORIZON * MAX_NU + 1;
/// Most QP constraint rows: the hard input bounds of the `m` moves, two soft rows per output
/// and prediction step, and `−ε ≤ 0`.
pub const MAX_NCON: usize =
    2 * MAX_CONTROL_HORIZON * MAX_NU + 2 * MAX_PREDICTION_HORIZON * MAX_NY + 1;
/// Most dual active-set iterations a design may ask for.
pub const MAX_QP_ITERATIONS: u32 = 1000;
/// Instructions a step may take per µs of its period on the device: the STM32F407's 168 MHz
/// at 2 cycles per instruction (flash wait states behind the ART accelerator, multi-cycle FPU
/// divisions), within half the period, the rest left to the link and the checks around it.
pub const STEP_BUDGET_INSTRUCTIONS_PER_US: u64 = 168 / 2 / 2;
/// A regulator's worst step (instructions): above the 1 518 (LQR) and 2 167 (LQG) measured
/// in QEMU (firmware/README.md).
const REGULATOR_STEP_INSTRUCTIONS: u64 = 3_000;
/// Number of plant states `[θ, θ̇, α, α̇]` the regulators feed back.
pub const NX_PLANT: usize = 4;

/// The version of the byte layout written by [`Design::to_bytes`].
pub const LAYOUT_VERSION: u16 = 4;
/// The first four bytes of every encoded design.
pub const MAGIC: [u8; 4] = *b"RIPD";
/// Bytes before the body: magic, version, kind, flags, total length.
pub const HEADER_LEN: usize = 12;

/// Which controller a [`Design`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Kind {
    /// LQR on measured angles, rates from a filtered difference.
    #[default]
    Lqr,
    /// The LQR gain on the plant part of the steady-state Kalman filter's current estimate.
    Lqg,
    /// Constrained MPC on the condensed QP, with the same Kalman filter.
    Mpc,
}

impl Kind {
    /// The byte that stands for the kind in the layout.
    pub fn code(self) -> u8 {
        match self {
            Self::Lqr => 1,
            Self::Lqg => 2,
            Self::Mpc => 3,
        }
    }

    /// The kind of a layout byte.
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(Self::Lqr),
            2 => Some(Self::Lqg),
            3 => Some(Self::Mpc),
            _ => None,
        }
    }

    /// `"lqr"`, `"lqg"` or `"mpc"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Lqr => "lqr",
            Self::Lqg => "lqg",
            Self::Mpc => "mpc",
        }
    }
}

/// Why a design was refused, naming the field (as in the layout and the crate docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DesignError {
    /// The output buffer cannot hold the encoded design; `needed` bytes are.
    BufferTooSmall {
        /// Bytes the encoding needs.
        needed: usize,
    },
    /// The bytes end before the layout does.
    Truncated,
    /// The first four bytes are not [`MAGIC`].
    BadMagic,
    /// A layout version this build does not read.
    UnsupportedVersion(u16),
    /// The length field disagrees with the bytes given.
    LengthMismatch,
    /// The CRC-32 does not match the bytes.
    BadChecksum,
    /// An unknown kind byte.
    UnknownKind(u8),
    /// A size exceeds this build's capacity or is inconsistent.
    BadSize(&'static str),
    /// A number is not finite (or not positive where it must be).
    BadValue(&'static str),
    /// The worst step ([`Design::worst_step_instructions`]) does not fit the period's budget
    /// ([`Design::step_budget_instructions`]) even at one QP iteration, or the design's
    /// `max_iterations` does not.
    OverBudget {
        /// The worst step's instructions at the design's iteration bound.
        instructions: u64,
        /// The budget of its period.
        budget: u64,
    },
}

impl core::fmt::Display for DesignError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BufferTooSmall { needed } => write!(f, "buffer too small: {needed} bytes needed"),
            Self::Truncated => f.write_str("design bytes end early"),
            Self::BadMagic => f.write_str("not a design (bad magic)"),
            Self::UnsupportedVersion(v) => write!(f, "unsupported design layout version {v}"),
            Self::LengthMismatch => f.write_str("design length field does not match"),
            Self::BadChecksum => f.write_str("design CRC-32 does not match"),
            Self::UnknownKind(k) => write!(f, "unknown controller kind {k}"),
            Self::BadSize(name) => write!(f, "{name}: size out of range"),
            Self::BadValue(name) => write!(f, "{name}: invalid value"),
            Self::OverBudget {
                instructions,
                budget,
            } => write!(
                f,
                "max_iterations: the worst step, {instructions} instructions, exceeds the \
                 period's budget of {budget}"
            ),
        }
    }
}

/// The voltage dead-zone and arm-friction compensation (rip-core's `compensation` module docs
/// give the law); all zero for none.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CompensationDesign<R: Real = f64> {
    /// Dead zone `V_d` (V, ≥ 0).
    pub dead_zone: R,
    /// Arm Coulomb friction as a voltage `V_f = C_r R_m / k_t` (V, ≥ 0).
    pub friction_voltage: R,
    /// Width `v_s` of the dead-zone sign ramp (V, > 0).
    pub voltage_scale: R,
    /// Width `ω_s` of the friction sign ramp (rad/s, > 0).
    pub velocity_scale: R,
}

impl<R: Real> CompensationDesign<R> {
    /// Whether there is anything to compensate.
    pub fn is_active(&self) -> bool {
        self.dead_zone != R::ZERO || self.friction_voltage != R::ZERO
    }

    /// `w = v + V_f σ(θ̇̂/ω_s)`, `u = w + V_d σ(w/v_s)`, before the final clamp to the input
    /// bounds (crate docs, "Compensation"). A non-finite rate counts as zero.
    #[inline]
    pub fn unclamped(&self, v: R, arm_rate: R) -> R {
        let rate = if arm_rate.is_finite() {
            arm_rate
        } else {
            R::ZERO
        };
        let w = v + self.friction_voltage * ramp_sign(rate / self.velocity_scale);
        w + self.dead_zone * ramp_sign(w / self.voltage_scale)
    }

    /// `z(u) − V_f σ(θ̇̂/ω_s)`: the voltage the linear model sees when `u` is written (the
    /// inverse of the law outside the ramps). A non-finite rate counts as zero.
    #[inline]
    pub fn effective(&self, u: R, arm_rate: R) -> R {
        let rate = if arm_rate.is_finite() {
            arm_rate
        } else {
            R::ZERO
        };
        let z = u - u.clamp(-self.dead_zone, self.dead_zone);
        z - self.friction_voltage * ramp_sign(rate / self.velocity_scale)
    }
}

/// A continuous sign: `clamp(s, −1, 1)`.
#[inline]
fn ramp_sign<R: Real>(s: R) -> R {
    s.clamp(-R::ONE, R::ONE)
}

/// A complete controller design: everything a [`Controller`](crate::Controller) needs, made on
/// the host (DARE, Kalman design, condensing in rip-core) and run wherever the controller runs.
///
/// Matrices are row-major in fixed-capacity arrays; only the leading `rows × cols` entries
/// given by the sizes are used (and encoded). Fields a kind does not use are zero.
#[derive(Debug, Clone, PartialEq)]
pub struct Design<R: Real = f64> {
    /// Which controller.
    pub kind: Kind,
    /// Sample time `Ts` (s, > 0).
    pub ts: R,
    /// Bounds `[u_min, u_max]` of the written voltage (finite, `u_min < u_max`). The regulators
    /// and the MPC plan within them (the MPC's own hard bounds are in its rows); the
    /// compensation's final clamp uses them too.
    pub input_bounds: [R; 2],
    /// LQR/LQG gain `K` (1×4, `u = −K (x − x_ref)`).
    pub k: [R; NX_PLANT],
    /// Integral gain `k_i` on the arm error (0: none).
    pub integral_gain: R,
    /// LQR rate-filter cut-off (Hz, > 0; `+∞` for the plain difference).
    pub rate_cutoff_hz: R,
    /// The law cancels an estimated disturbance `d` at the plant input
    /// (`x[k+1] = A x + B (u + d)`): `u = −K (x̂ − x_ref) − d̂` (crate docs, "LQR" and "LQG").
    /// LQG: the estimator's last state is `d`. LQR: `d̂` comes from the observer of
    /// [`disturbance_gain`](Self::disturbance_gain) on the 4-state model `a`, `b`.
    /// Byte-layout flag bit 0.
    pub cancels_input_disturbance: bool,
    /// LQG only: the law regulates the estimated outputs rather than the plant part of the
    /// estimate alone. Each angle's state takes on the estimate of what the estimator's extra
    /// states (an output disturbance) add to that output, `θ̂ ← θ̂ + s_θ Σ_{j≥4} C[0,j] x̂_j`
    /// and `α̂ ← α̂ + s_α Σ_{j≥4} C[1,j] x̂_j`, as the MPC's cost weights the outputs `y`
    /// (crate docs, "Estimator"). Byte-layout flag bit 1.
    pub regulates_outputs: bool,
    /// LQR's input-disturbance observer gain `g` (1×4), used with
    /// [`cancels_input_disturbance`](Self::cancels_input_disturbance):
    /// `d̂ ← d̂ + g (x̂ − x̂⁻)`, `x̂⁻` the model's prediction of `x̂` (crate docs, "LQR").
    pub disturbance_gain: [R; NX_PLANT],
    /// Estimator states `n` (LQG: ≥ 4, ≥ 5 with [`cancels_input_disturbance`]; MPC: the
    /// augmented model's; LQR: 4 with [`cancels_input_disturbance`], the observer's model,
    /// else unused).
    ///
    /// [`cancels_input_disturbance`]: Self::cancels_input_disturbance
    pub nx: usize,
    /// Outputs `ny` (2 for the rig).
    pub ny: usize,
    /// Estimator `A` (n×n).
    pub a: [R; MAX_NX * MAX_NX],
    /// Estimator `B_u` (n×1).
    pub b: [R; MAX_NX],
    /// Estimator `C` (ny×n), on the scaled outputs `y / s_y`.
    pub c: [R; MAX_NY * MAX_NX],
    /// Predictor gain `L` (n×ny).
    pub l: [R; MAX_NX * MAX_NY],
    /// Innovation gain `M` (n×ny).
    pub m: [R; MAX_NX * MAX_NY],
    /// Output scales `s_y` (the estimator sees `y / s_y`; 1 for the LQG).
    pub output_scales: [R; MAX_NY],
    /// MPC prediction horizon `P`.
    pub horizon: usize,
    /// MPC control horizon `m`.
    pub control_horizon: usize,
    /// QP constraint rows in use.
    pub ncon: usize,
    /// Hard input rows (first) of the constraints.
    pub n_input_rows: usize,
    /// Soft output rows (next); the last row is `−ε ≤ 0`.
    pub n_soft_rows: usize,
    /// QP Hessian `H` (nz×nz, nz = m + 1).
    pub h: [R; MAX_NZ * MAX_NZ],
    /// `f = f0 + F_x x + F_u u⁻ − F_r r` (nz).
    pub f0: [R; MAX_NZ],
    /// `F_x` (nz×n).
    pub fx: [R; MAX_NZ * MAX_NX],
    /// `F_u` (nz×1).
    pub fu: [R; MAX_NZ],
    /// `F_r` (nz×ny): the map of a constant reference held over the horizon.
    pub fr: [R; MAX_NZ * MAX_NY],
    /// Constraint matrix `A_c` (ncon×nz).
    pub ac: [R; MAX_NCON * MAX_NZ],
    /// `b = b0 + B_x x + B_u u⁻` (ncon).
    pub b0: [R; MAX_NCON],
    /// `B_x` (ncon×n).
    pub bx: [R; MAX_NCON * MAX_NX],
    /// `B_u` (ncon×1).
    pub bu: [R; MAX_NCON],
    /// Dual active-set iteration bound (1..=[`MAX_QP_ITERATIONS`]); the fallback law applies
    /// when it is hit.
    pub max_iterations: u32,
    /// The compensation (zero: none).
    pub compensation: CompensationDesign<R>,
}

impl<R: Real> Default for Design<R> {
    fn default() -> Self {
        let mut d = Self::zeroed();
        d.clear(Kind::Lqr);
        d
    }
}

impl<R: Real> Design<R> {
    /// Every number and size zero (not a valid design), `const` for a firmware's static that
    /// [`read_from`](Self::read_from) fills in place.
    pub const fn zeroed() -> Self {
        let z = R::ZERO;
        Self {
            kind: Kind::Lqr,
            ts: z,
            input_bounds: [z; 2],
            k: [z; NX_PLANT],
            integral_gain: z,
            rate_cutoff_hz: z,
            cancels_input_disturbance: false,
            regulates_outputs: false,
            disturbance_gain: [z; NX_PLANT],
            nx: 0,
            ny: 0,
            a: [z; MAX_NX * MAX_NX],
            b: [z; MAX_NX],
            c: [z; MAX_NY * MAX_NX],
            l: [z; MAX_NX * MAX_NY],
            m: [z; MAX_NX * MAX_NY],
            output_scales: [z; MAX_NY],
            horizon: 0,
            control_horizon: 0,
            ncon: 0,
            n_input_rows: 0,
            n_soft_rows: 0,
            h: [z; MAX_NZ * MAX_NZ],
            f0: [z; MAX_NZ],
            fx: [z; MAX_NZ * MAX_NX],
            fu: [z; MAX_NZ],
            fr: [z; MAX_NZ * MAX_NY],
            ac: [z; MAX_NCON * MAX_NZ],
            b0: [z; MAX_NCON],
            bx: [z; MAX_NCON * MAX_NX],
            bu: [z; MAX_NCON],
            max_iterations: 0,
            compensation: CompensationDesign {
                dead_zone: z,
                friction_voltage: z,
                voltage_scale: z,
                velocity_scale: z,
            },
        }
    }

    /// The defaults ([`Default`]) with `kind`, written in place: a design is tens of
    /// kilobytes, more than a firmware's stack should hold as a temporary.
    fn clear(&mut self, kind: Kind) {
        let z = R::ZERO;
        self.kind = kind;
        self.ts = R::from_f64(0.01);
        self.input_bounds = [
            R::from_f64(-crate::INPUT_LIMIT),
            R::from_f64(crate::INPUT_LIMIT),
        ];
        self.k = [z; NX_PLANT];
        self.integral_gain = z;
        self.rate_cutoff_hz = R::from_f64(20.0);
        self.cancels_input_disturbance = false;
        self.regulates_outputs = false;
        self.disturbance_gain = [z; NX_PLANT];
        self.nx = 0;
        self.ny = 0;
        self.output_scales = [R::ONE; MAX_NY];
        self.horizon = 0;
        self.control_horizon = 0;
        self.ncon = 0;
        self.n_input_rows = 0;
        self.n_soft_rows = 0;
        self.max_iterations = 200;
        self.compensation = CompensationDesign::default();
        for a in [
            &mut self.a[..],
            &mut self.b,
            &mut self.c,
            &mut self.l,
            &mut self.m,
            &mut self.h,
            &mut self.f0,
            &mut self.fx,
            &mut self.fu,
            &mut self.fr,
            &mut self.ac,
            &mut self.b0,
            &mut self.bx,
            &mut self.bu,
        ] {
            a.fill(z);
        }
    }
}

fn finite<R: Real>(name: &'static str, v: &[R]) -> Result<(), DesignError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(DesignError::BadValue(name))
    }
}

impl<R: Real> Design<R> {
    /// QP variables `m + 1`.
    pub fn nz(&self) -> usize {
        self.control_horizon * MAX_NU + 1
    }

    /// Checks sizes against the capacities and every number for what it must be; the error
    /// names the field. [`Controller::new`](crate::Controller::new) and
    /// [`from_bytes`](Self::from_bytes) call it.
    pub fn validate(&self) -> Result<(), DesignError> {
        use DesignError::{BadSize, BadValue};
        if !(self.ts.is_finite() && self.ts > R::ZERO) {
            return Err(BadValue("ts"));
        }
        let [lo, hi] = self.input_bounds;
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(BadValue("input_bounds"));
        }
        finite("k", &self.k)?;
        finite("integral_gain", &[self.integral_gain])?;
        let c = self.compensation;
        finite("compensation", &[c.dead_zone, c.friction_voltage])?;
        if c.dead_zone < R::ZERO || c.friction_voltage < R::ZERO {
            return Err(BadValue("compensation"));
        }
        if c.is_active() && !(c.voltage_scale > R::ZERO && c.velocity_scale > R::ZERO) {
            return Err(BadValue("compensation.scales"));
        }
        let cancels = self.cancels_input_disturbance;
        if cancels
            && match self.kind {
                Kind::Lqr => self.nx != NX_PLANT,
                Kind::Lqg => self.nx <= NX_PLANT,
                Kind::Mpc => true,
            }
        {
            return Err(BadValue("cancels_input_disturbance"));
        }
        // The law adds the states beyond the plant's four to the angles: an LQG without them,
        // or whose fifth is an input disturbance, has none to add.
        if self.regulates_outputs && (self.kind != Kind::Lqg || self.nx <= NX_PLANT || cancels) {
            return Err(BadValue("regulates_outputs"));
        }
        match self.kind {
            Kind::Lqr => {
                // NaN fails the comparison; +∞ is the plain difference.
                if self.rate_cutoff_hz.partial_cmp(&R::ZERO) != Some(core::cmp::Ordering::Greater) {
                    return Err(BadValue("rate_cutoff_hz"));
                }
                if cancels {
                    finite("a", &self.a[..NX_PLANT * NX_PLANT])?;
                    finite("b", &self.b[..NX_PLANT])?;
                    finite("disturbance_gain", &self.disturbance_gain)?;
                }
                return Ok(());
            }
            Kind::Lqg => {
                if self.nx < NX_PLANT || self.nx > MAX_NX {
                    return Err(BadSize("nx"));
                }
                if self.ny != 2 {
                    return Err(BadSize("ny"));
                }
            }
            Kind::Mpc => {
                if self.nx == 0 || self.nx > MAX_NX {
                    return Err(BadSize("nx"));
                }
                if self.ny == 0 || self.ny > MAX_NY {
                    return Err(BadSize("ny"));
                }
            }
        }
        let (n, ny) = (self.nx, self.ny);
        finite("a", &self.a[..n * n])?;
        finite("b", &self.b[..n])?;
        finite("c", &self.c[..ny * n])?;
        finite("l", &self.l[..n * ny])?;
        finite("m", &self.m[..n * ny])?;
        if !self.output_scales[..ny]
            .iter()
            .all(|s| s.is_finite() && *s > R::ZERO)
        {
            return Err(BadValue("output_scales"));
        }
        if self.kind != Kind::Mpc {
            return Ok(());
        }
        if self.horizon == 0 || self.horizon > MAX_PREDICTION_HORIZON {
            return Err(BadSize("horizon"));
        }
        if self.control_horizon == 0
            || self.control_horizon > MAX_CONTROL_HORIZON
            || self.control_horizon > self.horizon
        {
            return Err(BadSize("control_horizon"));
        }
        if self.ncon == 0
            || self.ncon > MAX_NCON
            || self.n_input_rows + self.n_soft_rows + 1 != self.ncon
        {
            return Err(BadSize("ncon"));
        }
        if self.max_iterations == 0 || self.max_iterations > MAX_QP_ITERATIONS {
            return Err(BadSize("max_iterations"));
        }
        let nz = self.nz();
        finite("h", &self.h[..nz * nz])?;
        finite("f0", &self.f0[..nz])?;
        finite("fx", &self.fx[..nz * n])?;
        finite("fu", &self.fu[..nz])?;
        finite("fr", &self.fr[..nz * ny])?;
        finite("ac", &self.ac[..self.ncon * nz])?;
        finite("b0", &self.b0[..self.ncon])?;
        finite("bx", &self.bx[..self.ncon * n])?;
        finite("bu", &self.bu[..self.ncon])?;
        Ok(())
    }

    /// The worst step's instructions on the Cortex-M4F in `f32`, at `iterations` QP
    /// iterations: for the MPC, the model fitted to QEMU's counts of the paper's design
    /// (firmware/README.md; n = 5, ncon = 107, nz = 4: 17 800 + 5 300 (I − 1) measured)
    ///
    /// ```text
    /// N(I) = 2 400 + 8 ncon (n + 1) + 12.5 ncon nz (I + 1)
    /// ```
    ///
    /// the fixed part (counts to angles, the Kalman correction, the plan), the QP data `f`, `b`
    /// (one multiply-add per row and state), and the solve: the data `d` of every row and one
    /// pass over the rows per iteration. For the paper's design it gives 18 236 at I = 1 and
    /// 28 936 at I = 3, above the 28 339 measured. Regulators: a constant above their measured
    /// worst.
    pub fn worst_step_instructions_at(&self, iterations: u32) -> u64 {
        if self.kind != Kind::Mpc {
            return REGULATOR_STEP_INSTRUCTIONS;
        }
        let (n, ncon, nz) = (self.nx as u64, self.ncon as u64, self.nz() as u64);
        2_400 + 8 * ncon * (n + 1) + 25 * ncon * nz * (u64::from(iterations) + 1) / 2
    }

    /// [`worst_step_instructions_at`](Self::worst_step_instructions_at) the design's
    /// `max_iterations`.
    pub fn worst_step_instructions(&self) -> u64 {
        self.worst_step_instructions_at(self.max_iterations)
    }

    /// The instructions a step may take in the design's period `Ts`:
    /// `Ts · `[`STEP_BUDGET_INSTRUCTIONS_PER_US`].
    pub fn step_budget_instructions(&self) -> u64 {
        let us = libm::round(self.ts.to_f64() * 1e6);
        if us.is_finite() && us > 0.0 {
            us as u64 * STEP_BUDGET_INSTRUCTIONS_PER_US
        } else {
            0
        }
    }

    /// The largest QP iteration bound whose worst step fits the period's budget (at most
    /// [`MAX_QP_ITERATIONS`]); 0 when not even one iteration does. A regulator needs none:
    /// [`MAX_QP_ITERATIONS`] if it fits, else 0.
    pub fn fitting_iterations(&self) -> u32 {
        let budget = self.step_budget_instructions();
        if self.worst_step_instructions_at(1) > budget {
            return 0;
        }
        if self.kind != Kind::Mpc {
            return MAX_QP_ITERATIONS;
        }
        // N(I) increases with I: the last I whose N(I) fits.
        let (mut lo, mut hi) = (1u32, MAX_QP_ITERATIONS);
        while lo < hi {
            let mid = lo + (hi - lo).div_ceil(2);
            if self.worst_step_instructions_at(mid) <= budget {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        lo
    }

    /// Whether the worst step at the design's iteration bound fits its period's budget: what
    /// the host requires of a design before it sends it, and the device before it runs it.
    ///
    /// # Errors
    /// [`DesignError::OverBudget`] with the two counts.
    pub fn check_step_budget(&self) -> Result<(), DesignError> {
        let instructions = self.worst_step_instructions();
        let budget = self.step_budget_instructions();
        if instructions > budget {
            return Err(DesignError::OverBudget {
                instructions,
                budget,
            });
        }
        Ok(())
    }
}

//! The discrete algebraic Riccati equation (DARE).
//!
//! [`dare`] returns the stabilizing solution `X = Xᵀ` of the generalized equation
//! (python-control `dare`, MATLAB `idare`)
//!
//! ```text
//! AᵀXA − EᵀXE − (AᵀXB + S)(BᵀXB + R)⁻¹(BᵀXA + Sᵀ) + Q = 0,
//! ```
//!
//! the gain `G = (BᵀXB + R)⁻¹(BᵀXA + Sᵀ)` and the closed-loop eigenvalues `eig(A − BG, E)`.
//!
//! The solver is the structured doubling algorithm (SDA) of Chu, Fan and Lin (2005). With
//! `A₀ = A − BR⁻¹Sᵀ`, `G₀ = BR⁻¹Bᵀ`, `H₀ = Q − SR⁻¹Sᵀ` it iterates
//!
//! ```text
//! W   = I + G_k H_k
//! A₊  = A_k W⁻¹ A_k
//! G₊  = G_k + A_k W⁻¹ G_k A_kᵀ
//! H₊  = H_k + A_kᵀ H_k W⁻¹ A_k          (H_k → X quadratically)
//! ```
//!
//! It never inverts `A`, so singular `A` (delays, pure integrators in discrete time) is fine,
//! unlike methods built on the symplectic matrix. `E` is eliminated up front
//! (`Â = E⁻¹A`, `B̂ = E⁻¹B`, `X = E⁻ᵀ Y E⁻¹`). Every answer is checked: the closed loop must be
//! Schur stable and the relative residual below [`DARE_RESIDUAL_TOLERANCE`]; otherwise the
//! failure is diagnosed (an unstable mode the input cannot reach, by the PBH test, or no
//! stabilizing solution) instead of returning a wrong matrix.
//!
//! Where `BᵀXB + R` is invertible but indefinite at the solution (DAREX 1.2 with its `S`, and
//! 1.4), the doubling finds no stabilizing gain; Newton's method on the true equation, started
//! from the gain of the auxiliary problem `Q = I`, `R = I`, `S = 0`, then finds the stabilizing
//! solution, its intermediate Stein equations solved in Kronecker form where the closed loop
//! is not yet stable.
//!
//! `R` need only be positive semidefinite: the equation needs `BᵀXB + R` invertible, not `R`
//! (SLICOT's and scipy's DAREX examples 3 and 4 have `R = 0` and a singular `R`). For a
//! singular `R` the doubling runs on `R + δI` (`δ = 10⁻⁶` of the problem's scale) only to find
//! a stabilizing gain, and Newton's method (Hewer 1971), whose steps need `BᵀX_kB + R`
//! invertible but never `R⁻¹`, converges from it to the solution of the true equation; the
//! same closed-loop and residual checks then apply.
//!
//! State dimensions up to 8 run the iteration on stack-allocated `SMatrix` types.

use nalgebra::{
    allocator::Allocator, Complex, Const, DMatrix, DefaultAllocator, DimMin, Dyn, OMatrix,
};

use crate::error::{Result, RipError};
use crate::linalg::{
    check_finite, check_psd, check_shape, check_state_matrix, check_symmetric, eigenvalues,
    symmetrize, Mat,
};

/// Relative residual above which a DARE solution is rejected.
pub const DARE_RESIDUAL_TOLERANCE: f64 = 1e-8;

const SDA_MAX_ITERATIONS: usize = 100;
/// Relative residual above which the doubling's solution is polished by Newton's method; the
/// doubling alone reaches `~1e-15` on well-conditioned problems, so only ill-conditioned ones
/// (say `cond(R) ≳ 1e8`, where `BR⁻¹Bᵀ` loses digits) pay for the polish.
const NEWTON_REFINEMENT_THRESHOLD: f64 = 1e-13;
/// Newton (Hewer) steps allowed when refining a DARE solution.
const NEWTON_MAX_ITERATIONS: usize = 50;
/// A mode counts as "unstable" for the stabilizability test when `|λ| ≥ 1 − this`.
const UNIT_CIRCLE_MARGIN: f64 = 1e-9;

/// The stabilizing solution of a DARE with what was computed alongside it.
#[derive(Debug, Clone)]
pub struct DareSolution {
    /// The stabilizing solution `X = Xᵀ`.
    pub x: Mat,
    /// `G = (BᵀXB + R)⁻¹(BᵀXA + Sᵀ)`; the optimal feedback is `u = −G x`.
    pub gain: Mat,
    /// Eigenvalues of the closed loop, `eig(A − BG, E)`.
    pub closed_loop_eigenvalues: Vec<Complex<f64>>,
    /// Doubling steps taken.
    pub iterations: usize,
    /// `‖residual‖_F / (‖Q‖_F + ‖X‖_F (1 + ‖A‖_F²))`.
    pub relative_residual: f64,
}

/// Why a validated DARE could not be solved; callers name the pair in their own terms.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum DareFailure {
    /// An eigenvalue of `A` on or outside the unit circle that `B` cannot reach.
    Unreachable(Complex<f64>),
    /// Everything else, with a reason.
    NoSolution(String),
}

impl DareFailure {
    /// Maps the failure onto the public error, naming the pair as `pair`; `dual` marks a
    /// filtering problem, where unreachability of `(Aᵀ, Cᵀ)` means `(A, C)` is not detectable.
    pub(crate) fn into_error(self, pair: &str, dual: bool) -> RipError {
        match self {
            DareFailure::Unreachable(z) if dual => RipError::NotDetectable {
                pair: pair.to_string(),
                re: z.re,
                im: z.im,
                modulus: z.norm(),
            },
            DareFailure::Unreachable(z) => RipError::NotStabilizable {
                pair: pair.to_string(),
                re: z.re,
                im: z.im,
                modulus: z.norm(),
            },
            DareFailure::NoSolution(reason) => RipError::NoStabilizingSolution { reason },
        }
    }
}

/// Solves the generalized DARE (see the module docs) after validating every argument.
///
/// `s` defaults to zero and `e` to the identity. Errors name the argument (`A`, `B`, `Q`, `R`,
/// `S`, `E`) or the pair `(A, B)`.
pub fn dare(
    a: &Mat,
    b: &Mat,
    q: &Mat,
    r: &Mat,
    s: Option<&Mat>,
    e: Option<&Mat>,
) -> Result<DareSolution> {
    let n = check_state_matrix(
        "A",
        a,
        &[("B", b.nrows()), ("Q", q.nrows()), ("Q", q.ncols())],
    )?;
    let m = b.ncols();
    check_shape("B", b, n, m)?;
    if m == 0 {
        return Err(RipError::Shape {
            name: "B".into(),
            expected: format!("({n}, m) with m ≥ 1"),
            rows: b.nrows(),
            cols: 0,
        });
    }
    check_shape("Q", q, n, n)?;
    check_shape("R", r, m, m)?;
    if let Some(s) = s {
        check_shape("S", s, n, m)?;
    }
    if let Some(e) = e {
        check_shape("E", e, n, n)?;
    }
    for (name, mat) in [("A", a), ("B", b), ("Q", q), ("R", r)] {
        check_finite(name, mat)?;
    }
    if let Some(s) = s {
        check_finite("S", s)?;
    }
    if let Some(e) = e {
        check_finite("E", e)?;
    }
    check_symmetric("Q", q)?;
    check_symmetric("R", r)?;
    check_psd("R", &symmetrize(r))?;
    solve_dare_validated(a, b, &symmetrize(q), &symmetrize(r), s, e)
        .map_err(|f| f.into_error("(A, B)", false))
}

/// The solver behind [`dare`], for arguments already validated by the caller.
pub(crate) fn solve_dare_validated(
    a: &Mat,
    b: &Mat,
    q: &Mat,
    r: &Mat,
    s: Option<&Mat>,
    e: Option<&Mat>,
) -> std::result::Result<DareSolution, DareFailure> {
    let solve = Solve::new(Args { a, b, q, r, s, e })?;
    // The doubling needs R⁻¹ and converges to the stabilizing solution only where BᵀXB + R is
    // positive definite; where it is merely invertible (indefinite Q or a singular R with a
    // cross term, SLICOT's DAREX 1.2 and 1.4) it finds no stabilizing gain. Newton's method on
    // the true equation, started from the gain of the auxiliary problem Q = I, R = I, S = 0
    // (stabilizing whenever (A, B) is stabilizable), converges to the stabilizing solution
    // there; the same closed-loop and residual checks decide.
    let (solution, x, relative_residual) = match solve.main_path() {
        Ok(done) if acceptable(&done) => done,
        first => match (solve.newton_on_auxiliary_gain(), first) {
            (Some(done), _) | (None, Ok(done)) => done,
            (None, Err(failure)) => return Err(failure),
        },
    };
    let ClosedLoop {
        gain,
        eigenvalues: closed_loop_eigenvalues,
        radius,
    } = solution.closed_loop;
    let iterations = solution.iterations;
    if radius.is_nan() || radius >= 1.0 - UNIT_CIRCLE_MARGIN {
        return Err(solve.diagnose(format!(
            "the closed loop has spectral radius {radius:.6} ≥ 1 (a mode on the unit circle?)"
        )));
    }
    if relative_residual.is_nan() || relative_residual > DARE_RESIDUAL_TOLERANCE {
        return Err(solve.diagnose(format!(
            "relative residual {relative_residual:.3e} exceeds {DARE_RESIDUAL_TOLERANCE:.0e}"
        )));
    }
    Ok(DareSolution {
        x,
        gain,
        closed_loop_eigenvalues,
        iterations,
        relative_residual,
    })
}

/// A candidate with its solution `X` of the original problem and that one's relative residual.
type Checked = (Candidate, Mat, f64);

/// Whether a checked candidate is the stabilizing solution to the required accuracy.
fn acceptable(done: &Checked) -> bool {
    let (radius, residual) = (done.0.closed_loop.radius, done.2);
    radius < 1.0 - UNIT_CIRCLE_MARGIN && residual <= DARE_RESIDUAL_TOLERANCE
}

/// The arguments of [`solve_dare_validated`].
#[derive(Clone, Copy)]
struct Args<'a> {
    a: &'a Mat,
    b: &'a Mat,
    q: &'a Mat,
    /// The true `R`.
    r: &'a Mat,
    s: Option<&'a Mat>,
    e: Option<&'a Mat>,
}

/// One DARE being solved: the arguments, their reduction to the standard problem and the
/// doubling's starting matrices.
struct Solve<'a> {
    args: Args<'a>,
    /// `R + δI` where `R` is singular (the doubling needs `R⁻¹`).
    regularised: Option<Mat>,
    a_hat: Mat,
    b_hat: Mat,
    e_inv: Option<Mat>,
    a0: Mat,
    g0: Mat,
    h0: Mat,
}

impl<'a> Solve<'a> {
    fn new(args: Args<'a>) -> std::result::Result<Self, DareFailure> {
        let Args { a, b, q, r, s, e } = args;
        // Generalized problem → standard one in Y = EᵀXE with Â = E⁻¹A, B̂ = E⁻¹B.
        let (a_hat, b_hat, e_inv) = match e {
            Some(e) => {
                let lu = e.clone().lu();
                let e_inv = lu
                    .try_inverse()
                    .ok_or_else(|| DareFailure::NoSolution("E is singular".into()))?;
                (&e_inv * a, &e_inv * b, Some(e_inv))
            }
            None => (a.clone(), b.clone(), None),
        };
        // A singular R (scipy's and SLICOT's DAREX examples 3 and 4) has no R⁻¹ for the
        // doubling. The doubling then runs on R + δI, only to find a stabilizing gain;
        // Newton's method, which needs BᵀXB + R invertible but never R⁻¹, finishes on the
        // true R.
        let regularised = match r.clone().cholesky() {
            Some(_) => None,
            None => {
                let scale = r.norm().max(b_hat.norm_squared() * q.norm()).max(1e-12);
                Some(r + Mat::identity(r.nrows(), r.nrows()) * (1e-6 * scale))
            }
        };
        let r_chol = regularised
            .as_ref()
            .unwrap_or(r)
            .clone()
            .cholesky()
            .ok_or_else(|| DareFailure::NoSolution("R + δI is not positive definite".into()))?;
        let r_inv_bt = r_chol.solve(&b_hat.transpose());
        let g0 = symmetrize(&(&b_hat * &r_inv_bt));
        let (a0, h0) = match s {
            Some(s) => {
                let r_inv_st = r_chol.solve(&s.transpose());
                (
                    &a_hat - &b_hat * &r_inv_st,
                    symmetrize(&(q - s * &r_inv_st)),
                )
            }
            None => (a_hat.clone(), q.clone()),
        };
        Ok(Self {
            args,
            regularised,
            a_hat,
            b_hat,
            e_inv,
            a0,
            g0,
            h0,
        })
    }

    /// The `R` the doubling works with: the true one, or `R + δI` where that is singular.
    fn doubling_r(&self) -> &Mat {
        self.regularised.as_ref().unwrap_or(self.args.r)
    }

    /// The standard problem with weight `r`.
    fn problem<'b>(&'b self, r: &'b Mat) -> StandardDare<'b> {
        StandardDare {
            a: &self.a_hat,
            b: &self.b_hat,
            q: self.args.q,
            r,
            s: self.args.s,
        }
    }

    /// A failure: the unreachable unstable mode when there is one, else `reason`.
    fn diagnose(&self, reason: String) -> DareFailure {
        match unreachable_unstable_mode(self.args.a, self.args.b, self.args.e) {
            Some(z) => DareFailure::Unreachable(z),
            None => DareFailure::NoSolution(reason),
        }
    }

    /// The doubling from `H₀ = h`, with the gain and closed loop of its result.
    fn doubling(&self, h: &Mat) -> Option<Candidate> {
        let (y, iterations) = sda_dispatch(&self.a0, &self.g0, h)?;
        let y = symmetrize(&y);
        let closed_loop = self.problem(self.doubling_r()).closed_loop(&y)?;
        Some(Candidate {
            y,
            closed_loop,
            iterations,
        })
    }

    /// `candidate` with its `X` and that one's residual in the problem of weight `r`.
    fn checked(&self, candidate: Candidate, r: &Mat) -> Checked {
        let x = unreduce(&candidate.y, self.e_inv.as_ref());
        let Args { a, b, q, s, e, .. } = self.args;
        let residual = dare_relative_residual(a, b, q, r, s, e, &x);
        (candidate, x, residual)
    }

    /// Newton's method on the problem of weight `r` from `start`'s gain, its steps added to
    /// `start`'s, checked; `what` says which Newton run failed.
    fn newton_from(
        &self,
        start: Candidate,
        r: &Mat,
        what: &str,
    ) -> std::result::Result<Checked, DareFailure> {
        let problem = self.problem(r);
        let (y, newton_steps) = problem
            .newton(start.closed_loop.gain)
            .ok_or_else(|| self.diagnose(what.into()))?;
        let closed_loop = problem
            .closed_loop(&y)
            .ok_or_else(|| self.diagnose("BᵀXB + R is singular at the solution".into()))?;
        let candidate = Candidate {
            y,
            closed_loop,
            iterations: start.iterations + newton_steps,
        };
        Ok(self.checked(candidate, r))
    }

    /// The doubling, refined by Newton's method where it is not accurate enough, and finished
    /// on the true `R` where the doubling ran on `R + δI`.
    ///
    /// The doubling from H₀ converges to the stabilizing solution when (H₀, A₀) is detectable;
    /// otherwise (an unstable mode Q does not weigh) it may settle on another solution, and
    /// with an ill-conditioned R its G₀ = BR⁻¹Bᵀ limits the accuracy. Both are repaired by
    /// Newton's method from a stabilizing gain: the doubling's own when it stabilizes, else
    /// that of the doubling on H₀ + δI, which is detectable for any δ > 0.
    fn main_path(&self) -> std::result::Result<Checked, DareFailure> {
        let r = self.doubling_r();
        let doubled = self
            .doubling(&self.h0)
            .filter(|c| c.closed_loop.radius < 1.0 - UNIT_CIRCLE_MARGIN)
            .map(|c| self.checked(c, r));
        let (solution, x, relative_residual) = match doubled {
            Some(done) if done.2 <= NEWTON_REFINEMENT_THRESHOLD => done,
            doubled => {
                let start = match doubled {
                    Some((candidate, _, _)) => candidate,
                    None => {
                        let delta = 1e-6 * self.h0.norm().max(1.0);
                        let n = self.h0.nrows();
                        let h_reg = &self.h0 + Mat::identity(n, n) * delta;
                        self.doubling(&h_reg)
                            .filter(|c| c.closed_loop.radius < 1.0)
                            .ok_or_else(|| {
                                self.diagnose(
                                    "the doubling iteration found no stabilizing gain to start \
                                     from"
                                        .into(),
                                )
                            })?
                    }
                };
                self.newton_from(
                    start,
                    r,
                    "Newton's method did not converge to a stabilizing solution",
                )?
            }
        };
        if self.regularised.is_none() {
            return Ok((solution, x, relative_residual));
        }
        self.newton_from(
            solution,
            self.args.r,
            "Newton's method on the singular R did not converge",
        )
    }

    /// Newton's method on the true equation from the auxiliary problem's gain, if that gives
    /// an acceptable solution.
    fn newton_on_auxiliary_gain(&self) -> Option<Checked> {
        let exact = self.problem(self.args.r);
        auxiliary_gain(&self.a_hat, &self.b_hat)
            .and_then(|gain| exact.newton(gain))
            .and_then(|(y, steps)| {
                let closed_loop = exact.closed_loop(&y)?;
                let candidate = Candidate {
                    y,
                    closed_loop,
                    iterations: steps,
                };
                Some(self.checked(candidate, self.args.r))
            })
            .filter(acceptable)
    }
}

/// `X = E⁻ᵀ Y E⁻¹`: the generalized problem's solution from the standard one's.
fn unreduce(y: &Mat, e_inv: Option<&Mat>) -> Mat {
    match e_inv {
        Some(e_inv) => symmetrize(&(e_inv.transpose() * y * e_inv)),
        None => y.clone(),
    }
}

/// The standard-form DARE `ÂᵀYÂ − Y − (ÂᵀYB̂ + S)(B̂ᵀYB̂ + R)⁻¹(B̂ᵀYÂ + Sᵀ) + Q = 0`.
struct StandardDare<'a> {
    a: &'a Mat,
    b: &'a Mat,
    q: &'a Mat,
    r: &'a Mat,
    s: Option<&'a Mat>,
}

/// A solution `Y` of the standard-form DARE with its closed loop and the iterations spent.
struct Candidate {
    y: Mat,
    closed_loop: ClosedLoop,
    iterations: usize,
}

/// The gain `G = (B̂ᵀYB̂ + R)⁻¹(B̂ᵀYÂ + Sᵀ)` of a candidate `Y` and its closed loop.
struct ClosedLoop {
    gain: Mat,
    eigenvalues: Vec<Complex<f64>>,
    radius: f64,
}

impl StandardDare<'_> {
    /// `None` where `B̂ᵀYB̂ + R` is singular; it need not be definite (DAREX 1.2 and 1.4).
    fn gain(&self, y: &Mat) -> Option<Mat> {
        let btyb_r = symmetrize(&(self.b.transpose() * y * self.b + self.r));
        let mut rhs = self.b.transpose() * y * self.a;
        if let Some(s) = self.s {
            rhs += s.transpose();
        }
        let gain = btyb_r.lu().solve(&rhs)?;
        gain.iter().all(|v| v.is_finite()).then_some(gain)
    }

    fn closed_loop(&self, y: &Mat) -> Option<ClosedLoop> {
        let gain = self.gain(y)?;
        let eigenvalues = eigenvalues(&(self.a - self.b * &gain));
        let radius = eigenvalues.iter().map(|z| z.norm()).fold(0.0, f64::max);
        Some(ClosedLoop {
            gain,
            eigenvalues,
            radius,
        })
    }

    /// Newton's method for the DARE (Hewer 1971) from a stabilizing gain `G₀`: each step
    /// solves the Stein equation of the closed loop `A_G = Â − B̂G`,
    ///
    /// ```text
    /// Y = A_Gᵀ Y A_G + Q − S G − Gᵀ Sᵀ + Gᵀ R G,
    /// ```
    ///
    /// and takes the gain of that `Y`. The gains stay stabilizing and `Y` decreases
    /// monotonically to the stabilizing solution, quadratically once close. `R⁻¹` is never
    /// formed. Returns `Y` and the number of steps.
    fn newton(&self, mut gain: Mat) -> Option<(Mat, usize)> {
        let mut y_prev: Option<Mat> = None;
        for step in 1..=NEWTON_MAX_ITERATIONS {
            let closed = self.a - self.b * &gain;
            let mut weight = self.q + gain.transpose() * self.r * &gain;
            if let Some(s) = self.s {
                let sg = s * &gain;
                weight -= &sg + sg.transpose();
            }
            let y = stein(&closed, &symmetrize(&weight))?;
            gain = self.gain(&y)?;
            if let Some(prev) = &y_prev {
                if (&y - prev).norm() <= 1e-14 * y.norm().max(f64::MIN_POSITIVE) {
                    return Some((y, step));
                }
            }
            y_prev = Some(y);
        }
        y_prev.map(|y| (y, NEWTON_MAX_ITERATIONS))
    }
}

/// The gain of the auxiliary DARE with `Q = I`, `R = I`, `S = 0` on `(Â, B̂)`, by the
/// doubling: a stabilizing gain whenever `(Â, B̂)` is stabilizable, from which Newton's method
/// can start on any other weights.
fn auxiliary_gain(a: &Mat, b: &Mat) -> Option<Mat> {
    let n = a.nrows();
    let eye_n = Mat::identity(n, n);
    let eye_m = Mat::identity(b.ncols(), b.ncols());
    let (y, _) = sda_dispatch(a, &symmetrize(&(b * b.transpose())), &eye_n)?;
    let aux = StandardDare {
        a,
        b,
        q: &eye_n,
        r: &eye_m,
        s: None,
    };
    aux.closed_loop(&symmetrize(&y))
        .filter(|c| c.radius < 1.0)
        .map(|c| c.gain)
}

/// Largest state dimension for which [`stein`] falls back to the Kronecker form (an
/// `n² × n²` solve) when `Φ` is not Schur stable.
const STEIN_KRONECKER_MAX_STATES: usize = 24;

/// Solves the Stein equation `Y = Φᵀ Y Φ + M`. For a Schur-stable `Φ`, by Smith's doubling
/// (`stein_smith`); otherwise (an intermediate Newton step of an indefinite problem) by its
/// Kronecker form `(I − Φᵀ ⊗ Φᵀ) vec Y = vec M`, solvable unless two eigenvalues of `Φ` have
/// product one.
fn stein(phi: &Mat, m: &Mat) -> Option<Mat> {
    stein_smith(phi, m).or_else(|| {
        let n = phi.nrows();
        if n > STEIN_KRONECKER_MAX_STATES {
            return None;
        }
        let phi_t = phi.transpose();
        let system = Mat::identity(n * n, n * n) - phi_t.kronecker(&phi_t);
        let vec_y = system
            .lu()
            .solve(&nalgebra::DVector::from_column_slice(m.as_slice()))?;
        let y = Mat::from_column_slice(n, n, vec_y.as_slice());
        y.iter().all(|v| v.is_finite()).then(|| symmetrize(&y))
    })
}

/// Smith's doubling for the Stein equation with a Schur-stable `Φ`:
/// `Y₊ = Y + Φ_kᵀ Y Φ_k`, `Φ₊ = Φ_k²`, which sums `Σ (Φᵀ)ʲ M Φʲ` in `log₂` as many steps.
fn stein_smith(phi: &Mat, m: &Mat) -> Option<Mat> {
    let mut y = m.clone();
    let mut phi = phi.clone();
    for _ in 0..64 {
        let increment = phi.transpose() * &y * &phi;
        y += &increment;
        phi = &phi * &phi;
        let size = y.norm();
        if !size.is_finite() || !phi.norm().is_finite() {
            return None;
        }
        if increment.norm() <= 1e-17 * size || phi.norm() <= 1e-300 {
            return Some(symmetrize(&y));
        }
    }
    None
}

/// Relative residual of the generalized DARE at `x` (see [`DareSolution::relative_residual`]).
pub fn dare_relative_residual(
    a: &Mat,
    b: &Mat,
    q: &Mat,
    r: &Mat,
    s: Option<&Mat>,
    e: Option<&Mat>,
    x: &Mat,
) -> f64 {
    let mut cross = a.transpose() * x * b;
    if let Some(s) = s {
        cross += s;
    }
    let btxb_r = b.transpose() * x * b + r;
    let Some(weighted_cross) = btxb_r.lu().solve(&cross.transpose()) else {
        return f64::INFINITY;
    };
    let exe = match e {
        Some(e) => e.transpose() * x * e,
        None => x.clone(),
    };
    let residual = a.transpose() * x * a - exe - &cross * weighted_cross + q;
    let scale = q.norm() + x.norm() * (1.0 + a.norm_squared());
    residual.norm() / scale.max(f64::MIN_POSITIVE)
}

/// An eigenvalue of `E⁻¹A` with `|λ| ≥ 1` that fails the PBH rank test
/// `rank [A − λE, B] = n`, if there is one.
pub(crate) fn unreachable_unstable_mode(a: &Mat, b: &Mat, e: Option<&Mat>) -> Option<Complex<f64>> {
    let n = a.nrows();
    let e = e.cloned().unwrap_or_else(|| Mat::identity(n, n));
    let a_eff = e.clone().lu().solve(a)?;
    let scale = a.norm() + b.norm() + e.norm();
    for lambda in eigenvalues(&a_eff) {
        if lambda.norm() < 1.0 - UNIT_CIRCLE_MARGIN {
            continue;
        }
        let mut pencil = DMatrix::<Complex<f64>>::zeros(n, n + b.ncols());
        for i in 0..n {
            for j in 0..n {
                pencil[(i, j)] = Complex::new(a[(i, j)], 0.0) - lambda * e[(i, j)];
            }
            for j in 0..b.ncols() {
                pencil[(i, n + j)] = Complex::new(b[(i, j)], 0.0);
            }
        }
        // Bounded iteration; a failed SVD cannot prove the mode unreachable.
        let Some(svd) = pencil.try_svd(false, false, f64::EPSILON, 100 * (2 * n + 1)) else {
            continue;
        };
        let sigma_min = svd.singular_values.min();
        if sigma_min <= 1e-9 * scale {
            return Some(lambda);
        }
    }
    None
}

/// Runs the doubling iteration on stack matrices when the state dimension is small.
fn sda_dispatch(a0: &Mat, g0: &Mat, h0: &Mat) -> Option<(Mat, usize)> {
    macro_rules! on_stack {
        ($n:literal) => {{
            let fixed = |m: &Mat| m.fixed_view::<$n, $n>(0, 0).into_owned();
            let (x, iterations) = sda::<Const<$n>>(fixed(a0), fixed(g0), fixed(h0))?;
            Some((Mat::from_column_slice($n, $n, x.as_slice()), iterations))
        }};
    }
    match a0.nrows() {
        1 => on_stack!(1),
        2 => on_stack!(2),
        3 => on_stack!(3),
        4 => on_stack!(4),
        5 => on_stack!(5),
        6 => on_stack!(6),
        7 => on_stack!(7),
        8 => on_stack!(8),
        _ => sda::<Dyn>(a0.clone(), g0.clone(), h0.clone()),
    }
}

/// The structured doubling iteration; returns `H_∞ = X` and the number of steps.
fn sda<D: DimMin<D, Output = D>>(
    a0: OMatrix<f64, D, D>,
    g0: OMatrix<f64, D, D>,
    h0: OMatrix<f64, D, D>,
) -> Option<(OMatrix<f64, D, D>, usize)>
where
    DefaultAllocator: Allocator<D, D> + Allocator<D>,
{
    let (rows, cols) = a0.shape_generic();
    let eye = OMatrix::<f64, D, D>::identity_generic(rows, cols);
    let (mut a, mut g, mut h) = (a0, g0, h0);
    let a_scale = a.norm().max(1.0);
    for iteration in 1..=SDA_MAX_ITERATIONS {
        let lu = (&eye + &g * &h).lu();
        let w_inv_a = lu.solve(&a)?;
        let w_inv_g = lu.solve(&g)?;
        let h_next = &h + a.transpose() * &h * &w_inv_a;
        let g_next = &g + &a * &w_inv_g * a.transpose();
        a = &a * &w_inv_a;
        let change = (&h_next - &h).norm();
        let size = h_next.norm();
        if !size.is_finite() || !a.norm().is_finite() {
            return None;
        }
        h = (&h_next + h_next.transpose()) * 0.5;
        g = (&g_next + g_next.transpose()) * 0.5;
        // A_k → 0 at the same quadratic rate; either test alone can stall at round-off level.
        if change <= 1e-13 * size || a.norm() <= 1e-15 * a_scale {
            return Some((h, iteration));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mat(rows: usize, cols: usize, v: &[f64]) -> Mat {
        Mat::from_row_slice(rows, cols, v)
    }

    #[test]
    fn scalar_dare_matches_closed_form() {
        // x = a²x − a²x²b²/(b²x + r) + q has the positive root of b²x² + (r − a²r − qb²)x − qr = 0.
        let (a, b, q, r) = (1.2_f64, 0.5_f64, 2.0_f64, 0.3_f64);
        let (qa, qb, qc) = (b * b, r - a * a * r - q * b * b, -q * r);
        let expected = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
        let sol = dare(
            &mat(1, 1, &[a]),
            &mat(1, 1, &[b]),
            &mat(1, 1, &[q]),
            &mat(1, 1, &[r]),
            None,
            None,
        )
        .unwrap();
        assert!((sol.x[(0, 0)] - expected).abs() < 1e-12 * expected);
        assert!(sol.closed_loop_eigenvalues[0].norm() < 1.0);
    }

    #[test]
    fn singular_a_is_solved() {
        let a = mat(2, 2, &[0.0, 1.0, 0.0, 0.0]);
        let b = mat(2, 1, &[0.0, 1.0]);
        let sol = dare(&a, &b, &Mat::identity(2, 2), &mat(1, 1, &[1.0]), None, None).unwrap();
        assert!(sol.relative_residual < 1e-12);
    }

    #[test]
    fn darex_1_2_singular_r_with_cross_term_is_solved() {
        // Ionescu & Weiss 1992 (DAREX 1.2, SLICOT BB02AD): R singular, S ≠ 0; BᵀXB + R is
        // invertible but indefinite at the solution. Reference: Newton's method in 40-digit
        // arithmetic (mpmath), residual 6e-37; closed-loop spectral radius 0.68727.
        let a = mat(2, 2, &[0.0, 1.0, 0.0, -1.0]);
        let b = mat(2, 2, &[1.0, 0.0, 2.0, 1.0]);
        let q = mat(2, 2, &[-4.0, -4.0, -4.0, 7.0]) / 11.0;
        let r = mat(2, 2, &[9.0, 3.0, 3.0, 1.0]);
        let s = mat(2, 2, &[3.0, 1.0, -1.0, 7.0]);
        let want = mat(
            2,
            2,
            &[
                -1.402_134_124_423_919_6,
                13.056_866_399_158_116,
                13.056_866_399_158_116,
                -125.636_492_795_290_76,
            ],
        );
        let sol = dare(&a, &b, &q, &r, Some(&s), None).unwrap();
        assert!((&sol.x - &want).norm() < 1e-13 * want.norm(), "{}", sol.x);
        let radius = sol
            .closed_loop_eigenvalues
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max);
        assert!((radius - 0.687_271_691_663_810_5).abs() < 1e-12, "{radius}");
    }

    #[test]
    fn darex_1_4_indefinite_q_and_singular_r_is_solved() {
        // Sun 1998 (DAREX 1.4): Q = diag(1e5, 1e3, −10) indefinite, R = diag(0, 1). The exact
        // solution is X = diag(1e5, 1e3, −9.9) (the 3,3 equation reads 0.1 − x − 10 = 0;
        // SLICOT's BB02AD lists x₃₃ = 0, whose residual is 9.9); BᵀXB + R = diag(1e5, −8.9).
        let mut a = Mat::zeros(3, 3);
        a[(0, 1)] = 0.1;
        a[(1, 2)] = 0.01;
        let mut b = Mat::zeros(3, 2);
        b[(0, 0)] = 1.0;
        b[(2, 1)] = 1.0;
        let q = Mat::from_diagonal(&nalgebra::DVector::from_vec(vec![1e5, 1e3, -10.0]));
        let r = Mat::from_diagonal(&nalgebra::DVector::from_vec(vec![0.0, 1.0]));
        let sol = dare(&a, &b, &q, &r, None, None).unwrap();
        let want = Mat::from_diagonal(&nalgebra::DVector::from_vec(vec![1e5, 1e3, -9.9]));
        assert!((&sol.x - &want).amax() < 1e-10, "{}", sol.x);
        assert!(sol.closed_loop_eigenvalues.iter().all(|z| z.norm() < 1e-8));
    }

    #[test]
    fn uncontrollable_unstable_mode_is_reported() {
        let a = mat(2, 2, &[1.5, 0.0, 0.0, 0.5]);
        let b = mat(2, 1, &[0.0, 1.0]);
        let err = dare(&a, &b, &Mat::identity(2, 2), &mat(1, 1, &[1.0]), None, None).unwrap_err();
        assert!(matches!(err, RipError::NotStabilizable { .. }), "{err}");
    }
}

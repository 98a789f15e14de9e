//! A dual active-set solver for the condensed MPC QP, in the manner of DAQP (Arnström,
//! Bemporad and Axehill, "A dual active-set solver for embedded quadratic programming using
//! recursive LDLᵀ updates", IEEE TAC 67(8), 2022).
//!
//! ```text
//! minimise ½ zᵀ H z + fᵀ z   subject to   A z ≤ b          (H ≻ 0, n = dim z small)
//! ```
//!
//! With `H = RᵀR` (Cholesky, once per design), `v = R⁻ᵀ f`, `u = R z + v`, `M = A R⁻¹` (once)
//! and `d = b + M v` (per solve), the problem is the least-distance problem
//!
//! ```text
//! minimise ½‖u‖²   subject to   M u ≤ d,        z = R⁻¹ (u − v),
//! ```
//!
//! whose dual is `min ½ λᵀ M Mᵀ λ + dᵀ λ` over `λ ≥ 0`, with `u = −Mᵀ λ`. The method keeps a
//! working set `W` of linearly independent rows and a dual-feasible `λ_W ≥ 0`:
//!
//! 1. solve `(M_W M_Wᵀ) λ* = −d_W`;
//! 2. if `λ* ≥ 0`: take `λ = λ*`, `u = −M_Wᵀ λ`; if no row is violated by more than the
//!    tolerance, `u` is optimal; otherwise the most violated row `i` joins `W`. If `M_i`
//!    depends on `M_W` (`M_i = M_Wᵀ c`), `λ` moves along `(−c, 1)`, which keeps `u` and lowers
//!    the dual cost, until a `λ_j` with `c_j > 0` reaches zero and `j` leaves (none: the
//!    problem is infeasible);
//! 3. otherwise `λ` steps towards `λ*` until the first component reaches zero, and that row
//!    leaves `W`.
//!
//! `|W| ≤ n ≤` [`MAX_NZ`](crate::MAX_NZ), so each subproblem is a Cholesky factorisation of
//! at most a 5 × 5 matrix, refactored from scratch (cheaper than DAQP's recursive LDLᵀ update
//! at this size, and simpler). The working set of the last solve is the warm start of the
//! next, with `λ = 0` (always dual feasible). The iteration count is bounded by the design's
//! `max_iterations`; nothing is allocated.

use crate::design::{MAX_NCON, MAX_NZ};
use crate::real::Real;

/// Outcome of one solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpOutcome {
    /// Optimal to the tolerances.
    Solved,
    /// The iteration bound was reached.
    IterationLimit,
    /// The rows are inconsistent (cannot happen for the MPC's QP, whose slack relaxes every
    /// soft row and whose hard rows bound the moves only).
    Infeasible,
    /// A factorisation broke down or a number overflowed.
    NumericalTrouble,
}

/// The solver: the factors of one QP's `H` and `A`, and its warm start.
#[derive(Debug, Clone)]
pub struct DualActiveSet<R: Real> {
    n: usize,
    ncon: usize,
    /// `R⁻¹` (upper triangular, n × n, row-major).
    rinv: [R; MAX_NZ * MAX_NZ],
    /// `M = A R⁻¹` (ncon × n, row-major).
    m: [R; MAX_NCON * MAX_NZ],
    /// `‖M_i‖²`.
    norm2: [R; MAX_NCON],
    max_iter: u32,
    working: [usize; MAX_NZ],
    nw: usize,
    lambda: [R; MAX_NZ],
    lambda_star: [R; MAX_NZ],
    chol: [R; MAX_NZ * MAX_NZ],
    d: [R; MAX_NCON],
    u: [R; MAX_NZ],
    v: [R; MAX_NZ],
    z: [R; MAX_NZ],
    tmp: [R; MAX_NZ],
}

impl<R: Real> DualActiveSet<R> {
    /// Factors `H` (n × n, row-major, positive definite) and forms `M = A R⁻¹` for the
    /// `ncon × n` row-major `a`. `None` when `H` is not numerically positive definite.
    pub fn new(h: &[R], a: &[R], n: usize, ncon: usize, max_iter: u32) -> Option<Self> {
        let mut s = Self {
            n,
            ncon,
            rinv: [R::ZERO; MAX_NZ * MAX_NZ],
            m: [R::ZERO; MAX_NCON * MAX_NZ],
            norm2: [R::ZERO; MAX_NCON],
            max_iter,
            working: [0; MAX_NZ],
            nw: 0,
            lambda: [R::ZERO; MAX_NZ],
            lambda_star: [R::ZERO; MAX_NZ],
            chol: [R::ZERO; MAX_NZ * MAX_NZ],
            d: [R::ZERO; MAX_NCON],
            u: [R::ZERO; MAX_NZ],
            v: [R::ZERO; MAX_NZ],
            z: [R::ZERO; MAX_NZ],
            tmp: [R::ZERO; MAX_NZ],
        };
        // Lower Cholesky factor L of H (so R = Lᵀ), in `chol`.
        let l = &mut s.chol;
        l[..n * n].copy_from_slice(&h[..n * n]);
        if !cholesky(l, n, R::from_f64(1e-13)) {
            return None;
        }
        // R⁻¹ = (Lᵀ)⁻¹ = (L⁻¹)ᵀ: invert L column by column (forward substitution on eⱼ).
        for j in 0..n {
            let mut col = [R::ZERO; MAX_NZ];
            col[j] = R::ONE;
            for i in 0..n {
                let mut acc = col[i];
                for c in 0..i {
                    acc -= l[i * n + c] * col[c];
                }
                col[i] = acc / l[i * n + i];
            }
            // col = L⁻¹ eⱼ, i.e. column j of L⁻¹ = row j of R⁻¹.
            s.rinv[j * n..j * n + n].copy_from_slice(&col[..n]);
        }
        for i in 0..ncon {
            let mut nrm = R::ZERO;
            for j in 0..n {
                let mut acc = R::ZERO;
                for c in 0..n {
                    acc += a[i * n + c] * s.rinv[c * n + j];
                }
                s.m[i * n + j] = acc;
                nrm += acc * acc;
            }
            s.norm2[i] = nrm;
        }
        Some(s)
    }

    /// The last solution `z` (the unconstrained minimiser `−H⁻¹ f` after a failed solve).
    pub fn solution(&self) -> &[R] {
        &self.z[..self.n]
    }

    /// The unconstrained minimiser `−H⁻¹ f = −R⁻¹ R⁻ᵀ f` of the last solve.
    pub fn unconstrained(&self, out: &mut [R]) {
        self.r_inverse_times(&self.v, out, true);
    }

    /// Rows in the working set after the last solve.
    pub fn working_set(&self) -> &[usize] {
        &self.working[..self.nw]
    }

    /// Forgets the warm start.
    pub fn reset(&mut self) {
        self.nw = 0;
    }

    /// `out = ±R⁻¹ x`.
    fn r_inverse_times(&self, x: &[R], out: &mut [R], negate: bool) {
        let n = self.n;
        for i in 0..n {
            let mut acc = R::ZERO;
            for c in i..n {
                acc += self.rinv[i * n + c] * x[c];
            }
            out[i] = if negate { -acc } else { acc };
        }
    }

    /// Solves for `f` (n) and `b` (ncon); returns the outcome and the iterations used.
    pub fn solve(&mut self, f: &[R], b: &[R]) -> (QpOutcome, u32) {
        let (n, ncon) = (self.n, self.ncon);
        // v = R⁻ᵀ f: (R⁻¹)ᵀ is lower triangular.
        for i in 0..n {
            let mut acc = R::ZERO;
            for c in 0..=i {
                acc += self.rinv[c * n + i] * f[c];
            }
            self.v[i] = acc;
        }
        let mut dscale = R::ONE;
        for i in 0..ncon {
            let mut acc = b[i];
            for j in 0..n {
                acc += self.m[i * n + j] * self.v[j];
            }
            self.d[i] = acc;
            dscale = dscale.max(acc.abs());
        }
        let eps = R::EPSILON;
        let k = R::from_f64(1e3);
        let primal_tol = k * eps * dscale;
        let dual_tol = k * eps;
        let pivot_tol = k * eps;
        self.lambda[..self.nw].fill(R::ZERO);
        let mut iter = 0u32;
        let outcome = loop {
            iter += 1;
            if iter > self.max_iter {
                iter -= 1;
                break QpOutcome::IterationLimit;
            }
            if !self.solve_equality() {
                break QpOutcome::NumericalTrouble;
            }
            let nw = self.nw;
            let mut all_nonneg = true;
            for j in 0..nw {
                if self.lambda_star[j] < -dual_tol {
                    all_nonneg = false;
                }
            }
            if all_nonneg {
                self.lambda[..nw].copy_from_slice(&self.lambda_star[..nw]);
                self.primal_from_dual();
                // The most violated row outside W.
                let mut worst = None;
                let mut worst_val = primal_tol;
                for i in 0..ncon {
                    if self.working[..nw].contains(&i) {
                        continue;
                    }
                    let mut mu = -self.d[i];
                    for j in 0..n {
                        mu += self.m[i * n + j] * self.u[j];
                    }
                    if !mu.is_finite() {
                        return self.fail(QpOutcome::NumericalTrouble, iter);
                    }
                    if mu > worst_val {
                        worst_val = mu;
                        worst = Some(i);
                    }
                }
                match worst {
                    None => break QpOutcome::Solved,
                    Some(i) => {
                        if !self.add(i, pivot_tol) {
                            break QpOutcome::Infeasible;
                        }
                    }
                }
            } else {
                // Step from λ towards λ*: the first component to reach zero leaves W.
                let mut alpha = R::ONE;
                let mut leave = 0;
                for j in 0..nw {
                    let ls = self.lambda_star[j];
                    if ls < -dual_tol {
                        let t = self.lambda[j] / (self.lambda[j] - ls);
                        if t < alpha {
                            alpha = t;
                            leave = j;
                        }
                    }
                }
                for j in 0..nw {
                    let l = self.lambda[j];
                    self.lambda[j] = l + alpha * (self.lambda_star[j] - l);
                }
                self.remove(leave);
            }
        };
        if outcome != QpOutcome::Solved {
            return self.fail(outcome, iter);
        }
        // z = R⁻¹ (u − v).
        for j in 0..n {
            self.tmp[j] = self.u[j] - self.v[j];
        }
        let tmp = self.tmp;
        let mut z = [R::ZERO; MAX_NZ];
        self.r_inverse_times(&tmp, &mut z, false);
        self.z = z;
        if self.z[..n].iter().all(|x| x.is_finite()) {
            (QpOutcome::Solved, iter)
        } else {
            self.fail(QpOutcome::NumericalTrouble, iter)
        }
    }

    fn fail(&mut self, outcome: QpOutcome, iter: u32) -> (QpOutcome, u32) {
        let v = self.v;
        let mut z = [R::ZERO; MAX_NZ];
        self.r_inverse_times(&v, &mut z, true);
        self.z = z;
        self.nw = 0;
        (outcome, iter)
    }

    /// `u = −M_Wᵀ λ_W`.
    fn primal_from_dual(&mut self) {
        let n = self.n;
        self.u[..n].fill(R::ZERO);
        for (w, &row) in self.working[..self.nw].iter().enumerate() {
            let l = self.lambda[w];
            for j in 0..n {
                self.u[j] -= self.m[row * n + j] * l;
            }
        }
    }

    fn dot_rows(&self, r1: usize, r2: usize) -> R {
        let n = self.n;
        let mut acc = R::ZERO;
        for j in 0..n {
            acc += self.m[r1 * n + j] * self.m[r2 * n + j];
        }
        acc
    }

    /// Factors `M_W M_Wᵀ` into `chol` and solves `λ* = −(M_W M_Wᵀ)⁻¹ d_W`.
    fn solve_equality(&mut self) -> bool {
        let k = self.nw;
        for a in 0..k {
            for c in 0..=a {
                self.chol[a * k + c] = self.dot_rows(self.working[a], self.working[c]);
            }
        }
        if !cholesky(&mut self.chol, k, R::EPSILON) {
            return false;
        }
        for a in 0..k {
            self.lambda_star[a] = -self.d[self.working[a]];
        }
        let mut rhs = self.lambda_star;
        cholesky_solve(&self.chol, k, &mut rhs[..k]);
        self.lambda_star = rhs;
        self.lambda_star[..k].iter().all(|x| x.is_finite())
    }

    /// Adds row `i` to W, first exchanging it for a row it depends on (module docs, step 2);
    /// `false` when it depends on W with no exchange possible (infeasible).
    fn add(&mut self, i: usize, pivot_tol: R) -> bool {
        let k = self.nw;
        // c = (M_W M_Wᵀ)⁻¹ M_W M_iᵀ with the factor of the last `solve_equality`; the pivot
        // of the extended factor is ‖M_i‖² − (M_W M_iᵀ)ᵀ c.
        let mut c = [R::ZERO; MAX_NZ];
        for a in 0..k {
            c[a] = self.dot_rows(self.working[a], i);
        }
        let g = c;
        cholesky_solve(&self.chol, k, &mut c[..k]);
        let mut proj = R::ZERO;
        for a in 0..k {
            proj += g[a] * c[a];
        }
        let pivot = self.norm2[i] - proj;
        if k < self.n && pivot > pivot_tol * self.norm2[i] {
            self.working[k] = i;
            self.lambda[k] = R::ZERO;
            self.nw = k + 1;
            return true;
        }
        // Dependent: move λ along (−c, 1) until a λ_j with c_j > 0 reaches zero.
        let mut t = None::<R>;
        let mut leave = 0;
        for a in 0..k {
            if c[a] > R::ZERO {
                let ta = self.lambda[a] / c[a];
                if t.map_or(true, |t| ta < t) {
                    t = Some(ta);
                    leave = a;
                }
            }
        }
        let Some(t) = t else {
            return false;
        };
        for a in 0..k {
            self.lambda[a] -= t * c[a];
        }
        self.remove(leave);
        let k = self.nw;
        self.working[k] = i;
        self.lambda[k] = t;
        self.nw = k + 1;
        true
    }

    fn remove(&mut self, idx: usize) {
        let k = self.nw;
        for a in idx..k - 1 {
            self.working[a] = self.working[a + 1];
            self.lambda[a] = self.lambda[a + 1];
        }
        self.nw = k - 1;
    }
}

/// In-place lower Cholesky of the row-major `k × k` matrix (lower triangle read); `false`
/// unless every pivot exceeds `rel` times the largest diagonal entry (NaN fails).
fn cholesky<R: Real>(s: &mut [R], k: usize, rel: R) -> bool {
    let mut scale = R::ZERO;
    for i in 0..k {
        scale = scale.max(s[i * k + i].abs());
    }
    for j in 0..k {
        let mut d = s[j * k + j];
        for c in 0..j {
            d -= s[j * k + c] * s[j * k + c];
        }
        if d.partial_cmp(&(rel * scale)) != Some(core::cmp::Ordering::Greater) {
            return false;
        }
        let d = d.sqrt();
        s[j * k + j] = d;
        for i in j + 1..k {
            let mut v = s[i * k + j];
            for c in 0..j {
                v -= s[i * k + c] * s[j * k + c];
            }
            s[i * k + j] = v / d;
        }
    }
    true
}

/// Solves `L Lᵀ x = rhs` in place.
fn cholesky_solve<R: Real>(l: &[R], k: usize, rhs: &mut [R]) {
    for i in 0..k {
        let mut v = rhs[i];
        for c in 0..i {
            v -= l[i * k + c] * rhs[c];
        }
        rhs[i] = v / l[i * k + i];
    }
    for i in (0..k).rev() {
        let mut v = rhs[i];
        for r in i + 1..k {
            v -= l[r * k + i] * rhs[r];
        }
        rhs[i] = v / l[i * k + i];
    }
}

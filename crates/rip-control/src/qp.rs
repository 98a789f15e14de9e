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
//! `|W| ≤ n`, so each subproblem is a Cholesky factorisation of at most an `n × n` matrix
//! (5 × 5 on the device), refactored from scratch: cheaper than DAQP's recursive LDLᵀ update
//! at this size, and simpler. The working set of the last solve is the warm start of the
//! next, with `λ = 0` (always dual feasible). The iteration count is bounded by the design's
//! `max_iterations`; nothing is allocated.
//!
//! The solver works in caller-provided storage ([`DualActiveSet::new_in`], its length from
//! [`DualActiveSet::storage_len`]): fixed arrays on the device ([`FixedQp`]), vectors for the
//! host's larger problems.

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

/// Reals of storage the device's largest QP needs ([`DualActiveSet::storage_len`]).
pub const FIXED_STORAGE: usize = 2 * MAX_NZ * MAX_NZ + (MAX_NZ + 2) * MAX_NCON + 8 * MAX_NZ;

/// The device's solver: storage in fixed arrays sized for [`MAX_NZ`] and [`MAX_NCON`].
pub type FixedQp<R> = DualActiveSet<R, [R; FIXED_STORAGE], [usize; MAX_NZ]>;

/// The solver: the factors of one QP's `H` and `A` and its warm start, in storage `B` (reals)
/// and `W` (the working set).
#[derive(Debug, Clone)]
pub struct DualActiveSet<R: Real, B, W> {
    n: usize,
    ncon: usize,
    max_iter: u32,
    nw: usize,
    buf: B,
    working: W,
    _real: core::marker::PhantomData<R>,
}

/// The solver's storage split into its arrays.
struct Parts<'a, R> {
    /// `R⁻¹` (upper triangular, n × n, row-major).
    rinv: &'a mut [R],
    /// `M = A R⁻¹` (ncon × n, row-major).
    m: &'a mut [R],
    /// `‖M_i‖²`.
    norm2: &'a mut [R],
    d: &'a mut [R],
    chol: &'a mut [R],
    lambda: &'a mut [R],
    lambda_star: &'a mut [R],
    u: &'a mut [R],
    v: &'a mut [R],
    z: &'a mut [R],
    tmp: &'a mut [R],
    c: &'a mut [R],
    g: &'a mut [R],
}

fn split<R>(buf: &mut [R], n: usize, ncon: usize) -> Parts<'_, R> {
    let (rinv, rest) = buf.split_at_mut(n * n);
    let (m, rest) = rest.split_at_mut(ncon * n);
    let (norm2, rest) = rest.split_at_mut(ncon);
    let (d, rest) = rest.split_at_mut(ncon);
    let (chol, rest) = rest.split_at_mut(n * n);
    let (lambda, rest) = rest.split_at_mut(n);
    let (lambda_star, rest) = rest.split_at_mut(n);
    let (u, rest) = rest.split_at_mut(n);
    let (v, rest) = rest.split_at_mut(n);
    let (z, rest) = rest.split_at_mut(n);
    let (tmp, rest) = rest.split_at_mut(n);
    let (c, rest) = rest.split_at_mut(n);
    let (g, _) = rest.split_at_mut(n);
    Parts {
        rinv,
        m,
        norm2,
        d,
        chol,
        lambda,
        lambda_star,
        u,
        v,
        z,
        tmp,
        c,
        g,
    }
}

impl<R: Real> FixedQp<R> {
    /// [`new_in`](DualActiveSet::new_in) with the device's fixed storage; `None` also when
    /// the sizes exceed [`MAX_NZ`] or [`MAX_NCON`].
    pub fn new(h: &[R], a: &[R], n: usize, ncon: usize, max_iter: u32) -> Option<Self> {
        if n > MAX_NZ || ncon > MAX_NCON {
            return None;
        }
        let mut qp = Self::empty();
        qp.refactor(h, a, n, ncon, max_iter).then_some(qp)
    }

    /// A solver of no QP (`n = 0`: empty solutions), `const` for a firmware's static, to be
    /// [`refactor`](DualActiveSet::refactor)ed in place.
    pub const fn empty() -> Self {
        Self {
            n: 0,
            ncon: 0,
            max_iter: 0,
            nw: 0,
            buf: [R::ZERO; FIXED_STORAGE],
            working: [0; MAX_NZ],
            _real: core::marker::PhantomData,
        }
    }
}

impl<R: Real, B: AsRef<[R]> + AsMut<[R]>, W: AsRef<[usize]> + AsMut<[usize]>>
    DualActiveSet<R, B, W>
{
    /// Reals of storage a QP with `n` variables and `ncon` rows needs.
    pub const fn storage_len(n: usize, ncon: usize) -> usize {
        2 * n * n + (n + 2) * ncon + 8 * n
    }

    /// Factors `H` (n × n, row-major, positive definite) and forms `M = A R⁻¹` for the
    /// `ncon × n` row-major `a`, in `buf` (at least [`storage_len`](Self::storage_len) reals)
    /// and `working` (at least `n`). `None` when `H` is not numerically positive definite or
    /// the storage is short.
    pub fn new_in(
        h: &[R],
        a: &[R],
        n: usize,
        ncon: usize,
        max_iter: u32,
        buf: B,
        working: W,
    ) -> Option<Self> {
        let mut qp = Self {
            n: 0,
            ncon: 0,
            max_iter,
            nw: 0,
            buf,
            working,
            _real: core::marker::PhantomData,
        };
        qp.refactor(h, a, n, ncon, max_iter).then_some(qp)
    }

    /// [`new_in`](Self::new_in) in the solver's own storage, for a device that keeps its one
    /// solver in a static: the factors of a QP of `n` variables and `ncon` rows replace the
    /// previous QP's, and the warm start is forgotten. `false` (the solver then holds no QP,
    /// `n = 0`) when `H` is not numerically positive definite or the storage is short.
    pub fn refactor(&mut self, h: &[R], a: &[R], n: usize, ncon: usize, max_iter: u32) -> bool {
        self.n = 0;
        self.ncon = 0;
        self.nw = 0;
        self.max_iter = max_iter;
        if self.buf.as_ref().len() < Self::storage_len(n, ncon)
            || self.working.as_ref().len() < n
            || h.len() < n * n
            || a.len() < ncon * n
        {
            return false;
        }
        let p = split(self.buf.as_mut(), n, ncon);
        // Lower Cholesky factor L of H (so R = Lᵀ), in `chol`.
        let l = p.chol;
        l.copy_from_slice(&h[..n * n]);
        if !cholesky(l, n, R::from_f64(1e-13)) {
            return false;
        }
        // R⁻¹ = (Lᵀ)⁻¹ = (L⁻¹)ᵀ: row j of R⁻¹ is column j of L⁻¹ (forward substitution on eⱼ).
        for j in 0..n {
            let col = &mut p.rinv[j * n..j * n + n];
            col.fill(R::ZERO);
            col[j] = R::ONE;
            for i in 0..n {
                let mut acc = col[i];
                for c in 0..i {
                    acc -= l[i * n + c] * col[c];
                }
                col[i] = acc / l[i * n + i];
            }
        }
        for i in 0..ncon {
            let mut nrm = R::ZERO;
            for j in 0..n {
                let mut acc = R::ZERO;
                for c in 0..n {
                    acc += a[i * n + c] * p.rinv[c * n + j];
                }
                p.m[i * n + j] = acc;
                nrm += acc * acc;
            }
            p.norm2[i] = nrm;
        }
        p.z.fill(R::ZERO);
        self.n = n;
        self.ncon = ncon;
        true
    }

    fn z_offset(&self) -> usize {
        let (n, ncon) = (self.n, self.ncon);
        2 * n * n + (n + 2) * ncon + 4 * n
    }

    /// The last solution `z` (the unconstrained minimiser `−H⁻¹ f` after a failed solve).
    pub fn solution(&self) -> &[R] {
        let o = self.z_offset();
        &self.buf.as_ref()[o..o + self.n]
    }

    /// The unconstrained minimiser `−H⁻¹ f = −R⁻¹ R⁻ᵀ f` of the last solve, into `out`.
    pub fn unconstrained(&self, out: &mut [R]) {
        let (n, ncon) = (self.n, self.ncon);
        let buf = self.buf.as_ref();
        let rinv = &buf[..n * n];
        let vo = 2 * n * n + (n + 2) * ncon + 3 * n;
        r_inverse_times(rinv, &buf[vo..vo + n], out, n, true);
    }

    /// Rows in the working set after the last solve.
    pub fn working_set(&self) -> &[usize] {
        &self.working.as_ref()[..self.nw]
    }

    /// Forgets the warm start.
    pub fn reset(&mut self) {
        self.nw = 0;
    }

    /// Solves for `f` (n) and `b` (ncon); returns the outcome and the iterations used.
    pub fn solve(&mut self, f: &[R], b: &[R]) -> (QpOutcome, u32) {
        let (n, ncon, max_iter) = (self.n, self.ncon, self.max_iter);
        let mut nw = self.nw;
        let working = &mut self.working.as_mut()[..n];
        let p = split(self.buf.as_mut(), n, ncon);
        let (outcome, iter) = solve_in(p, working, &mut nw, n, ncon, max_iter, f, b);
        self.nw = nw;
        (outcome, iter)
    }
}

/// `out = ±R⁻¹ x` for the upper-triangular row-major `rinv`.
fn r_inverse_times<R: Real>(rinv: &[R], x: &[R], out: &mut [R], n: usize, negate: bool) {
    for i in 0..n {
        let mut acc = R::ZERO;
        for c in i..n {
            acc += rinv[i * n + c] * x[c];
        }
        out[i] = if negate { -acc } else { acc };
    }
}

#[allow(clippy::too_many_arguments)]
fn solve_in<R: Real>(
    mut p: Parts<'_, R>,
    working: &mut [usize],
    nw: &mut usize,
    n: usize,
    ncon: usize,
    max_iter: u32,
    f: &[R],
    b: &[R],
) -> (QpOutcome, u32) {
    // v = R⁻ᵀ f: (R⁻¹)ᵀ is lower triangular.
    for i in 0..n {
        let mut acc = R::ZERO;
        for c in 0..=i {
            acc += p.rinv[c * n + i] * f[c];
        }
        p.v[i] = acc;
    }
    let mut dscale = R::ONE;
    let v = &p.v[..n];
    for ((d, &bi), row) in p.d[..ncon]
        .iter_mut()
        .zip(&b[..ncon])
        .zip(p.m.chunks_exact(n))
    {
        let acc = dot_from(bi, row, v);
        *d = acc;
        dscale = dscale.max(acc.abs());
    }
    let eps = R::EPSILON;
    let k = R::from_f64(1e3);
    let primal_tol = k * eps * dscale;
    let dual_tol = k * eps;
    let pivot_tol = k * eps;
    p.lambda[..*nw].fill(R::ZERO);
    let mut iter = 0u32;
    let outcome = loop {
        iter += 1;
        if iter > max_iter {
            iter -= 1;
            break QpOutcome::IterationLimit;
        }
        let k = *nw;
        if !solve_equality(&mut p, working, k, n) {
            break QpOutcome::NumericalTrouble;
        }
        if p.lambda_star[..k].iter().all(|&l| l >= -dual_tol) {
            p.lambda[..k].copy_from_slice(&p.lambda_star[..k]);
            // u = −M_Wᵀ λ_W.
            p.u.fill(R::ZERO);
            for (&row, &l) in working[..k].iter().zip(&p.lambda[..k]) {
                for (uj, &mj) in p.u.iter_mut().zip(&p.m[row * n..row * n + n]) {
                    *uj -= mj * l;
                }
            }
            // The most violated row outside W. The rows of W are skipped only where they
            // would matter (a candidate, a non-finite value): rare, and the outcome is the
            // same as skipping them first.
            let mut worst = None;
            let mut worst_val = primal_tol;
            let mut finite = true;
            let u = &p.u[..n];
            let in_w = |i: usize| working[..k].contains(&i);
            for (i, (&di, row)) in p.d[..ncon].iter().zip(p.m.chunks_exact(n)).enumerate() {
                let mu = dot_from(-di, row, u);
                if !mu.is_finite() {
                    finite &= in_w(i);
                } else if mu > worst_val && !in_w(i) {
                    worst_val = mu;
                    worst = Some(i);
                }
            }
            if !finite {
                break QpOutcome::NumericalTrouble;
            }
            match worst {
                None => break QpOutcome::Solved,
                Some(i) => {
                    if !add(&mut p, working, nw, n, i, pivot_tol) {
                        break QpOutcome::Infeasible;
                    }
                }
            }
        } else {
            // Step from λ towards λ*: the first component to reach zero leaves W.
            let mut alpha = R::ONE;
            let mut leave = 0;
            for j in 0..k {
                let ls = p.lambda_star[j];
                if ls < -dual_tol {
                    let t = p.lambda[j] / (p.lambda[j] - ls);
                    if t < alpha {
                        alpha = t;
                        leave = j;
                    }
                }
            }
            for j in 0..k {
                let l = p.lambda[j];
                p.lambda[j] = l + alpha * (p.lambda_star[j] - l);
            }
            remove(p.lambda, working, nw, leave);
        }
    };
    if outcome == QpOutcome::Solved {
        // z = R⁻¹ (u − v).
        for j in 0..n {
            p.tmp[j] = p.u[j] - p.v[j];
        }
        r_inverse_times(p.rinv, p.tmp, p.z, n, false);
        if p.z.iter().all(|x| x.is_finite()) {
            return (QpOutcome::Solved, iter);
        }
    }
    r_inverse_times(p.rinv, p.v, p.z, n, true);
    *nw = 0;
    let outcome = if outcome == QpOutcome::Solved {
        QpOutcome::NumericalTrouble
    } else {
        outcome
    };
    (outcome, iter)
}

fn dot_rows<R: Real>(m: &[R], n: usize, r1: usize, r2: usize) -> R {
    dot_from(R::ZERO, &m[r1 * n..r1 * n + n], &m[r2 * n..r2 * n + n])
}

/// `init + Σ a_j x_j`, accumulated left to right: the solver's inner loop, over slices so
/// that no index is checked inside it.
#[inline(always)]
fn dot_from<R: Real>(init: R, a: &[R], x: &[R]) -> R {
    let mut acc = init;
    for (&aj, &xj) in a.iter().zip(x) {
        acc += aj * xj;
    }
    acc
}

/// Factors `M_W M_Wᵀ` into `chol` and solves `λ* = −(M_W M_Wᵀ)⁻¹ d_W`.
fn solve_equality<R: Real>(p: &mut Parts<'_, R>, working: &[usize], k: usize, n: usize) -> bool {
    for a in 0..k {
        for c in 0..=a {
            p.chol[a * k + c] = dot_rows(p.m, n, working[a], working[c]);
        }
    }
    if !cholesky(p.chol, k, R::EPSILON) {
        return false;
    }
    for a in 0..k {
        p.lambda_star[a] = -p.d[working[a]];
    }
    cholesky_solve(p.chol, k, &mut p.lambda_star[..k]);
    p.lambda_star[..k].iter().all(|x| x.is_finite())
}

/// Adds row `i` to W, first exchanging it for a row it depends on (module docs, step 2);
/// `false` when it depends on W with no exchange possible (infeasible).
fn add<R: Real>(
    p: &mut Parts<'_, R>,
    working: &mut [usize],
    nw: &mut usize,
    n: usize,
    i: usize,
    pivot_tol: R,
) -> bool {
    let k = *nw;
    // c = (M_W M_Wᵀ)⁻¹ M_W M_iᵀ with the factor of the last `solve_equality`; the pivot of
    // the extended factor is ‖M_i‖² − (M_W M_iᵀ)ᵀ c.
    for a in 0..k {
        p.g[a] = dot_rows(p.m, n, working[a], i);
    }
    p.c[..k].copy_from_slice(&p.g[..k]);
    cholesky_solve(p.chol, k, &mut p.c[..k]);
    let mut proj = R::ZERO;
    for a in 0..k {
        proj += p.g[a] * p.c[a];
    }
    let pivot = p.norm2[i] - proj;
    if k < n && pivot > pivot_tol * p.norm2[i] {
        working[k] = i;
        p.lambda[k] = R::ZERO;
        *nw = k + 1;
        return true;
    }
    // Dependent: move λ along (−c, 1) until a λ_j with c_j > 0 reaches zero.
    let mut t = None::<R>;
    let mut leave = 0;
    for a in 0..k {
        if p.c[a] > R::ZERO {
            let ta = p.lambda[a] / p.c[a];
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
        p.lambda[a] -= t * p.c[a];
    }
    remove(p.lambda, working, nw, leave);
    let k = *nw;
    working[k] = i;
    p.lambda[k] = t;
    *nw = k + 1;
    true
}

fn remove<R: Real>(lambda: &mut [R], working: &mut [usize], nw: &mut usize, idx: usize) {
    let k = *nw;
    for a in idx..k - 1 {
        working[a] = working[a + 1];
        lambda[a] = lambda[a + 1];
    }
    *nw = k - 1;
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

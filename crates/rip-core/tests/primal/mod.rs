#![allow(dead_code)]
//! The dense primal active-set QP solver rip-core used before rip-control's dual method (kept
//! here as an independent reference for the tests).
//!
//! Solves
//!
//! ```text
//! minimise ½ zᵀ H z + fᵀ z   subject to   A z ≤ b
//! ```
//!
//! with `H` symmetric positive definite and `A` fixed at construction (only `f` and `b` change
//! between solves), by the primal active-set method (Nocedal & Wright, *Numerical
//! Optimization*, 2nd ed., Algorithm 16.3).
//!
//! # Equality-constrained subproblems (range-space form)
//!
//! For a working set `W` the subproblem `min ½zᵀHz + fᵀz s.t. A_W z = b_W` has the solution
//!
//! ```text
//! z_unc = −H⁻¹ f,   (A_W H⁻¹ A_Wᵀ) λ = A_W z_unc − b_W,   z_W = z_unc − H⁻¹ A_Wᵀ λ,
//! ```
//!
//! with multipliers `λ` (optimal for the inequality problem when `z_W` is feasible and
//! `λ ≥ 0`). `H⁻¹` and `V = H⁻¹ Aᵀ` are computed once, so each subproblem costs one Cholesky
//! factorisation of a `|W| × |W|` matrix with `|W| ≤ dim z`.
//!
//! # Warm start
//!
//! Each solve first tries the working set that was optimal last time: if its subproblem
//! solution is feasible, iteration starts there (in steady state it is already optimal and the
//! solve takes one subproblem). Otherwise it starts from the unconstrained minimiser moved into
//! the feasible set by the caller's projection and the elastic variable (the MPC slack `ε`),
//! with an empty working set.
//!
//! Nothing is allocated in [`ActiveSetSolver::solve`].

use nalgebra::DVector;

use rip_core::linalg::Mat;
use rip_core::mpc::QpStatus;

/// Outcome of one [`ActiveSetSolver::solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActiveSetOutcome {
    pub status: QpStatus,
    /// Subproblems solved (working-set changes plus one).
    pub iterations: usize,
}

/// Dense primal active-set solver with warm start (module docs).
#[derive(Debug, Clone)]
pub struct ActiveSetSolver {
    n: usize,
    ncon: usize,
    a: Mat,
    h_inv: Mat,
    /// `V = H⁻¹ Aᵀ` (n × ncon).
    v: Mat,
    /// Index of a variable that relaxes every row with a negative coefficient in it (the slack).
    elastic: Option<usize>,
    max_iter: usize,
    // Workspace.
    z: DVector<f64>,
    z_unc: DVector<f64>,
    z_w: DVector<f64>,
    step: DVector<f64>,
    az: DVector<f64>,
    ap: DVector<f64>,
    working: Vec<usize>,
    in_working: Vec<bool>,
    lambda: Vec<f64>,
    gram: Vec<f64>,
    rhs: Vec<f64>,
}

impl ActiveSetSolver {
    /// Prepares the solver for `H` (n × n, positive definite) and `A` (ncon × n). Returns
    /// `None` when `H` is not positive definite.
    pub fn new(h: &Mat, a: &Mat, elastic: Option<usize>, max_iter: usize) -> Option<Self> {
        let n = h.nrows();
        let ncon = a.nrows();
        let chol = h.clone().cholesky()?;
        let h_inv = chol.inverse();
        let v = chol.solve(&a.transpose());
        Some(Self {
            n,
            ncon,
            a: a.clone(),
            h_inv,
            v,
            elastic,
            max_iter,
            z: DVector::zeros(n),
            z_unc: DVector::zeros(n),
            z_w: DVector::zeros(n),
            step: DVector::zeros(n),
            az: DVector::zeros(ncon),
            ap: DVector::zeros(ncon),
            working: Vec::with_capacity(n),
            in_working: vec![false; ncon],
            lambda: vec![0.0; n],
            gram: vec![0.0; n * n],
            rhs: vec![0.0; n],
        })
    }

    /// The last solution.
    pub fn solution(&self) -> &DVector<f64> {
        &self.z
    }

    /// Forgets the warm start.
    pub fn reset(&mut self) {
        for &i in &self.working {
            self.in_working[i] = false;
        }
        self.working.clear();
    }

    /// Solves the QP for new `f` and `b`. `project` maps a point onto the rows that the
    /// elastic variable cannot relax (for the MPC: the input bounds); afterwards the elastic
    /// variable is raised until every row holds.
    pub fn solve(
        &mut self,
        f: &DVector<f64>,
        b: &DVector<f64>,
        project: impl Fn(&mut [f64]),
    ) -> ActiveSetOutcome {
        let scale_b = 1.0 + b.amax();
        let feas_tol = 1e-9 * scale_b;
        self.z_unc.gemv(-1.0, &self.h_inv, f, 0.0);
        let mut iterations = 1;

        // Warm start from the previous working set if its subproblem solution is feasible.
        let warm = !self.working.is_empty()
            && self.solve_subproblem(b)
            && self.max_violation_of_subproblem(b) <= feas_tol;
        if warm {
            self.z.copy_from(&self.z_w);
        } else {
            self.reset();
            self.z.copy_from(&self.z_unc);
            project(self.z.as_mut_slice());
            if let Some(e) = self.elastic {
                self.raise_elastic(e, b);
            }
            if self.max_violation_of_z(b) > feas_tol {
                return ActiveSetOutcome {
                    status: QpStatus::Infeasible,
                    iterations,
                };
            }
        }

        loop {
            if (iterations > 1 || !warm) && !self.solve_subproblem(b) {
                return ActiveSetOutcome {
                    status: QpStatus::NumericalTrouble,
                    iterations,
                };
            }
            self.step.copy_from(&self.z_w);
            self.step -= &self.z;
            let z_scale = 1.0 + self.z.amax().max(self.z_w.amax());
            // With n rows in W, z_W is a vertex and z is on it up to round-off: a step would
            // only find another row through the same (degenerate) vertex, so z_W is taken as
            // reached and the multipliers decide.
            if self.step.amax() <= 1e-12 * z_scale || self.working.len() == self.n {
                self.z.copy_from(&self.z_w);
                // Most negative multiplier decides which constraint to release.
                let k = self.working.len();
                let lambda_tol = 1e-10 * (1.0 + f.amax());
                let mut worst = None;
                let mut worst_val = -lambda_tol;
                for (idx, &l) in self.lambda[..k].iter().enumerate() {
                    if l < worst_val {
                        worst_val = l;
                        worst = Some(idx);
                    }
                }
                match worst {
                    None => {
                        return ActiveSetOutcome {
                            status: QpStatus::Solved,
                            iterations,
                        }
                    }
                    Some(idx) => {
                        let row = self.working.swap_remove(idx);
                        self.in_working[row] = false;
                    }
                }
            } else {
                // Longest feasible step along z_W − z; the first row hit joins W.
                self.az.gemv(1.0, &self.a, &self.z, 0.0);
                self.ap.gemv(1.0, &self.a, &self.step, 0.0);
                let mut alpha = 1.0;
                let mut blocking = None;
                for i in 0..self.ncon {
                    if self.in_working[i] {
                        continue;
                    }
                    let ap = self.ap[i];
                    if ap > 1e-14 * z_scale {
                        let t = ((b[i] - self.az[i]) / ap).max(0.0);
                        if t < alpha {
                            alpha = t;
                            blocking = Some(i);
                        }
                    }
                }
                self.z.axpy(alpha, &self.step, 1.0);
                if let Some(i) = blocking {
                    if self.working.len() == self.n {
                        return ActiveSetOutcome {
                            status: QpStatus::NumericalTrouble,
                            iterations,
                        };
                    }
                    self.working.push(i);
                    self.in_working[i] = true;
                }
            }
            iterations += 1;
            if iterations > self.max_iter {
                return ActiveSetOutcome {
                    status: QpStatus::MaxIterations,
                    iterations: iterations - 1,
                };
            }
        }
    }

    /// Solves the equality subproblem for the current working set into `z_w` and `lambda`.
    /// Returns `false` if `A_W H⁻¹ A_Wᵀ` is numerically singular.
    fn solve_subproblem(&mut self, b: &DVector<f64>) -> bool {
        let k = self.working.len();
        self.z_w.copy_from(&self.z_unc);
        if k == 0 {
            return true;
        }
        for (r, &i) in self.working.iter().enumerate() {
            let ai = self.a.row(i);
            let mut az = 0.0;
            for col in 0..self.n {
                az += ai[col] * self.z_unc[col];
            }
            self.rhs[r] = az - b[i];
            for (c, &j) in self.working.iter().enumerate().take(r + 1) {
                let vj = self.v.column(j);
                let mut s = 0.0;
                for col in 0..self.n {
                    s += ai[col] * vj[col];
                }
                self.gram[r * k + c] = s;
            }
        }
        if !cholesky_in_place(&mut self.gram[..k * k], k) {
            return false;
        }
        cholesky_solve(&self.gram[..k * k], k, &mut self.rhs[..k]);
        for (r, &i) in self.working.iter().enumerate() {
            let l = self.rhs[r];
            self.lambda[r] = l;
            self.z_w.axpy(-l, &self.v.column(i), 1.0);
        }
        true
    }

    fn max_violation_of_z(&mut self, b: &DVector<f64>) -> f64 {
        self.az.gemv(1.0, &self.a, &self.z, 0.0);
        self.az
            .iter()
            .zip(b.iter())
            .fold(f64::NEG_INFINITY, |acc, (&az, &bi)| acc.max(az - bi))
    }

    fn max_violation_of_subproblem(&mut self, b: &DVector<f64>) -> f64 {
        self.az.gemv(1.0, &self.a, &self.z_w, 0.0);
        self.az
            .iter()
            .zip(b.iter())
            .fold(f64::NEG_INFINITY, |acc, (&az, &bi)| acc.max(az - bi))
    }

    /// Raises `z[e]` just enough that every row with a negative coefficient on it holds.
    fn raise_elastic(&mut self, e: usize, b: &DVector<f64>) {
        self.az.gemv(1.0, &self.a, &self.z, 0.0);
        let mut needed = f64::NEG_INFINITY;
        for i in 0..self.ncon {
            let coef = self.a[(i, e)];
            if coef < 0.0 {
                // a·z + coef·(z_e' − z_e) ≤ b  ⇔  z_e' ≥ z_e + (a·z − b)/(−coef)
                needed = needed.max(self.z[e] + (self.az[i] - b[i]) / -coef);
            }
        }
        if needed > self.z[e] {
            self.z[e] = needed;
        }
    }
}

/// In-place Cholesky `S = L Lᵀ` of the row-major `k × k` matrix whose lower triangle is filled;
/// `L` overwrites that triangle. Returns `false` unless `S` is numerically positive definite.
fn cholesky_in_place(s: &mut [f64], k: usize) -> bool {
    let scale = (0..k).map(|i| s[i * k + i].abs()).fold(0.0, f64::max);
    for j in 0..k {
        let mut d = s[j * k + j];
        for c in 0..j {
            d -= s[j * k + c] * s[j * k + c];
        }
        // Also rejects NaN.
        if d.partial_cmp(&(1e-13 * scale)) != Some(std::cmp::Ordering::Greater) {
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

/// Solves `L Lᵀ x = rhs` in place with the factor from [`cholesky_in_place`].
fn cholesky_solve(l: &[f64], k: usize, rhs: &mut [f64]) {
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
/// Moves `Δ` so that every blocked input `u(k+j) = u⁻ + Σ_{l≤j} Δu(k+l)` lies in its bounds:
/// the running sums are clamped and the moves recomputed from them.
pub fn project_inputs(z: &mut [f64], u_prev: &[f64], lo: &[f64], hi: &[f64], m: usize) {
    let nu = u_prev.len();
    for c in 0..nu {
        let mut target = u_prev[c];
        let mut prev = u_prev[c];
        for j in 0..m {
            target += z[j * nu + c];
            let v = target.max(lo[c]).min(hi[c]);
            z[j * nu + c] = v - prev;
            prev = v;
        }
    }
}

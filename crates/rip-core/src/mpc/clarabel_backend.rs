//! The condensed QP solved by the Clarabel interior-point solver.
//!
//! Clarabel's standard form is `min ½ dᵀ P d + qᵀ d  s.t.  A d + s = b, s ∈ K`, with `K` the
//! nonnegative orthant. The condensed QP `min ½ zᵀ H z + fᵀ z  s.t.  A_c z ≤ b` is handed to it
//! shifted to its unconstrained minimiser `z₀ = −H⁻¹ f`: with `z = z₀ + d`,
//!
//! ```text
//! ½ zᵀ H z + fᵀ z = ½ dᵀ H d − ½ fᵀ H⁻¹ f,      A_c d ≤ b − A_c z₀,
//! ```
//!
//! so `P = H` (upper triangle), `q = 0` and only `b` changes between solves. The shift is for
//! accuracy: the unshifted objective carries the large state-dependent constant `−½ fᵀ H⁻¹ f`
//! (often `−10⁴`), against which Clarabel's relative duality-gap test stops with errors of
//! `~10⁻⁴` in the moves; the shifted objective is the constraints' own cost, near zero, so the
//! default tolerances give, in the same 13–14 iterations per solve of the paper's problem,
//! first moves usually within `10⁻⁶` of the exact solution (`3.4·10⁻⁷` at worst on the random
//! instances of the tests, `1.8·10⁻⁷` along a closed loop of the paper's problem). The
//! tolerances bound the cost, not the moves: over 1800 random QPs a first move was `7.7·10⁻⁶`
//! off and, at a degenerate vertex, a later planned move `2.5·10⁻⁴` off, the cost within
//! `6·10⁻⁹` (docs/design.md). The solver, its factorisation pattern and equilibration are set
//! up once (presolve and zero dropping are off so that data updates are allowed).
//!
//! # Allocation
//!
//! Nothing in this module allocates per solve, but Clarabel's own `solve` does (one heap
//! allocation per call with Clarabel 0.11): an [`Mpc`](super::Mpc) on this backend is
//! therefore not allocation-free in [`step`](crate::Controller::step). The allocation-free
//! guarantee of the real-time loop holds for the active-set backend and the regulators; choose
//! [`QpSolver::ActiveSet`](super::QpSolver::ActiveSet) where every allocation counts.

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT,
    SolverStatus,
};
use nalgebra::DVector;

use super::QpStatus;
use crate::error::{Result, RipError};
use crate::linalg::Mat;

/// Clarabel on the condensed QP, with its data kept to rebuild the solver on `clone`.
pub(crate) struct ClarabelBackend {
    solver: DefaultSolver<f64>,
    p: CscMatrix<f64>,
    a: CscMatrix<f64>,
    ncon: usize,
    /// `−H⁻¹`, mapping `f` to the unconstrained minimiser `z₀`.
    neg_h_inv: Mat,
    /// `A_c`, dense, to shift the bounds by `A_c z₀`.
    a_dense: Mat,
    z0: DVector<f64>,
    settings: DefaultSettings<f64>,
    // Clarabel's update functions take `&Vec`; reused every solve.
    b_buf: Vec<f64>,
}

impl std::fmt::Debug for ClarabelBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClarabelBackend")
            .field("n", &self.p.n)
            .field("ncon", &self.ncon)
            .field("max_iter", &self.settings.max_iter)
            .finish()
    }
}

impl Clone for ClarabelBackend {
    fn clone(&self) -> Self {
        // Setup succeeded once with exactly these data and settings, so it succeeds again.
        Self::build(
            &self.p,
            &self.a,
            self.neg_h_inv.clone(),
            self.a_dense.clone(),
            self.settings.clone(),
        )
        .expect("rebuilding a Clarabel solver from data it accepted before")
    }
}

impl ClarabelBackend {
    /// Sets up Clarabel for `H` (n × n) and `A_c` (ncon × n).
    pub fn new(h: &Mat, a: &Mat, max_iter: usize) -> Result<Self> {
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .input_sparse_dropzeros(false)
            .max_iter(u32::try_from(max_iter).unwrap_or(u32::MAX))
            // Refinement of the KKT solves roughly doubles the solve time on these small
            // problems; without it the backends still agree to 1e-7 V on the paper's loop.
            .iterative_refinement_enable(false)
            .build()
            .map_err(|e| RipError::invalid("max_iterations", e.to_string()))?;
        let neg_h_inv = -h
            .clone()
            .cholesky()
            .ok_or_else(|| RipError::NotPositiveDefinite {
                name: "QP Hessian".into(),
            })?
            .inverse();
        Self::build(
            &dense_to_csc(h, true),
            &dense_to_csc(a, false),
            neg_h_inv,
            a.clone(),
            settings,
        )
    }

    fn build(
        p: &CscMatrix<f64>,
        a: &CscMatrix<f64>,
        neg_h_inv: Mat,
        a_dense: Mat,
        settings: DefaultSettings<f64>,
    ) -> Result<Self> {
        let n = p.n;
        let ncon = a.m;
        let q = vec![0.0; n];
        let b = vec![0.0; ncon];
        let cones = [NonnegativeConeT(ncon)];
        let solver = DefaultSolver::new(p, &q, a, &b, &cones, settings.clone())
            .map_err(|e| RipError::invalid("solver", format!("Clarabel setup failed: {e}")))?;
        Ok(Self {
            solver,
            p: p.clone(),
            a: a.clone(),
            ncon,
            z0: DVector::zeros(p.n),
            neg_h_inv,
            a_dense,
            settings,
            b_buf: b,
        })
    }

    /// Solves for new `f` and `b`, writing the primal solution into `z`. Returns the status
    /// and the interior-point iteration count. Allocates inside Clarabel (module docs).
    pub fn solve(
        &mut self,
        f: &DVector<f64>,
        b: &DVector<f64>,
        z: &mut DVector<f64>,
    ) -> (QpStatus, usize) {
        self.z0.gemv(1.0, &self.neg_h_inv, f, 0.0);
        for (i, bi) in self.b_buf.iter_mut().enumerate() {
            *bi = b[i] - self.a_dense.row(i).transpose().dot(&self.z0);
        }
        if self.solver.update_b(&self.b_buf).is_err() {
            return (QpStatus::NumericalTrouble, 0);
        }
        self.solver.solve();
        let sol = &self.solver.solution;
        let status = match sol.status {
            SolverStatus::Solved => QpStatus::Solved,
            SolverStatus::AlmostSolved => QpStatus::AlmostSolved,
            SolverStatus::MaxIterations | SolverStatus::MaxTime => QpStatus::MaxIterations,
            SolverStatus::PrimalInfeasible
            | SolverStatus::DualInfeasible
            | SolverStatus::AlmostPrimalInfeasible
            | SolverStatus::AlmostDualInfeasible => QpStatus::Infeasible,
            _ => QpStatus::NumericalTrouble,
        };
        for ((zi, z0i), di) in z.iter_mut().zip(self.z0.iter()).zip(&sol.x) {
            *zi = z0i + di;
        }
        let status = if status.is_usable() && z.iter().any(|v| !v.is_finite()) {
            QpStatus::NumericalTrouble
        } else {
            status
        };
        (status, sol.iterations as usize)
    }
}

/// Compressed-column copy of a dense matrix (only its upper triangle when `upper`), keeping
/// exact zeros out of the pattern.
fn dense_to_csc(m: &Mat, upper: bool) -> CscMatrix<f64> {
    let (rows, cols) = m.shape();
    let mut colptr = Vec::with_capacity(cols + 1);
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    colptr.push(0);
    for j in 0..cols {
        let last = if upper { (j + 1).min(rows) } else { rows };
        for i in 0..last {
            let v = m[(i, j)];
            if v != 0.0 {
                rowval.push(i);
                nzval.push(v);
            }
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows, cols, colptr, rowval, nzval)
}

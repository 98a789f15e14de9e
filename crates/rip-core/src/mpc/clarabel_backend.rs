//! The condensed QP solved by the Clarabel interior-point solver.
//!
//! Clarabel's standard form is `min ½ zᵀ P z + qᵀ z  s.t.  A z + s = b, s ∈ K`; here `P = H`
//! (upper triangle), `q = f`, `A = A_c` and `K` the nonnegative orthant, so `A_c z ≤ b`. The
//! solver, its factorisation pattern and equilibration are set up once; each solve overwrites
//! only `q` and `b` (presolve and zero dropping are off so that data updates are allowed).
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

/// Duality-gap tolerance (absolute and relative). The condensed objective omits the
/// state-dependent constant, so it is often `−10⁴` or below while its optimal value with the
/// constant is near zero; Clarabel's default `1e-8` relative gap then leaves an error of
/// `~10⁻⁴` in inactive slacks and moves. Two more digits cost one or two iterations.
const GAP_TOLERANCE: f64 = 1e-10;

/// Clarabel on the condensed QP, with its data kept to rebuild the solver on `clone`.
pub struct ClarabelBackend {
    solver: DefaultSolver<f64>,
    p: CscMatrix<f64>,
    a: CscMatrix<f64>,
    ncon: usize,
    settings: DefaultSettings<f64>,
    // Clarabel's update functions take `&Vec`; these are reused every solve.
    q_buf: Vec<f64>,
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
        Self::build(&self.p, &self.a, self.settings.clone())
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
            .tol_gap_abs(GAP_TOLERANCE)
            .tol_gap_rel(GAP_TOLERANCE)
            // Refinement of the KKT solves roughly doubles the solve time on these small
            // problems; without it the backends still agree to the tested 2e-5 V.
            .iterative_refinement_enable(false)
            .build()
            .map_err(|e| RipError::invalid("max_iterations", e.to_string()))?;
        Self::build(&dense_to_csc(h, true), &dense_to_csc(a, false), settings)
    }

    fn build(
        p: &CscMatrix<f64>,
        a: &CscMatrix<f64>,
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
            settings,
            q_buf: q,
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
        self.q_buf.copy_from_slice(f.as_slice());
        self.b_buf.copy_from_slice(b.as_slice());
        if self.solver.update_q(&self.q_buf).is_err() || self.solver.update_b(&self.b_buf).is_err()
        {
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
        z.copy_from_slice(&sol.x);
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

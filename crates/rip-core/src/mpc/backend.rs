//! Backend selection: which QP solver computes the move ([`QpSolver`]), what it reported
//! ([`QpStatus`]), and the solver instance an [`Mpc`](super::Mpc) holds.

use nalgebra::DVector;

use super::clarabel_backend::ClarabelBackend;
use super::condense::Condensed;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RipError};

/// Which QP solver computes the move (`[mpc] solver = "active_set"` or `"clarabel"`).
///
/// The default is the active set, for every entry point (the file's `[mpc]`, `rip-rt`,
/// [`MpcSettings`](super::MpcSettings)'s both profiles, Python's `riprs.Mpc`): both solve the
/// same strictly convex QP, the active set exactly to rounding and Clarabel to its stopping
/// tolerances (about 10⁻⁶ V in the first move, farther later in the plan on some problems;
/// docs/design.md measures both against the exact QP solution, and the Python tests hold each
/// to it). The active set (rip-control's dual method) warm-starts from the previous working
/// set and solves in a few microseconds without allocating, which a 100 Hz loop and a Monte Carlo study both need
/// (about 50× Clarabel's throughput in `simulate_metrics`); Clarabel, the interior-point
/// alternative, allocates inside its solve and costs about a hundred times more per step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QpSolver {
    /// Clarabel interior-point solver, accurate to its stopping tolerances. Clarabel allocates
    /// inside its `solve`, so a step with this backend is not allocation-free.
    Clarabel,
    /// The dual active-set solver of rip-control ([`rip_control::qp`], in the manner of
    /// DAQP) with warm start and a bounded iteration count: the same code the device runs.
    /// Nearly dependent rows are exchanged within the method, so no problem is handed to
    /// another solver; solves without allocating.
    #[default]
    ActiveSet,
}

impl QpSolver {
    /// Parses `"clarabel"` or `"active_set"` (also `"active-set"`, `"dense"`).
    pub fn from_name(name: &str) -> Result<Self> {
        match name.to_ascii_lowercase().as_str() {
            "clarabel" => Ok(Self::Clarabel),
            "active_set" | "active-set" | "activeset" | "dense" => Ok(Self::ActiveSet),
            _ => Err(RipError::invalid(
                "solver",
                format!("must be 'clarabel' or 'active_set', got {name:?}"),
            )),
        }
    }

    /// The name accepted by [`from_name`](Self::from_name).
    pub fn name(self) -> &'static str {
        match self {
            Self::Clarabel => "clarabel",
            Self::ActiveSet => "active_set",
        }
    }
}

/// Outcome of one QP solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QpStatus {
    /// Solved to the solver's full accuracy.
    #[default]
    Solved,
    /// Clarabel's reduced-accuracy solution; the move is applied.
    AlmostSolved,
    /// The iteration limit was reached.
    MaxIterations,
    /// A factorisation failed or the solution is not finite.
    NumericalTrouble,
    /// The solver reported (or found) an infeasible problem.
    Infeasible,
    /// The state, previous input, measurement or reference held NaN or Inf, or the QP data
    /// computed from them overflowed.
    InvalidInput,
}

impl QpStatus {
    /// Whether the computed move is applied (otherwise the fallback is).
    pub fn is_usable(self) -> bool {
        matches!(self, Self::Solved | Self::AlmostSolved)
    }

    /// Snake-case name (`"solved"`, `"max_iterations"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::Solved => "solved",
            Self::AlmostSolved => "almost_solved",
            Self::MaxIterations => "max_iterations",
            Self::NumericalTrouble => "numerical_trouble",
            Self::Infeasible => "infeasible",
            Self::InvalidInput => "invalid_input",
        }
    }
}

/// rip-control's dual active set in vectors (the host's problems can exceed the device's
/// fixed capacities).
type DualSolver = rip_control::qp::DualActiveSet<f64, Vec<f64>, Vec<usize>>;

pub(crate) enum Backend {
    Clarabel(Box<ClarabelBackend>),
    /// The dual active-set solver.
    ActiveSet(Box<DualSolver>),
}

impl Clone for Backend {
    fn clone(&self) -> Self {
        match self {
            Self::Clarabel(c) => Self::Clarabel(c.clone()),
            Self::ActiveSet(a) => Self::ActiveSet(a.clone()),
        }
    }
}

impl std::fmt::Debug for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Clarabel(c) => c.fmt(f),
            Self::ActiveSet(..) => f.write_str("DualActiveSet"),
        }
    }
}

impl Backend {
    /// The solver for the condensed QP `qp`.
    pub(crate) fn new(solver: QpSolver, qp: &Condensed, max_iterations: usize) -> Result<Self> {
        Ok(match solver {
            QpSolver::Clarabel => Self::Clarabel(Box::new(ClarabelBackend::new(
                &qp.h,
                &qp.a,
                max_iterations,
            )?)),
            QpSolver::ActiveSet => {
                let (n, ncon) = (qp.nz, qp.ncon);
                let row_major = |m: &crate::linalg::Mat| {
                    let mut v = Vec::with_capacity(m.nrows() * m.ncols());
                    for i in 0..m.nrows() {
                        v.extend(m.row(i).iter());
                    }
                    v
                };
                let iterations = u32::try_from(max_iterations).unwrap_or(u32::MAX);
                Self::ActiveSet(Box::new(
                    DualSolver::new_in(
                        &row_major(&qp.h),
                        &row_major(&qp.a),
                        n,
                        ncon,
                        iterations,
                        vec![0.0; DualSolver::storage_len(n, ncon)],
                        vec![0; n],
                    )
                    .ok_or_else(|| RipError::NotPositiveDefinite {
                        name: "QP Hessian".into(),
                    })?,
                ))
            }
        })
    }

    /// Solves `min ½zᵀHz + fᵀz` s.t. `A_c z ≤ b` into `z`; returns the status and iterations.
    pub(crate) fn solve(
        &mut self,
        f: &DVector<f64>,
        b: &DVector<f64>,
        z: &mut DVector<f64>,
    ) -> (QpStatus, usize) {
        match self {
            Self::Clarabel(solver) => solver.solve(f, b, z),
            Self::ActiveSet(solver) => {
                use rip_control::qp::QpOutcome;
                let (outcome, iterations) = solver.solve(f.as_slice(), b.as_slice());
                z.copy_from_slice(solver.solution());
                let status = match outcome {
                    QpOutcome::Solved => QpStatus::Solved,
                    QpOutcome::IterationLimit => QpStatus::MaxIterations,
                    QpOutcome::Infeasible => QpStatus::Infeasible,
                    QpOutcome::NumericalTrouble => QpStatus::NumericalTrouble,
                };
                (status, iterations as usize)
            }
        }
    }

    /// Forgets the warm start.
    pub(crate) fn reset(&mut self) {
        if let Self::ActiveSet(s) = self {
            s.reset();
        }
    }
}

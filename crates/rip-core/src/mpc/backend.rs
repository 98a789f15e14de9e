//! Backend selection: which QP solver computes the move ([`QpSolver`]), what it reported
//! ([`QpStatus`]), and the solver instance an [`Mpc`](super::Mpc) holds.

use nalgebra::DVector;

use super::active_set::ActiveSetSolver;
use super::clarabel_backend::ClarabelBackend;
use super::condense::Condensed;
use serde::{Deserialize, Serialize};

use crate::error::{Result, RipError};

/// Which QP solver computes the move (`[mpc] solver = "active_set"` or `"clarabel"`).
///
/// The default is the active set, for every entry point (the file's `[mpc]`, `rip-rt`,
/// [`MpcSettings`](super::MpcSettings)'s both profiles, Python's `riprs.Mpc`): both solve the
/// same strictly convex QP to the same minimiser (agreeing to the solvers' tolerances, which
/// the MPC tests check along the paper's loop), so the choice changes speed, not the
/// controller. The active set warm-starts from the previous working set and solves in a few
/// microseconds without allocating, which a 100 Hz loop and a Monte Carlo study both need
/// (about 50× Clarabel's throughput in `simulate_metrics`); Clarabel, the interior-point
/// reference, allocates inside its solve and costs about a hundred times more per step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QpSolver {
    /// Clarabel interior-point solver (the reference). Clarabel allocates inside its `solve`,
    /// so a step with this backend is not allocation-free.
    Clarabel,
    /// Dense primal active-set solver with warm start (module `active_set`); solves
    /// without allocating. A problem whose nearly dependent constraints make its working-set
    /// systems singular (rare: none along the paper's loop) is handed to Clarabel, which
    /// allocates.
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

pub(crate) enum Backend {
    Clarabel(Box<ClarabelBackend>),
    /// The active-set solver, and Clarabel on the same QP for the rare problem whose nearly
    /// dependent constraints (output rows late in a long horizon converge to the steady-state
    /// gain) make its working-set systems singular.
    ActiveSet(Box<ActiveSetSolver>, Box<ClarabelBackend>),
}

impl Clone for Backend {
    fn clone(&self) -> Self {
        match self {
            Self::Clarabel(c) => Self::Clarabel(c.clone()),
            Self::ActiveSet(a, rescue) => Self::ActiveSet(a.clone(), rescue.clone()),
        }
    }
}

impl std::fmt::Debug for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Clarabel(c) => c.fmt(f),
            Self::ActiveSet(..) => f.write_str("ActiveSetSolver"),
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
            QpSolver::ActiveSet => Self::ActiveSet(
                Box::new(
                    ActiveSetSolver::new(&qp.h, &qp.a, Some(qp.nz - 1), max_iterations)
                        .ok_or_else(|| RipError::NotPositiveDefinite {
                            name: "QP Hessian".into(),
                        })?,
                ),
                Box::new(ClarabelBackend::new(&qp.h, &qp.a, max_iterations)?),
            ),
        })
    }

    /// Solves `min ½zᵀHz + fᵀz` s.t. `A_c z ≤ b` into `z`; returns the status and iterations.
    /// `u_prev`, `bounds` and `m` let the active-set solver start from a move that respects the
    /// input bounds.
    pub(crate) fn solve(
        &mut self,
        f: &DVector<f64>,
        b: &DVector<f64>,
        u_prev: &[f64],
        (lo, hi): (&[f64], &[f64]),
        m: usize,
        z: &mut DVector<f64>,
    ) -> (QpStatus, usize) {
        match self {
            Self::Clarabel(solver) => solver.solve(f, b, z),
            Self::ActiveSet(solver, rescue) => {
                let out = solver.solve(f, b, |z| project_inputs(z, u_prev, lo, hi, m));
                z.copy_from(solver.solution());
                let status = if out.status.is_usable() && z.iter().any(|v| !v.is_finite()) {
                    QpStatus::NumericalTrouble
                } else {
                    out.status
                };
                if status == QpStatus::NumericalTrouble {
                    let (status, iterations) = rescue.solve(f, b, z);
                    (status, out.iterations + iterations)
                } else {
                    (status, out.iterations)
                }
            }
        }
    }

    /// Forgets the warm start.
    pub(crate) fn reset(&mut self) {
        if let Self::ActiveSet(s, _) = self {
            s.reset();
        }
    }
}

/// Moves `Δ` so that every blocked input `u(k+j) = u⁻ + Σ_{l≤j} Δu(k+l)` lies in its bounds:
/// the running sums are clamped and the moves recomputed from them.
fn project_inputs(z: &mut [f64], u_prev: &[f64], lo: &[f64], hi: &[f64], m: usize) {
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

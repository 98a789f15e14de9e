//! The condensed QP: prediction matrices, Hessian, linear-term maps and constraint rows.
//!
//! Everything here is built once in [`Condensed::new`]; per step only the vectors `f` and `b`
//! are filled by [`Condensed::fill_linear`] (no allocation).
//!
//! # Prediction (move blocking)
//!
//! With `Δ = [Δu(k); …; Δu(k+m−1)]` and `Δu(k+j) = 0` for `j ≥ m`, the inputs and predicted
//! (scaled) outputs are affine in `x = x̂[k|k]`, `u⁻ = u(k−1)` and `Δ`:
//!
//! ```text
//! U = 1⊗u⁻ + T Δ,                  T(j, l) = I  for l ≤ j              (j = 0..P−1)
//! Y = Φ x + Γ u⁻ + G Δ,            Φ_i = C Aⁱ,  Γ_i = C S_i,  G(i, l) = C S_{i−l} (i > l)
//! S_i = Σ_{j<i} Aʲ B                                                    (i = 1..P)
//! ```
//!
//! # Prediction grid
//!
//! With `prediction_step = s > 1` the index `i` above counts steps of `s` sample periods:
//! `A` and `B` stand for the grid's `A_s = Aˢ` and `B_s = Σ_{j<s} Aʲ B` (the input held over
//! the `s` periods of a grid step), so `y(k+i|k)` is the output `i·s` periods ahead,
//! `Δu(k+l)` the change at the start of grid step `l`, and the cost and the rows below are
//! taken on that grid. Only the first move is applied, for one period, before the next solve.
//!
//! # Cost `½ zᵀ H z + fᵀ z + const` over `z = [Δ; ε]`
//!
//! ```text
//! H = blkdiag( 2 (Gᵀ Q_y G + R_Δu + Tᵀ Q_u T),  2 ρ_ε )
//! f = 2 Gᵀ Q_y (Φ x + Γ u⁻ − S_y⁻¹ R) + 2 Tᵀ Q_u (1⊗u⁻ − 1⊗u_t)
//! Q_y = I_P ⊗ diag(w^y)²,  Q_u = I_P ⊗ diag(w^u / s^u)²,  R_Δu = I_m ⊗ diag(w^Δu / s^u)²
//! ```
//!
//! # Constraints `A_c z ≤ b = b₀ + B_x x + B_u u⁻`
//!
//! Rows, in this order (only finite bounds produce rows):
//! 1. hard inputs, `u_min ≤ u(k+j) ≤ u_max` for `j = 0..m−1` (for `j ≥ m` the blocked input
//!    equals `u(k+m−1)`, so those rows would repeat);
//! 2. soft outputs, `G_i Δ − ε ≤ y_max/s_y − Φ_i x − Γ_i u⁻` and
//!    `−G_i Δ − ε ≤ −y_min/s_y + Φ_i x + Γ_i u⁻` for `i = 1..P` (equal concern relaxation 1);
//! 3. `−ε ≤ 0`.

use nalgebra::{DVector, DVectorView};

use crate::linalg::Mat;

/// Which rows of the constraint matrix hold which kind of constraint.
#[derive(Debug, Clone)]
pub(crate) struct RowLayout {
    /// Number of hard-input rows (first block).
    pub n_input: usize,
    /// Number of soft-output rows (second block).
    pub n_soft: usize,
}

/// The condensed QP data that does not depend on the current state (module docs).
#[derive(Debug, Clone)]
pub(crate) struct Condensed {
    pub nx: usize,
    pub nu: usize,
    pub ny: usize,
    pub p: usize,
    pub m: usize,
    /// `m·nu + 1`.
    pub nz: usize,
    pub ncon: usize,
    pub h: Mat,
    fx: Mat,
    fu: Mat,
    /// `[F_r,1 … F_r,P]`, `F_r,i = 2 G_iᵀ Q_y S_y⁻¹` (nz × P·ny).
    fr: Mat,
    /// Suffix sums `Σ_{j ≥ i} F_r,j` (nz × P·ny), for a preview shorter than `P`.
    fr_tail: Mat,
    f0: DVector<f64>,
    pub a: Mat,
    b0: DVector<f64>,
    bx: Mat,
    bu: Mat,
    pub rows: RowLayout,
    /// Prediction matrices (scaled outputs), kept for reporting predicted trajectories.
    pub phi: Mat,
    pub gamma: Mat,
    pub g: Mat,
}

/// The numbers the condensed problem is built from (validated by the caller).
pub(crate) struct CondenseInput<'a> {
    pub a: &'a Mat,
    pub b: &'a Mat,
    /// Scaled output matrix `[S_y⁻¹ C, C_od]`.
    pub c: &'a Mat,
    pub p: usize,
    pub m: usize,
    /// Sample periods per prediction step (module docs, "Prediction grid").
    pub step: usize,
    pub output_weights: &'a [f64],
    pub input_weights: &'a [f64],
    pub input_rate_weights: &'a [f64],
    pub input_target: &'a [f64],
    pub input_scales: &'a [f64],
    pub output_scales: &'a [f64],
    pub input_bounds: &'a [(f64, f64)],
    pub output_bounds: &'a [(f64, f64)],
    pub ecr_weight: f64,
}

impl Condensed {
    pub fn new(d: &CondenseInput<'_>) -> Self {
        let Dims {
            nx,
            nu,
            ny,
            p,
            m,
            nz,
            ..
        } = Dims::of(d);
        let Prediction { phi, gamma, g, t } = prediction(d);
        let Cost {
            h,
            fx,
            fu,
            f0,
            fr,
            fr_tail,
        } = cost(d, &phi, &gamma, &g, &t);
        let (a, b0, bx, bu, rows) = constraints(d, &phi, &gamma, &g);
        let ncon = a.nrows();

        Self {
            nx,
            nu,
            ny,
            p,
            m,
            nz,
            ncon,
            h,
            fx,
            fu,
            fr,
            fr_tail,
            f0,
            a,
            b0,
            bx,
            bu,
            rows,
            phi,
            gamma,
            g,
        }
    }

    /// Fills `f` and `b` for the state `x`, previous input `u_prev` and reference `r`.
    ///
    /// `r` holds `q·ny` values, `1 ≤ q ≤ P`, row `i` being `r(k+1+i)` in engineering units;
    /// the last row is held for the remaining steps (a constant reference is `q = 1`).
    pub fn fill_linear(
        &self,
        x: &[f64],
        u_prev: &[f64],
        r: &[f64],
        f: &mut DVector<f64>,
        b: &mut DVector<f64>,
    ) {
        let ny = self.ny;
        let q = r.len() / ny;
        debug_assert!(q >= 1 && q <= self.p && q * ny == r.len());
        let xv = DVectorView::from_slice(x, self.nx);
        let uv = DVectorView::from_slice(u_prev, self.nu);
        f.copy_from(&self.f0);
        f.gemv(1.0, &self.fx, &xv, 1.0);
        f.gemv(1.0, &self.fu, &uv, 1.0);
        if q > 1 {
            let head = DVectorView::from_slice(&r[..(q - 1) * ny], (q - 1) * ny);
            f.gemv(-1.0, &self.fr.columns(0, (q - 1) * ny), &head, 1.0);
        }
        let last = DVectorView::from_slice(&r[(q - 1) * ny..], ny);
        f.gemv(-1.0, &self.fr_tail.columns((q - 1) * ny, ny), &last, 1.0);

        b.copy_from(&self.b0);
        b.gemv(1.0, &self.bx, &xv, 1.0);
        b.gemv(1.0, &self.bu, &uv, 1.0);
    }

    /// Fills the QP part of a rip-control design: `H`, the linear-term maps (the reference
    /// map is the one of a constant reference, the first block of the suffix sums) and the
    /// rows. Errors name what exceeds the onboard capacity.
    pub fn fill_control(&self, d: &mut rip_control::Design) -> crate::error::Result<()> {
        use crate::onboard::put;
        use rip_control::{MAX_NCON, MAX_NX, MAX_NY, MAX_NZ};
        if self.nu != 1 {
            return Err(crate::error::RipError::invalid(
                "B",
                "the onboard MPC has one input",
            ));
        }
        if self.p > rip_control::MAX_PREDICTION_HORIZON {
            return Err(crate::error::RipError::invalid(
                "prediction_horizon",
                format!(
                    "{} exceeds the onboard capacity {}",
                    self.p,
                    rip_control::MAX_PREDICTION_HORIZON
                ),
            ));
        }
        if self.m > rip_control::MAX_CONTROL_HORIZON {
            return Err(crate::error::RipError::invalid(
                "control_horizon",
                format!(
                    "{} exceeds the onboard capacity {}",
                    self.m,
                    rip_control::MAX_CONTROL_HORIZON
                ),
            ));
        }
        put("H", &mut d.h, &self.h, MAX_NZ, MAX_NZ)?;
        put(
            "f0",
            &mut d.f0,
            &Mat::from_column_slice(self.nz, 1, self.f0.as_slice()),
            MAX_NZ,
            1,
        )?;
        put("F_x", &mut d.fx, &self.fx, MAX_NZ, MAX_NX)?;
        put("F_u", &mut d.fu, &self.fu, MAX_NZ, 1)?;
        put(
            "F_r",
            &mut d.fr,
            &self.fr_tail.columns(0, self.ny).into_owned(),
            MAX_NZ,
            MAX_NY,
        )?;
        put("A_c", &mut d.ac, &self.a, MAX_NCON, MAX_NZ)?;
        put(
            "b0",
            &mut d.b0,
            &Mat::from_column_slice(self.ncon, 1, self.b0.as_slice()),
            MAX_NCON,
            1,
        )?;
        put("B_x", &mut d.bx, &self.bx, MAX_NCON, MAX_NX)?;
        put("B_u", &mut d.bu, &self.bu, MAX_NCON, 1)?;
        d.horizon = self.p;
        d.control_horizon = self.m;
        d.ncon = self.ncon;
        d.n_input_rows = self.rows.n_input;
        d.n_soft_rows = self.rows.n_soft;
        Ok(())
    }

    /// Predicted scaled outputs `Y = Φ x + Γ u⁻ + G Δ` (P·ny, stacked by step).
    pub fn predict(&self, x: &[f64], u_prev: &[f64], du: &[f64]) -> DVector<f64> {
        &self.phi * DVectorView::from_slice(x, self.nx)
            + &self.gamma * DVectorView::from_slice(u_prev, self.nu)
            + &self.g * DVectorView::from_slice(du, self.m * self.nu)
    }
}

/// The problem's sizes: states, inputs, outputs, horizons, moves `m·nu` and `nz = m·nu + 1`.
#[derive(Debug, Clone, Copy)]
struct Dims {
    nx: usize,
    nu: usize,
    ny: usize,
    p: usize,
    m: usize,
    nd: usize,
    nz: usize,
}

impl Dims {
    fn of(d: &CondenseInput<'_>) -> Self {
        let nu = d.b.ncols();
        Self {
            nx: d.a.nrows(),
            nu,
            ny: d.c.nrows(),
            p: d.p,
            m: d.m,
            nd: d.m * nu,
            nz: d.m * nu + 1,
        }
    }
}

/// The prediction matrices `Φ`, `Γ`, `G` and the input map `T` (module docs, "Prediction").
struct Prediction {
    phi: Mat,
    gamma: Mat,
    g: Mat,
    t: Mat,
}

fn prediction(d: &CondenseInput<'_>) -> Prediction {
    let Dims {
        nx,
        nu,
        ny,
        p,
        m,
        nd,
        ..
    } = Dims::of(d);
    let (a_grid, b_grid) = grid_model(d.a, d.b, d.step);
    // S_i = Σ_{j<i} Aʲ B and Aⁱ, i = 0..P, on the grid.
    let mut apow = Mat::identity(nx, nx);
    let mut s = vec![Mat::zeros(nx, nu)];
    let mut phi = Mat::zeros(p * ny, nx);
    let mut gamma = Mat::zeros(p * ny, nu);
    for i in 1..=p {
        let next_s = &s[i - 1] + &apow * &b_grid;
        apow = &apow * &a_grid;
        phi.view_mut(((i - 1) * ny, 0), (ny, nx))
            .copy_from(&(d.c * &apow));
        gamma
            .view_mut(((i - 1) * ny, 0), (ny, nu))
            .copy_from(&(d.c * &next_s));
        s.push(next_s);
    }
    let mut g = Mat::zeros(p * ny, nd);
    for i in 1..=p {
        for l in 0..m.min(i) {
            g.view_mut(((i - 1) * ny, l * nu), (ny, nu))
                .copy_from(&(d.c * &s[i - l]));
        }
    }
    let mut t = Mat::zeros(p * nu, nd);
    for j in 0..p {
        for l in 0..m.min(j + 1) {
            t.view_mut((j * nu, l * nu), (nu, nu)).fill_diagonal(1.0);
        }
    }
    Prediction { phi, gamma, g, t }
}

/// `(Aˢ, Σ_{j<s} Aʲ B)`: one prediction step of `s` periods with the input held.
fn grid_model(a: &Mat, b: &Mat, step: usize) -> (Mat, Mat) {
    let mut a_s = Mat::identity(a.nrows(), a.ncols());
    let mut b_s = Mat::zeros(b.nrows(), b.ncols());
    for _ in 0..step {
        b_s += &a_s * b;
        a_s = &a_s * a;
    }
    (a_s, b_s)
}

/// `H` and the maps from `x`, `u⁻`, the reference and the input target to `f` (module docs,
/// "Cost").
struct Cost {
    h: Mat,
    fx: Mat,
    fu: Mat,
    f0: DVector<f64>,
    fr: Mat,
    fr_tail: Mat,
}

fn cost(d: &CondenseInput<'_>, phi: &Mat, gamma: &Mat, g: &Mat, t: &Mat) -> Cost {
    let Dims {
        nx,
        nu,
        ny,
        p,
        nd,
        nz,
        ..
    } = Dims::of(d);
    let qy = DVector::from_fn(p * ny, |r, _| d.output_weights[r % ny].powi(2));
    let qu = DVector::from_fn(p * nu, |r, _| {
        (d.input_weights[r % nu] / d.input_scales[r % nu]).powi(2)
    });
    let rdu = DVector::from_fn(nd, |r, _| {
        (d.input_rate_weights[r % nu] / d.input_scales[r % nu]).powi(2)
    });
    let qy_g = scale_rows(g, &qy);
    let qu_t = scale_rows(t, &qu);

    let mut h = Mat::zeros(nz, nz);
    let h_dd =
        (g.transpose() * &qy_g + t.transpose() * &qu_t) * 2.0 + Mat::from_diagonal(&(rdu * 2.0));
    h.view_mut((0, 0), (nd, nd)).copy_from(&h_dd);
    h[(nd, nd)] = 2.0 * d.ecr_weight;
    // Exact symmetry keeps the factorizations of both backends well defined.
    let h = (&h + h.transpose()) * 0.5;

    let mut fx = Mat::zeros(nz, nx);
    fx.view_mut((0, 0), (nd, nx))
        .copy_from(&(qy_g.transpose() * phi * 2.0));
    let mut fu = Mat::zeros(nz, nu);
    let mut ones_u = Mat::zeros(p * nu, nu);
    for j in 0..p {
        ones_u.view_mut((j * nu, 0), (nu, nu)).fill_diagonal(1.0);
    }
    fu.view_mut((0, 0), (nd, nu))
        .copy_from(&((qy_g.transpose() * gamma + qu_t.transpose() * &ones_u) * 2.0));
    let mut f0 = DVector::zeros(nz);
    let target = DVector::from_column_slice(d.input_target);
    f0.rows_mut(0, nd)
        .copy_from(&(qu_t.transpose() * &ones_u * &target * -2.0));

    let mut fr = Mat::zeros(nz, p * ny);
    for col in 0..p * ny {
        let w = 2.0 / d.output_scales[col % ny];
        for row in 0..nd {
            fr[(row, col)] = qy_g[(col, row)] * w;
        }
    }
    let mut fr_tail = fr.clone();
    for i in (0..p.saturating_sub(1)).rev() {
        for o in 0..ny {
            let next = fr_tail.column((i + 1) * ny + o).clone_owned();
            let mut col = fr_tail.column_mut(i * ny + o);
            col += next;
        }
    }
    Cost {
        h,
        fx,
        fu,
        f0,
        fr,
        fr_tail,
    }
}

/// `A_c`, `b₀`, `B_x`, `B_u` and the row layout (module docs, "Constraints").
fn constraints(
    d: &CondenseInput<'_>,
    phi: &Mat,
    gamma: &Mat,
    g: &Mat,
) -> (Mat, DVector<f64>, Mat, Mat, RowLayout) {
    let Dims {
        nx,
        nu,
        ny,
        p,
        m,
        nd,
        nz,
    } = Dims::of(d);
    // Constraint rows.
    let finite_sides = |bounds: &[(f64, f64)]| -> usize {
        bounds
            .iter()
            .map(|&(lo, hi)| usize::from(lo.is_finite()) + usize::from(hi.is_finite()))
            .sum()
    };
    let n_input = m * finite_sides(d.input_bounds);
    let n_soft = p * finite_sides(d.output_bounds);
    let ncon = n_input + n_soft + 1;
    let mut a = Mat::zeros(ncon, nz);
    let mut b0 = DVector::zeros(ncon);
    let mut bx = Mat::zeros(ncon, nx);
    let mut bu = Mat::zeros(ncon, nu);
    let mut row = 0;
    for j in 0..m {
        for (c, &(lo, hi)) in d.input_bounds.iter().enumerate() {
            for (bound, sign) in [(hi, 1.0), (lo, -1.0)] {
                if !bound.is_finite() {
                    continue;
                }
                for l in 0..=j {
                    a[(row, l * nu + c)] = sign;
                }
                b0[row] = sign * bound;
                bu[(row, c)] = -sign;
                row += 1;
            }
        }
    }
    for i in 0..p {
        for (o, &(lo, hi)) in d.output_bounds.iter().enumerate() {
            for (bound, sign) in [(hi, 1.0), (lo, -1.0)] {
                if !bound.is_finite() {
                    continue;
                }
                let r = i * ny + o;
                for col in 0..nd {
                    a[(row, col)] = sign * g[(r, col)];
                }
                a[(row, nd)] = -1.0;
                b0[row] = sign * bound / d.output_scales[o];
                for col in 0..nx {
                    bx[(row, col)] = -sign * phi[(r, col)];
                }
                for col in 0..nu {
                    bu[(row, col)] = -sign * gamma[(r, col)];
                }
                row += 1;
            }
        }
    }
    a[(row, nd)] = -1.0;
    debug_assert_eq!(row + 1, ncon);
    (a, b0, bx, bu, RowLayout { n_input, n_soft })
}

/// `diag(w) M`.
fn scale_rows(m: &Mat, w: &DVector<f64>) -> Mat {
    let mut out = m.clone();
    for (mut row, &wi) in out.row_iter_mut().zip(w.iter()) {
        row *= wi;
    }
    out
}

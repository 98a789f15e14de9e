//! The model and settings of the reproduced study (Huynh et al., "A survey of LQG over MPC and
//! LQR control for rotary inverted pendulum", section 3).
//!
//! State order: arm angle θ, arm rate θ̇, pendulum angle α (0 = upright), pendulum rate α̇;
//! input: motor voltage u (V); outputs: θ and α (rad); sample time `Ts = 0.01 s`.
//!
//! # How the printed model was recovered
//!
//! The paper prints `A_d`, `B_d` (eq. (3)) rounded to 2–5 digits, and the Kalman gains `L`, `M`
//! (eq. (12)) that MATLAB computed from the unrounded matrices. Designing the filter from the
//! printed `A_d` misses eq. (12) by up to 6·10⁻³, so the unrounded plant is recovered instead:
//! a continuous-time model with the structure of a linearised Furuta pendulum,
//!
//! ```text
//! ẋ = [0 1 0 0; 0 a₁₁ a₁₂ a₁₃; 0 0 0 1; 0 a₃₁ a₃₂ a₃₃] x + [0; b₁; 0; b₃] u,
//! ```
//!
//! is discretised by zero-order hold and its eight parameters are fitted (least squares, each
//! residual in units of half the last printed digit) to the 20 printed entries of `A_d`, `B_d`
//! and the 20 printed entries of `L` and `M`. The result ([`CONTINUOUS_PARAMETERS`]) reproduces
//! every printed entry of `L` and `M` and of `B_d` exactly after rounding, and every entry of
//! `A_d` to its printed precision (the test suite checks all of this).
//!
//! # Corrections to the printed numbers
//!
//! 1. `A_d[0][1]` is printed `0.001`; it is `0.009916`. A rate entry near `Ts = 0.01` is what
//!    any sampled double integrator has, and with `0.001` the designed gains are wrong in the
//!    first digit (`L[0][0] = 0.0143` instead of the printed `0.0723`), while `0.0099` gives
//!    `0.0721` and the fitted model gives `0.0723`.
//! 2. Eq. (8) prints `Q[1][0] = 0.008`; `Q = BBᵀ` is symmetric and `Q[0][1] = 0.0008`
//!    (`= 0.002 · 0.398`), so the printed value drops a zero.
//! 3. `A_d[2][1]` is printed `0`; the model has `−0.000053`, which row 2's three-decimal
//!    precision (`1.003`) rounds to zero.

use crate::error::Result;
use crate::linalg::{c2d, Mat};

/// Sample time of the study (s).
pub const TS: f64 = 0.01;

/// `[a₁₁, a₁₂, a₁₃, a₃₁, a₃₂, a₃₃, b₁, b₃]` of the continuous-time model (module docs).
pub const CONTINUOUS_PARAMETERS: [f64; 8] = [
    -1.691009, 16.54502, -0.2274903, -1.061153, 51.64511, -0.7087696, 4.018462, 2.520259,
];

/// The actuator limit (V): the motor's rated ±12 V, the paper's hard input bound `|u| ≤ 12 V`
/// (section 3). The default of every clamp on the voltage: the regulators' `[u_min, u_max]`, the
/// MPC's input bound, the simulator's saturation and `rip-rt`'s safety limit. Defined once, in
/// the `no_std` controllers (`rip_control::INPUT_LIMIT`), which the device and the firmware share.
pub const INPUT_LIMIT: f64 = rip_control::INPUT_LIMIT;

/// Input scale factor `L_su` of the MPC (section 3).
pub const INPUT_SCALE: f64 = 10.0;

/// `A_d` exactly as printed in eq. (3), typo included (for comparison tables).
pub const PRINTED_AD: [[f64; 4]; 4] = [
    [1.0, 0.001, 0.0008, 0.0],
    [0.0, 0.9832, 0.1636, -0.00143],
    [0.0, 0.0, 1.003, 0.01],
    [0.0, -0.0105, 0.5142, 0.996],
];

/// `B_d` as printed (the `B_u` column of eq. (11)).
pub const PRINTED_BD: [f64; 4] = [0.0002, 0.0398, 0.0001, 0.0249];

/// Predictor gain `L` as printed in eq. (12).
pub const PRINTED_L: [[f64; 2]; 5] = [
    [0.0723, 0.0317],
    [0.2659, 0.2788],
    [0.0214, 0.1524],
    [0.1681, 1.0357],
    [-0.0001, -0.0093],
];

/// Innovation gain `M` as printed in eq. (12).
pub const PRINTED_M: [[f64; 2]; 5] = [
    [0.0696, 0.029],
    [0.2674, 0.2612],
    [0.0198, 0.1424],
    [0.1615, 0.9695],
    [-0.0001, -0.0093],
];

/// Tab. 1: experimental RMSE of (arm angle rad, pendulum angle rad, voltage V).
pub const TABLE1: [(&str, [f64; 3]); 3] = [
    ("LQG", [0.341, 0.015, 0.308]),
    ("LQR", [0.061, 0.007, 1.75]),
    ("MPC", [0.073, 0.005, 0.8]),
];

/// A discrete-time state-space model `x[k+1] = A x + B u`, `y = C x + D u`.
#[derive(Debug, Clone)]
pub struct StateSpace {
    /// State matrix `A` (`n × n`).
    pub a: Mat,
    /// Input matrix `B` (`n × m`), one column per input.
    pub b: Mat,
    /// Output matrix `C` (`p × n`), one row per output.
    pub c: Mat,
    /// Feedthrough matrix `D` (`p × m`).
    pub d: Mat,
    /// Sample time (s); `0` for a continuous-time model.
    pub ts: f64,
}

/// The noise model of eqs. (8)–(10): `Q = BBᵀ`, `R = DDᵀ`, `N = BDᵀ` for the augmented model.
#[derive(Debug, Clone)]
pub struct NoiseModel {
    /// Process-noise covariance `Q = B Bᵀ` (eq. (8)), `5 × 5` on the augmented state.
    pub q: Mat,
    /// Measurement-noise covariance `R = D Dᵀ` (eq. (9)), `2 × 2` on the outputs (θ, α).
    pub r: Mat,
    /// Cross-covariance `N = B Dᵀ` (eq. (10)), `5 × 2`, between process and measurement noise.
    pub n: Mat,
}

/// The continuous-time linear model `(A_c, B_c)` (module docs).
pub fn continuous_model() -> (Mat, Mat) {
    let [a11, a12, a13, a31, a32, a33, b1, b3] = CONTINUOUS_PARAMETERS;
    let a = Mat::from_row_slice(
        4,
        4,
        &[
            0.0, 1.0, 0.0, 0.0, //
            0.0, a11, a12, a13, //
            0.0, 0.0, 0.0, 1.0, //
            0.0, a31, a32, a33,
        ],
    );
    let b = Mat::from_row_slice(4, 1, &[0.0, b1, 0.0, b3]);
    (a, b)
}

/// The plant of section 3: `A_d`, `B_d` (4 states, 1 input), `C` picking θ and α, `D = 0`.
pub fn discrete_model() -> StateSpace {
    let (ac, bc) = continuous_model();
    let (a, b) = c2d(&ac, &bc, TS).expect("the built-in model is valid");
    StateSpace {
        a,
        b,
        c: output_matrix(),
        d: Mat::zeros(2, 1),
        ts: TS,
    }
}

/// `C` of the plant: the two angles.
pub fn output_matrix() -> Mat {
    Mat::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0])
}

/// The 5-state observer model of eq. (3), plant plus one integrated-white-noise output
/// disturbance feeding both outputs (eq. (1)), with inputs `[u, w_od, w_n1, w_n2]`:
///
/// ```text
/// A = [A_d 0; 0 1],  B = [B_d·L_su 0 0 0; 0 0.01 0 0],  C = [C 1 1ᵀ],  D = [0 0 I₂]
/// ```
///
/// The `u` column is scaled by `L_su` because MATLAB's MPC models the manipulated variable as
/// unit-variance white noise in scaled units.
pub fn augmented_model() -> StateSpace {
    let plant = discrete_model();
    let mut a = Mat::zeros(5, 5);
    a.view_mut((0, 0), (4, 4)).copy_from(&plant.a);
    a[(4, 4)] = 1.0;
    let mut b = Mat::zeros(5, 4);
    b.view_mut((0, 0), (4, 1))
        .copy_from(&(&plant.b * INPUT_SCALE));
    b[(4, 1)] = 0.01;
    let mut c = Mat::zeros(2, 5);
    c.view_mut((0, 0), (2, 4)).copy_from(&plant.c);
    c[(0, 4)] = 1.0;
    c[(1, 4)] = 1.0;
    let mut d = Mat::zeros(2, 4);
    d[(0, 2)] = 1.0;
    d[(1, 3)] = 1.0;
    StateSpace { a, b, c, d, ts: TS }
}

/// Eqs. (8)–(10) from [`augmented_model`].
pub fn noise_model() -> NoiseModel {
    let m = augmented_model();
    NoiseModel {
        q: &m.b * m.b.transpose(),
        r: &m.d * m.d.transpose(),
        n: &m.b * m.d.transpose(),
    }
}

/// The diagonal of the LQR state weight of eq. (13), `Q = diag(25, 0, 50, 0)` for
/// `[θ, θ̇, α, α̇]`: the `[lqr]` section's default.
pub const LQR_Q: [f64; 4] = [25.0, 0.0, 50.0, 0.0];
/// The LQR input weight of eq. (13), `R = 0.1`: the `[lqr]` section's default.
pub const LQR_R: f64 = 0.1;

/// LQR weights of eq. (13): `Q = diag(`[`LQR_Q`]`)`, `R = `[`LQR_R`].
pub fn lqr_weights() -> (Mat, Mat) {
    (
        Mat::from_diagonal(&nalgebra::DVector::from_row_slice(&LQR_Q)),
        Mat::from_element(1, 1, LQR_R),
    )
}

/// The Kalman design of eq. (11): `kalman(ss(A, [B_u G], C, [D H], Ts), Q, R, N)` with `G = I`,
/// `H = 0` on the augmented model.
pub fn kalman_design() -> Result<crate::kalman::KalmanDesign> {
    let m = augmented_model();
    let noise = noise_model();
    let g = Mat::identity(5, 5);
    crate::kalman::kalman(&m.a, &g, &m.c, &noise.q, &noise.r, Some(&noise.n), None)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_to(v: f64, decimals: i32) -> f64 {
        let s = 10f64.powi(decimals);
        (v * s).round() / s
    }

    #[test]
    fn every_default_voltage_clamp_is_the_one_input_limit() {
        use crate::controller::Controller;
        // Section 3: |u| <= 12 V.
        assert_eq!(INPUT_LIMIT, 12.0);
        assert_eq!(crate::SimConfig::default().u_limit, INPUT_LIMIT);
        let mpc = crate::mpc::paper::settings(crate::mpc::QpSolver::default());
        assert_eq!(mpc.input_bounds, vec![(-INPUT_LIMIT, INPUT_LIMIT)]);
        let spec = crate::spec::Spec::default();
        assert_eq!(spec.mpc.input_bounds, vec![(-INPUT_LIMIT, INPUT_LIMIT)]);
        // A far-off reference drives the default regulators into their clamp.
        let mut u = [0.0];
        for mut c in [
            Box::new(crate::Lqr::paper().unwrap()) as Box<dyn Controller>,
            Box::new(crate::Lqg::paper().unwrap()),
        ] {
            c.step(&[0.0, 0.0], &[100.0, 0.0], &mut u);
            assert_eq!(u[0].abs(), INPUT_LIMIT);
        }
    }

    #[test]
    fn kalman_gains_reproduce_eq12_to_printed_precision() {
        let design = kalman_design().unwrap();
        for i in 0..5 {
            for j in 0..2 {
                let digits = if (i, j) == (0, 1) { 3 } else { 4 };
                assert_eq!(
                    round_to(design.l[(i, j)], 4),
                    PRINTED_L[i][j],
                    "L[{i}][{j}]"
                );
                assert_eq!(
                    round_to(design.m[(i, j)], digits),
                    PRINTED_M[i][j],
                    "M[{i}][{j}]"
                );
            }
        }
    }

    #[test]
    fn discrete_model_matches_printed_matrices() {
        let m = discrete_model();
        for i in 0..4 {
            assert!((m.b[(i, 0)] - PRINTED_BD[i]).abs() <= 0.5e-4, "B_d[{i}]");
            for (j, printed) in PRINTED_AD[i].iter().enumerate() {
                let half_unit = match (i, j) {
                    (0, 1) => continue, // corrected typo, module docs
                    (1, 3) => 0.5e-5,
                    (2, _) | (3, 3) => 0.5e-3,
                    _ => 0.5e-4,
                };
                let err = (m.a[(i, j)] - printed).abs();
                assert!(err <= half_unit * 1.0001, "A_d[{i}][{j}] off by {err}");
            }
        }
        assert!((m.a[(0, 1)] - 0.0099).abs() < 0.5e-4);
    }
}

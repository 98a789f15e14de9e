//! The made-up LQG both augmented-estimator tests start from, the current-form Kalman filter
//! written out densely, and their single-precision check.

// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use rip_control::{Controller, Design, Kind, Measurement};

/// Estimator states: the plant's four and one more (a disturbance).
pub const N: usize = 5;

/// An LQG design on a stable 4-state model with small gains and made-up numbers, its estimator
/// of [`N`] states: the plant block of `a` and `b`, `K`, and the Kalman gains `L` and
/// `M = 0.8 L`; the fifth state's dynamics and outputs are the caller's.
pub fn lqg_base() -> Design {
    let a4 = [
        [1.0, 0.01, 0.0, 0.0],
        [0.0, 0.98, 0.05, 0.0],
        [0.0, 0.0, 1.001, 0.01],
        [0.0, -0.03, 0.12, 0.999],
    ];
    let b4 = [0.0005, 0.09, -0.0004, -0.08];
    let mut d = Design {
        kind: Kind::Lqg,
        ts: 0.01,
        k: [-1.2, -0.9, 25.0, 2.1],
        input_bounds: [-12.0, 12.0],
        nx: N,
        ny: 2,
        ..Design::default()
    };
    for i in 0..4 {
        for j in 0..4 {
            d.a[i * N + j] = a4[i][j];
        }
        d.b[i] = b4[i];
    }
    d.a[4 * N + 4] = 1.0;
    let l = [
        [0.5, 0.01],
        [2.0, 0.1],
        [0.02, 0.6],
        [0.1, 3.0],
        [0.3, -0.2],
    ];
    for i in 0..N {
        for j in 0..2 {
            d.l[i * 2 + j] = l[i][j];
            d.m[i * 2 + j] = 0.8 * l[i][j];
        }
    }
    d
}

/// The device runs f32: `d` read from its bytes as `Design<f32>` keeps the moves within 1 mV of
/// f64 over 400 samples of `angles(t)` with the arm's reference at 0.5 rad (the regulators'
/// agreement in the crate docs). Returns the single-precision design.
pub fn single_precision_within_a_millivolt(
    d: &Design,
    angles: impl Fn(f64) -> [f64; 2],
) -> Design<f32> {
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    let single: Design<f32> = Design::from_bytes(&buf).unwrap();
    let mut c64 = Controller::new(d).unwrap();
    let mut c32 = Controller::new(&single).unwrap();
    for k in 0..400 {
        let y = angles(k as f64 * 0.01);
        let u64 = c64
            .step(Measurement {
                angles: y,
                reference: [0.5, 0.0],
            })
            .voltage;
        let u32 = c32
            .step(Measurement {
                angles: [y[0] as f32, y[1] as f32],
                reference: [0.5, 0.0],
            })
            .voltage;
        assert!((u64 - f64::from(u32)).abs() < 1e-3, "k={k}: {u64} {u32}");
    }
    single
}

/// The current-form Kalman filter written out densely, its law the caller's:
/// `e = y/s − C x̂⁻` (0 for a sample with non-finite angles, which is discarded),
/// `x̂[k|k] = x̂⁻ + M e`, `u = sat(law(x̂[k|k]))`, `x̂⁻ ← A x̂⁻ + B u + L e`.
pub struct DenseLqg {
    pub d: Design,
    pub prior: [f64; N],
}

impl DenseLqg {
    pub fn new(d: &Design) -> Self {
        Self {
            d: d.clone(),
            prior: [0.0; N],
        }
    }

    /// One sample of the angles `y`; the move.
    pub fn step(&mut self, y: [f64; 2], law: impl Fn(&Design, &[f64; N]) -> f64) -> f64 {
        let d = &self.d;
        let s = d.output_scales;
        let mut e = [0.0; 2];
        if y.iter().all(|v| v.is_finite()) {
            for i in 0..2 {
                e[i] = y[i] / s[i] - (0..N).map(|j| d.c[i * N + j] * self.prior[j]).sum::<f64>();
            }
        }
        let post: [f64; N] =
            std::array::from_fn(|i| self.prior[i] + d.m[i * 2] * e[0] + d.m[i * 2 + 1] * e[1]);
        let u = law(d, &post).clamp(d.input_bounds[0], d.input_bounds[1]);
        let mut next = [0.0; N];
        for i in 0..N {
            next[i] = (0..N).map(|j| d.a[i * N + j] * self.prior[j]).sum::<f64>()
                + d.b[i] * u
                + d.l[i * 2] * e[0]
                + d.l[i * 2 + 1] * e[1];
        }
        self.prior = next;
        u
    }
}

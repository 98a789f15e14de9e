//! LQG regulating the estimated outputs (`Design::regulates_outputs`): its moves against a
//! dense reimplementation of the current-form Kalman filter and of the law on the plant part
//! plus the output disturbance's share of each angle, and the flag in the byte layout.

// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use rip_control::{Controller, Design, DesignError, Kind, Measurement};

mod common;

use common::N;

/// The common LQG whose fifth state is one integrated output disturbance feeding both (scaled)
/// outputs with different weights, as the paper's eq. (1) does with equal ones, and output
/// scales that are not one.
fn design() -> Design {
    let scales = [2.0, 0.5];
    let mut d = Design {
        regulates_outputs: true,
        ..common::lqg_base()
    };
    // C on the scaled outputs: S_y⁻¹ C for the plant, then the disturbance's column.
    d.c[0] = 1.0 / scales[0];
    d.c[N + 2] = 1.0 / scales[1];
    d.c[4] = 1.0;
    d.c[N + 4] = 0.7;
    d.output_scales[..2].copy_from_slice(&scales);
    d
}

/// The filter and the law written out: `e = y/s − C x̂⁻` (0 for a sample with non-finite
/// angles, which is discarded), `x̂[k|k] = x̂⁻ + M e`, `ŷ_i = s_i (C x̂[k|k])_i` (the estimated
/// outputs, engineering units), `u = sat(−K ([ŷ_θ, x̂_1, ŷ_α, x̂_3] − x_ref))`,
/// `x̂⁻ ← A x̂⁻ + B u + L e`.
struct Dense {
    d: Design,
    prior: [f64; N],
}

impl Dense {
    fn step(&mut self, y: [f64; 2], r: f64) -> f64 {
        let d = &self.d;
        let s = d.output_scales;
        let mut e = [0.0; 2];
        if y.iter().all(|v| v.is_finite()) {
            for i in 0..2 {
                e[i] = y[i] / s[i] - (0..N).map(|j| d.c[i * N + j] * self.prior[j]).sum::<f64>();
            }
        }
        let post: Vec<f64> = (0..N)
            .map(|i| self.prior[i] + d.m[i * 2] * e[0] + d.m[i * 2 + 1] * e[1])
            .collect();
        let output = |i: usize| s[i] * (0..N).map(|j| d.c[i * N + j] * post[j]).sum::<f64>();
        let err = [output(0) - r, post[1], output(1), post[3]];
        let v = -(0..4).map(|j| d.k[j] * err[j]).sum::<f64>();
        let u = v.clamp(d.input_bounds[0], d.input_bounds[1]);
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

#[test]
fn the_law_regulates_the_estimated_outputs() {
    let d = design();
    let mut dense = Dense {
        d: d.clone(),
        prior: [0.0; N],
    };
    let mut c = Controller::new(&d).unwrap();
    let mut plain = Controller::new(&Design {
        regulates_outputs: false,
        ..d.clone()
    })
    .unwrap();
    let mut apart = 0.0f64;
    for k in 0..400 {
        let t = k as f64 * 0.01;
        // An offset on the arm that the output disturbance takes up, a sine on each angle, and
        // a few samples lost on the way.
        let y = if k % 97 == 50 {
            [f64::NAN, 0.0]
        } else {
            [0.1 + 0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()]
        };
        let r = if k > 200 { 0.5 } else { 0.0 };
        let m = Measurement {
            angles: y,
            reference: [r, 0.0],
        };
        let u = c.step(m).voltage;
        let want = dense.step(y, r);
        assert!((u - want).abs() < 1e-9, "k={k}: {u} {want}");
        apart = apart.max((plain.step(m).voltage - u).abs());
    }
    // The disturbance's share is not nothing: the paper's law moves differently.
    assert!(apart > 1e-3, "{apart}");
}

#[test]
fn the_law_runs_in_single_precision_within_a_millivolt() {
    // The device runs f32: the same design read as `Design<f32>` keeps the moves within 1 mV
    // of f64 over 400 samples (the regulators' agreement in the crate docs).
    let d = design();
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    let single: Design<f32> = Design::from_bytes(&buf).unwrap();
    assert!(single.regulates_outputs);
    let mut c64 = Controller::new(&d).unwrap();
    let mut c32 = Controller::new(&single).unwrap();
    for k in 0..400 {
        let t = k as f64 * 0.01;
        let y = [0.1 + 0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()];
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
}

#[test]
fn the_flag_travels_in_the_layout_and_only_with_lqg() {
    let d = design();
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    assert_eq!(buf[7], 2);
    let back: Design = Design::from_bytes(&buf).unwrap();
    assert!(back.regulates_outputs && !back.cancels_input_disturbance);
    assert_eq!(back, d);
    // An LQG with nothing beyond the plant's states, or whose fifth state is an input
    // disturbance its law cancels, has no output disturbance to add: refused, not ignored.
    let four = Design { nx: 4, ..d.clone() };
    let cancelling = Design {
        cancels_input_disturbance: true,
        ..d.clone()
    };
    for refused in [four, cancelling] {
        assert_eq!(
            refused.validate(),
            Err(DesignError::BadValue("regulates_outputs"))
        );
    }
    for kind in [Kind::Lqr, Kind::Mpc] {
        let other: Design = Design {
            kind,
            regulates_outputs: true,
            ..Design::default()
        };
        assert_eq!(
            other.validate(),
            Err(DesignError::BadValue("regulates_outputs")),
            "{kind:?}"
        );
    }
}

//! LQG regulating the estimated outputs (`Design::regulates_outputs`): its moves against a
//! dense reimplementation of the current-form Kalman filter and of the law on the plant part
//! plus the output disturbance's share of each angle, and the flag in the byte layout.

// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use rip_control::{Controller, Design, DesignError, Kind, Measurement};

const N: usize = 5;

/// An LQG design on a 4-state model augmented by one integrated output disturbance feeding
/// both (scaled) outputs with different weights, as the paper's eq. (1) does with equal ones;
/// made-up numbers (a stable model, small gains), output scales that are not one.
fn design() -> Design {
    let a4 = [
        [1.0, 0.01, 0.0, 0.0],
        [0.0, 0.98, 0.05, 0.0],
        [0.0, 0.0, 1.001, 0.01],
        [0.0, -0.03, 0.12, 0.999],
    ];
    let b4 = [0.0005, 0.09, -0.0004, -0.08];
    let scales = [2.0, 0.5];
    let mut d = Design {
        kind: Kind::Lqg,
        ts: 0.01,
        k: [-1.2, -0.9, 25.0, 2.1],
        input_bounds: [-12.0, 12.0],
        nx: N,
        ny: 2,
        regulates_outputs: true,
        ..Design::default()
    };
    for i in 0..4 {
        for j in 0..4 {
            d.a[i * N + j] = a4[i][j];
        }
        d.b[i] = b4[i];
    }
    d.a[4 * N + 4] = 1.0;
    // C on the scaled outputs: S_y⁻¹ C for the plant, then the disturbance's column.
    d.c[0] = 1.0 / scales[0];
    d.c[N + 2] = 1.0 / scales[1];
    d.c[4] = 1.0;
    d.c[N + 4] = 0.7;
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
    d.output_scales[..2].copy_from_slice(&scales);
    d
}

/// The filter and the law written out: `e = y/s − C x̂⁻`, `x̂[k|k] = x̂⁻ + M e`,
/// `ŷ_i = s_i (C x̂[k|k])_i` (the estimated outputs, engineering units),
/// `u = sat(−K ([ŷ_θ, x̂_1, ŷ_α, x̂_3] − x_ref))`, `x̂⁻ ← A x̂⁻ + B u + L e`.
struct Dense {
    d: Design,
    prior: [f64; N],
}

impl Dense {
    fn step(&mut self, y: [f64; 2], r: f64) -> f64 {
        let d = &self.d;
        let s = d.output_scales;
        let mut e = [0.0; 2];
        for i in 0..2 {
            e[i] = y[i] / s[i] - (0..N).map(|j| d.c[i * N + j] * self.prior[j]).sum::<f64>();
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
        // An offset on the arm that the output disturbance takes up, and a sine on each angle.
        let y = [0.1 + 0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()];
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
fn the_flag_travels_in_the_layout_and_only_with_lqg() {
    let d = design();
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    assert_eq!(buf[7], 2);
    let back: Design = Design::from_bytes(&buf).unwrap();
    assert!(back.regulates_outputs && !back.cancels_input_disturbance);
    assert_eq!(back, d);
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

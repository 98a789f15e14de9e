//! LQG regulating the estimated outputs (`Design::regulates_outputs`): its moves against a
//! dense reimplementation of the current-form Kalman filter and of the law on the plant part
//! plus the output disturbance's share of each angle, and the flag in the byte layout.

// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use rip_control::{Controller, Design, DesignError, Kind, Measurement};

mod common;

use common::{DenseLqg, N};

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

/// The law written out on the dense filter's `x̂[k|k]`: the estimated outputs
/// `ŷ_i = s_i (C x̂[k|k])_i` (engineering units) in place of the angles,
/// `u = −K ([ŷ_θ, x̂_1, ŷ_α, x̂_3] − x_ref)`.
fn on_outputs(d: &Design, post: &[f64; N], r: f64) -> f64 {
    let s = d.output_scales;
    let output = |i: usize| s[i] * (0..N).map(|j| d.c[i * N + j] * post[j]).sum::<f64>();
    let err = [output(0) - r, post[1], output(1), post[3]];
    -(0..4).map(|j| d.k[j] * err[j]).sum::<f64>()
}

#[test]
fn the_law_regulates_the_estimated_outputs() {
    let d = design();
    let mut dense = DenseLqg::new(&d);
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
        let want = dense.step(y, |d, post| on_outputs(d, post, r));
        assert!((u - want).abs() < 1e-9, "k={k}: {u} {want}");
        apart = apart.max((plain.step(m).voltage - u).abs());
    }
    // The disturbance's share is not nothing: the paper's law moves differently.
    assert!(apart > 1e-3, "{apart}");
}

#[test]
fn the_law_runs_in_single_precision_within_a_millivolt() {
    let single = common::single_precision_within_a_millivolt(&design(), |t| {
        [0.1 + 0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()]
    });
    assert!(single.regulates_outputs);
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

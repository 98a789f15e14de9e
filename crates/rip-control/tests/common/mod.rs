//! The made-up LQG both augmented-estimator tests start from.

// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use rip_control::{Design, Kind};

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

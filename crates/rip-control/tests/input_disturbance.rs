//! LQG and LQR cancelling an estimated input disturbance
//! (`Design::cancels_input_disturbance`): their moves against dense reimplementations of the
//! law, the current-form Kalman filter (LQG) and the rate filter with its disturbance observer
//! (LQR), and the flag in the byte layout.

// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use rip_control::{Controller, Design, DesignError, Kind, Measurement};

const N: usize = 5;

/// An LQG design on a 4-state model augmented by an input disturbance, with made-up numbers
/// (a stable model, small gains).
fn design() -> Design {
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
        cancels_input_disturbance: true,
        ..Design::default()
    };
    for i in 0..4 {
        for j in 0..4 {
            d.a[i * N + j] = a4[i][j];
        }
        d.a[i * N + 4] = b4[i];
        d.b[i] = b4[i];
    }
    d.a[4 * N + 4] = 1.0;
    d.c[0] = 1.0;
    d.c[N + 2] = 1.0;
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
    d.output_scales[..2].copy_from_slice(&[1.0, 1.0]);
    d
}

/// The law and the filter written out: `x̂[k|k] = x̂⁻ + M e`, `u = sat(−K (x̂ − r) − d̂)`,
/// `x̂⁻ ← A x̂⁻ + B u + L e`.
struct Dense {
    d: Design,
    prior: [f64; N],
}

impl Dense {
    fn step(&mut self, y: [f64; 2], r: f64) -> f64 {
        let d = &self.d;
        let mut e = [0.0; 2];
        for i in 0..2 {
            e[i] = y[i] - (0..N).map(|j| d.c[i * N + j] * self.prior[j]).sum::<f64>();
        }
        let post: Vec<f64> = (0..N)
            .map(|i| self.prior[i] + d.m[i * 2] * e[0] + d.m[i * 2 + 1] * e[1])
            .collect();
        let err = [post[0] - r, post[1], post[2], post[3]];
        let v = -(0..4).map(|j| d.k[j] * err[j]).sum::<f64>() - post[4];
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
fn the_law_cancels_the_estimated_input_disturbance() {
    let d = design();
    let mut c = Controller::new(&d).unwrap();
    let mut dense = Dense {
        d: d.clone(),
        prior: [0.0; N],
    };
    let mut plain = Controller::new(&Design {
        cancels_input_disturbance: false,
        ..d.clone()
    })
    .unwrap();
    let mut apart = 0.0f64;
    for k in 0..400 {
        let t = k as f64 * 0.01;
        let y = [0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()];
        let r = if k > 200 { 0.5 } else { 0.0 };
        let m = Measurement {
            angles: [y[0], y[1]],
            reference: [r, 0.0],
        };
        let u = c.step(m).voltage;
        let want = dense.step(y, r);
        assert!((u - want).abs() < 1e-9, "k={k}: {u} {want}");
        apart = apart.max((plain.step(m).voltage - u).abs());
    }
    // The estimate it cancels is not nothing: without the flag the moves differ.
    assert!(apart > 1e-3, "{apart}");
}

#[test]
fn the_flag_travels_in_the_layout_and_only_with_an_lqg_that_estimates_it() {
    let d = design();
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    assert_eq!(buf[7], 1);
    let back: Design = Design::from_bytes(&buf).unwrap();
    assert!(back.cancels_input_disturbance);
    // An unknown flag is refused, not ignored.
    buf[7] = 2;
    let n = buf.len();
    let crc = rip_control::crc32(&buf[..n - 4]);
    buf[n - 4..].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(
        Design::<f64>::from_bytes(&buf).map(|_| ()),
        Err(DesignError::BadValue("flags"))
    );
    // Without a fifth state, or on another controller, the flag is refused.
    let four = Design { nx: 4, ..d.clone() };
    assert_eq!(
        four.validate(),
        Err(DesignError::BadValue("cancels_input_disturbance"))
    );
    let lqr: Design = Design {
        kind: Kind::Lqr,
        cancels_input_disturbance: true,
        ..Design::default()
    };
    assert_eq!(
        lqr.validate(),
        Err(DesignError::BadValue("cancels_input_disturbance"))
    );
    let mpc = Design {
        kind: Kind::Mpc,
        ..d.clone()
    };
    assert_eq!(
        mpc.validate(),
        Err(DesignError::BadValue("cancels_input_disturbance"))
    );
}

/// An LQR with its input-disturbance observer on the 4-state model of [`design`].
fn lqr_design() -> Design {
    let lqg = design();
    let mut d = Design {
        kind: Kind::Lqr,
        ts: 0.01,
        k: lqg.k,
        input_bounds: [-12.0, 12.0],
        rate_cutoff_hz: 20.0,
        cancels_input_disturbance: true,
        nx: 4,
        ..Design::default()
    };
    let mut norm = 0.0;
    for i in 0..4 {
        for j in 0..4 {
            d.a[i * 4 + j] = lqg.a[i * N + j];
        }
        d.b[i] = lqg.b[i];
        norm += lqg.b[i] * lqg.b[i];
    }
    for i in 0..4 {
        d.disturbance_gain[i] = 0.2 * d.b[i] / norm;
    }
    d
}

/// The LQR law and observer written out densely (rip-core's `Lqr` docs): the rate filter,
/// `d̂ += g (x̂ − x̂⁻)`, `u = sat(−K (x̂ − x_ref) − d̂)`, `x̂⁻ = A x̂ + B (u + d̂)`.
struct DenseLqr {
    d: Design,
    prev: Option<[f64; 2]>,
    rates: [f64; 2],
    predicted: Option<[f64; 4]>,
    disturbance: f64,
}

impl DenseLqr {
    fn step(&mut self, y: [f64; 2], r: f64) -> f64 {
        let d = &self.d;
        let a = (-2.0 * std::f64::consts::PI * d.rate_cutoff_hz * d.ts).exp();
        if let Some(p) = self.prev {
            for i in 0..2 {
                self.rates[i] = a * self.rates[i] + (1.0 - a) * (y[i] - p[i]) / d.ts;
            }
        }
        self.prev = Some(y);
        let x = [y[0], self.rates[0], y[1], self.rates[1]];
        if let Some(p) = self.predicted {
            self.disturbance += (0..4)
                .map(|i| d.disturbance_gain[i] * (x[i] - p[i]))
                .sum::<f64>();
        }
        let err = [x[0] - r, x[1], x[2], x[3]];
        let v = -(0..4).map(|j| d.k[j] * err[j]).sum::<f64>() - self.disturbance;
        let u = v.clamp(d.input_bounds[0], d.input_bounds[1]);
        let mut next = [0.0; 4];
        for i in 0..4 {
            next[i] = (0..4).map(|j| d.a[i * 4 + j] * x[j]).sum::<f64>()
                + d.b[i] * (u + self.disturbance);
        }
        self.predicted = Some(next);
        u
    }
}

#[test]
fn the_lqr_cancels_the_disturbance_its_observer_estimates() {
    let d = lqr_design();
    let mut c = Controller::new(&d).unwrap();
    let mut dense = DenseLqr {
        d: d.clone(),
        prev: None,
        rates: [0.0; 2],
        predicted: None,
        disturbance: 0.0,
    };
    let mut plain = Controller::new(&Design {
        cancels_input_disturbance: false,
        ..d.clone()
    })
    .unwrap();
    let mut apart = 0.0f64;
    for k in 0..400 {
        let t = k as f64 * 0.01;
        let y = [0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()];
        let r = if k > 200 { 0.5 } else { 0.0 };
        let m = Measurement {
            angles: y,
            reference: [r, 0.0],
        };
        let u = c.step(m).voltage;
        let want = dense.step(y, r);
        assert!((u - want).abs() < 1e-9, "k={k}: {u} {want}");
        assert!((c.input_disturbance() - dense.disturbance).abs() < 1e-9);
        apart = apart.max((plain.step(m).voltage - u).abs());
    }
    assert!(apart > 1e-3, "{apart}");
    // The swing-up's moves are no disturbance: an observed sample clears the estimate.
    c.observe([0.1, 0.0], 3.0);
    assert_eq!(c.input_disturbance(), 0.0);
}

#[test]
fn the_lqr_observer_travels_in_the_layout() {
    let d = lqr_design();
    let mut buf = vec![0u8; d.encoded_len()];
    let n = d.to_bytes(&mut buf).unwrap();
    assert_eq!(buf[7], 1);
    // The paper's LQR and the model, the observer's gain.
    let plain = Design {
        cancels_input_disturbance: false,
        ..d.clone()
    };
    assert_eq!(n, plain.encoded_len() + 8 * (16 + 4 + 4));
    let back: Design = Design::from_bytes(&buf[..n]).unwrap();
    assert_eq!(back, d);
    let mut bad = d.clone();
    bad.disturbance_gain[2] = f64::NAN;
    assert_eq!(
        bad.validate(),
        Err(DesignError::BadValue("disturbance_gain"))
    );
}

//! LQG and LQR cancelling an estimated input disturbance
//! (`Design::cancels_input_disturbance`): their moves against dense reimplementations of the
//! law, the current-form Kalman filter (LQG) and the rate filter with its disturbance observer
//! (LQR), and the flag in the byte layout.

// Dense row-major numerics index several arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

use rip_control::{Controller, Design, DesignError, Kind, Measurement};

mod common;

use common::{DenseLqg, N};

/// The common LQG whose fifth state is a disturbance at the plant input, `x[k+1] = A x +
/// B (u + d)`, measured through the angles alone.
fn design() -> Design {
    let mut d = Design {
        cancels_input_disturbance: true,
        ..common::lqg_base()
    };
    for i in 0..4 {
        d.a[i * N + 4] = d.b[i];
    }
    d.c[0] = 1.0;
    d.c[N + 2] = 1.0;
    d.output_scales[..2].copy_from_slice(&[1.0, 1.0]);
    d
}

/// The law written out on the dense filter's `x̂[k|k]`: `u = −K (x̂ − r) − d̂`.
fn cancelling(d: &Design, post: &[f64; N], r: f64) -> f64 {
    let err = [post[0] - r, post[1], post[2], post[3]];
    -(0..4).map(|j| d.k[j] * err[j]).sum::<f64>() - post[4]
}

/// Steps the device's controller of `d` and `dense` (which returns its move and, where it
/// has one, the disturbance it cancels) on the same 400 samples, a sine on each angle and a
/// reference step at 2 s: they agree to 1e-9, and the same design without the flag moves
/// differently (the estimate it cancels is not nothing). Returns the device's controller.
fn agrees_with_dense(
    d: &Design,
    mut dense: impl FnMut([f64; 2], f64) -> (f64, Option<f64>),
) -> Controller {
    let mut c = Controller::new(d).unwrap();
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
        let (want, disturbance) = dense(y, r);
        assert!((u - want).abs() < 1e-9, "k={k}: {u} {want}");
        if let Some(d) = disturbance {
            assert!((c.input_disturbance() - d).abs() < 1e-9, "k={k}");
        }
        apart = apart.max((plain.step(m).voltage - u).abs());
    }
    assert!(apart > 1e-3, "{apart}");
    c
}

#[test]
fn the_law_cancels_the_estimated_input_disturbance() {
    let d = design();
    let mut dense = DenseLqg::new(&d);
    agrees_with_dense(&d, |y, r| {
        (dense.step(y, |d, post| cancelling(d, post, r)), None)
    });
}

#[test]
fn the_flag_travels_in_the_layout_and_only_with_a_regulator_that_estimates_it() {
    let d = design();
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    assert_eq!(buf[7], 1);
    let back: Design = Design::from_bytes(&buf).unwrap();
    assert!(back.cancels_input_disturbance);
    // An unknown flag is refused, not ignored.
    buf[7] = 4;
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

/// The LQR law and observer written out densely (rip-core's `Lqr` docs): the rate filter
/// (spanning held periods), `d̂ += g (x̂ − x̂⁻)`, `u = sat(−K (x̂ − x_ref) − d̂)`,
/// `x̂⁻ = A x̂ + B (u + d̂)`; a held period advances `x̂⁻`, a seed clears `d̂`.
struct DenseLqr {
    d: Design,
    prev: Option<[f64; 2]>,
    held: i32,
    rates: [f64; 2],
    x: [f64; 4],
    predicted: Option<[f64; 4]>,
    disturbance: f64,
}

impl DenseLqr {
    fn new(d: &Design) -> Self {
        Self {
            d: d.clone(),
            prev: None,
            held: 0,
            rates: [0.0; 2],
            x: [0.0; 4],
            predicted: None,
            disturbance: 0.0,
        }
    }

    fn predict(&self, x: [f64; 4], u: f64) -> [f64; 4] {
        let d = &self.d;
        std::array::from_fn(|i| {
            (0..4).map(|j| d.a[i * 4 + j] * x[j]).sum::<f64>() + d.b[i] * (u + self.disturbance)
        })
    }

    fn law(&self, r: f64) -> f64 {
        let (d, x) = (&self.d, self.x);
        let err = [x[0] - r, x[1], x[2], x[3]];
        let v = -(0..4).map(|j| d.k[j] * err[j]).sum::<f64>() - self.disturbance;
        v.clamp(d.input_bounds[0], d.input_bounds[1])
    }

    fn step(&mut self, y: [f64; 2], r: f64) -> f64 {
        let d = &self.d;
        let n = self.held + 1;
        let an = (-2.0 * std::f64::consts::PI * d.rate_cutoff_hz * d.ts * f64::from(n)).exp();
        if let Some(p) = self.prev {
            for i in 0..2 {
                self.rates[i] =
                    an * self.rates[i] + (1.0 - an) * (y[i] - p[i]) / (f64::from(n) * d.ts);
            }
        }
        self.prev = Some(y);
        self.held = 0;
        self.x = [y[0], self.rates[0], y[1], self.rates[1]];
        if let Some(p) = self.predicted {
            self.disturbance += (0..4)
                .map(|i| d.disturbance_gain[i] * (self.x[i] - p[i]))
                .sum::<f64>();
        }
        let u = self.law(r);
        self.predicted = Some(self.predict(self.x, u));
        u
    }

    /// A period whose sample was unusable: the law on the kept `x̂`, the period held.
    fn invalid(&mut self, r: f64) -> f64 {
        let u = self.law(r);
        self.hold(u);
        u
    }

    fn hold(&mut self, u: f64) {
        self.held += 1;
        self.predicted = self.predicted.map(|p| self.predict(p, u));
    }

    fn seed(&mut self, x: [f64; 4], u: f64) {
        self.disturbance = 0.0;
        if !x.iter().all(|v| v.is_finite()) {
            self.hold(u);
            return;
        }
        self.prev = Some([x[0], x[2]]);
        self.held = 0;
        self.rates = [x[1], x[3]];
        self.x = x;
        self.predicted = Some(self.predict(x, u));
    }
}

#[test]
fn the_lqr_cancels_the_disturbance_its_observer_estimates() {
    let d = lqr_design();
    let mut dense = DenseLqr::new(&d);
    let mut c = agrees_with_dense(&d, |y, r| {
        let u = dense.step(y, r);
        (u, Some(dense.disturbance))
    });
    // The swing-up's moves are no disturbance: an observed sample clears the estimate.
    c.observe([0.1, 0.0], 3.0);
    assert_eq!(c.input_disturbance(), 0.0);
}

#[test]
fn the_lqr_observer_agrees_through_held_unusable_and_seeded_periods() {
    let d = lqr_design();
    let mut c = Controller::new(&d).unwrap();
    let mut dense = DenseLqr::new(&d);
    for k in 0..300 {
        let t = k as f64 * 0.01;
        let y = [0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()];
        let m = Measurement {
            angles: y,
            reference: [0.3, 0.0],
        };
        let (u, want) = match k {
            // Two held periods: the written voltage goes on, no sample.
            60 | 61 => {
                c.hold(1.5);
                dense.hold(1.5);
                continue;
            }
            // An unusable sample.
            90 => {
                let bad = Measurement {
                    angles: [f64::NAN, y[1]],
                    ..m
                };
                (c.step(bad).voltage, dense.invalid(0.3))
            }
            // A handover, and one with a state that cannot be used.
            150 => {
                let x = [y[0], 0.1, y[1], -0.2];
                c.seed(x, 2.0);
                dense.seed(x, 2.0);
                assert_eq!(c.input_disturbance(), 0.0);
                continue;
            }
            200 => {
                c.seed([f64::NAN, 0.0, 0.0, 0.0], -1.0);
                dense.seed([f64::NAN, 0.0, 0.0, 0.0], -1.0);
                assert_eq!(c.input_disturbance(), 0.0);
                continue;
            }
            _ => (c.step(m).voltage, dense.step(y, 0.3)),
        };
        assert!((u - want).abs() < 1e-9, "k={k}: {u} {want}");
        assert!(
            (c.input_disturbance() - dense.disturbance).abs() < 1e-9,
            "k={k}"
        );
    }
}

#[test]
fn the_lqr_runs_its_observer_in_single_precision_within_a_millivolt() {
    common::single_precision_within_a_millivolt(&lqr_design(), |t| {
        [0.2 * (1.3 * t).sin(), 0.01 * (7.0 * t).cos()]
    });
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
    // The flag and the body must agree: the paper's LQR's bytes with the flag set end before
    // the observer's fields, the observer's bytes with it cleared run past the LQR's.
    let with_crc = |mut b: Vec<u8>| {
        let n = b.len();
        let crc = rip_control::crc32(&b[..n - 4]);
        b[n - 4..].copy_from_slice(&crc.to_le_bytes());
        b
    };
    let mut short = vec![0u8; plain.encoded_len()];
    plain.to_bytes(&mut short).unwrap();
    short[7] = 1;
    assert_eq!(
        Design::<f64>::from_bytes(&with_crc(short)).map(|_| ()),
        Err(DesignError::Truncated)
    );
    let mut long = buf[..n].to_vec();
    long[7] = 0;
    assert_eq!(
        Design::<f64>::from_bytes(&with_crc(long)).map(|_| ()),
        Err(DesignError::LengthMismatch)
    );
}

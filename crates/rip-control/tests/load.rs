//! A controller loaded in place from a design's bytes (`Controller::load`, what the firmware
//! does in its static) against one built from the decoded design (`Controller::new`), and the
//! step budget a device holds a design to (`Design::check_step_budget`).

use rip_control::{Controller, Design, DesignError, Kind, Measurement};

/// A deterministic sequence in [−1, 1).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// An MPC design of the paper's sizes (5 states, 2 outputs, P = 50, m = 3: 6 input rows,
/// 100 soft rows, 107 in all) with made-up numbers: a stable model, a diagonally dominant
/// Hessian.
fn mpc(ts: f64, max_iterations: u32, seed: u64) -> Design {
    let mut r = Lcg(seed);
    let (n, ny, m, p) = (5, 2, 3, 50);
    let nz = m + 1;
    let mut d = Design {
        kind: Kind::Mpc,
        ts,
        k: [-1.0, -1.5, 30.0, 3.0],
        nx: n,
        ny,
        horizon: p,
        control_horizon: m,
        n_input_rows: 2 * m,
        n_soft_rows: 2 * p,
        ncon: 2 * m + 2 * p + 1,
        max_iterations,
        ..Design::default()
    };
    for i in 0..n {
        for j in 0..n {
            d.a[i * n + j] = if i == j { 0.9 } else { 0.02 * r.next() };
        }
        d.b[i] = 0.1 * r.next();
        for o in 0..ny {
            d.c[o * n + i] = r.next();
            d.l[i * ny + o] = 0.1 * r.next();
            d.m[i * ny + o] = 0.1 * r.next();
        }
    }
    for i in 0..nz {
        for j in i..nz {
            let v = if i == j { 4.0 } else { 0.3 * r.next().abs() };
            d.h[i * nz + j] = v;
            d.h[j * nz + i] = v;
        }
    }
    for v in d.f0[..nz].iter_mut().chain(&mut d.fu[..nz]) {
        *v = r.next();
    }
    for v in d.fx[..nz * n].iter_mut().chain(&mut d.fr[..nz * ny]) {
        *v = 10.0 * r.next();
    }
    let ncon = d.ncon;
    for v in d.ac[..ncon * nz].iter_mut().chain(&mut d.bx[..ncon * n]) {
        *v = r.next();
    }
    for (b0, bu) in d.b0[..ncon].iter_mut().zip(&mut d.bu[..ncon]) {
        *b0 = 0.05 + 0.1 * r.next().abs();
        *bu = 0.1 * r.next();
    }
    d
}

fn lqr() -> Design {
    Design {
        kind: Kind::Lqr,
        ts: 0.001,
        k: [-3.2, -1.9, 42.0, 4.1],
        rate_cutoff_hz: 25.0,
        ..Design::default()
    }
}

fn bytes(d: &Design) -> Vec<u8> {
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    buf
}

/// The moves of `c` over a fixed sequence of measurements, as bits.
fn moves(c: &mut Controller, seed: u64) -> Vec<u64> {
    let mut r = Lcg(seed);
    (0..300)
        .map(|k| {
            let m = Measurement {
                angles: [0.3 * r.next(), 0.05 * r.next()],
                reference: [if k > 100 { 1.0 } else { 0.0 }, 0.0],
            };
            c.step(m).voltage.to_bits()
        })
        .collect()
}

#[test]
fn a_controller_loaded_in_place_runs_as_one_built_from_the_decoded_design() {
    let (first, second) = (mpc(0.001, 5, 1), mpc(0.01, 8, 2));
    let mut loaded = Box::new(Controller::<f64>::unloaded());
    // Each load replaces what the previous one left, whatever its kind.
    for d in [&first, &lqr(), &second, &lqr(), &first] {
        loaded.load(&bytes(d)).unwrap();
        let decoded = Design::from_bytes(&bytes(d)).unwrap();
        let mut built = Box::new(Controller::new(&decoded).unwrap());
        assert_eq!(loaded.design(), built.design(), "{:?}", d.kind);
        assert_eq!(moves(&mut loaded, 9), moves(&mut built, 9), "{:?}", d.kind);
        assert_eq!(loaded.stats(), built.stats());
        if d.kind == Kind::Mpc {
            // The constrained solve ran: some step needed an active row.
            assert!(loaded.stats().max_iterations >= 1, "{:?}", loaded.stats());
            assert_eq!(loaded.qp_solution().len(), d.nz());
        } else {
            assert!(loaded.qp_solution().is_empty());
        }
    }
}

#[test]
fn a_load_that_fails_leaves_a_controller_that_loads_again() {
    let good = mpc(0.001, 5, 3);
    let mut c = Box::new(Controller::<f64>::unloaded());
    let mut bad = bytes(&good);
    let last = bad.len() - 5;
    bad[last] ^= 1;
    assert_eq!(c.load(&bad), Err(DesignError::BadChecksum));
    c.load(&bytes(&good)).unwrap();
    let mut built = Box::new(Controller::new(&good).unwrap());
    assert_eq!(moves(&mut c, 4), moves(&mut built, 4));
}

#[test]
fn the_step_budget_is_half_the_period_at_168_mhz_and_two_cycles_per_instruction() {
    // 168e6 Hz / 2 cycles per instruction / 2 (half the period) = 42 instructions per µs.
    // The documented model N(I) = 2 400 + 8 ncon (n + 1) + 12.5 ncon nz (I + 1), here
    // n = 5, ncon = 107, nz = 4: 7 536 + 5 350 (I + 1).
    let model = |i: u64| 7_536 + 5_350 * (i + 1);
    let at_1khz = mpc(0.001, 5, 5);
    assert_eq!(at_1khz.step_budget_instructions(), 42_000);
    assert_eq!(at_1khz.worst_step_instructions(), model(5));
    assert_eq!(at_1khz.check_step_budget(), Ok(()));
    assert_eq!(at_1khz.fitting_iterations(), 5);
    let over = mpc(0.001, 6, 5);
    assert_eq!(
        over.check_step_budget(),
        Err(DesignError::OverBudget {
            instructions: model(6),
            budget: 42_000
        })
    );
    // 100 Hz: 420 000 instructions, the last I with 7 536 + 5 350 (I + 1) within them is 76.
    let at_100hz = mpc(0.01, 76, 5);
    assert_eq!(at_100hz.fitting_iterations(), 76);
    assert_eq!(at_100hz.check_step_budget(), Ok(()));
    assert!(mpc(0.01, 77, 5).check_step_budget().is_err());
    assert!(mpc(0.01, 200, 5).check_step_budget().is_err());
    // A regulator fits any period the device runs.
    assert_eq!(lqr().check_step_budget(), Ok(()));
}

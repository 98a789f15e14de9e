//! rip-control, the one run-time implementation, against independent references: the MPC's
//! dual active-set QP against Clarabel and against the dense primal active set rip-core used
//! before (`primal/`), on closed-loop simulations of both presets, and the bytes a
//! design travels in.

mod primal;

use nalgebra::DVector;
use rand::{rngs::StdRng, Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rip_control::{Controller as Step, Measurement, Status};
type CDesign = rip_control::Design<f64>;
use rip_core::mpc::{QpSolver, QpStatus};
use rip_core::spec::{ControllerKind, Spec};

fn specs() -> Vec<(&'static str, Spec)> {
    vec![
        ("paper", Spec::default()),
        (
            "qube_servo2",
            Spec::parse("[plant]\npreset = 'qube_servo2'\n").unwrap(),
        ),
    ]
}

struct QpStats {
    qps: usize,
    worst_vs_active_set: f64,
    worst_vs_clarabel: f64,
    max_iterations: u32,
    active_soft: usize,
    saturated: usize,
    restarts: usize,
    /// Solves where a reference did not report success (not compared).
    reference_failures: usize,
    /// Clarabel's reduced-accuracy solutions among them.
    clarabel_almost: usize,
    /// The largest relative excess of the onboard cost over the better reference's.
    worst_cost_excess: f64,
}

/// A closed loop on the nonlinear plant driven by the onboard MPC, through the 0 → 1 rad arm
/// step with sensor noise and random torque kicks; at every step rip-core solves the same QP
/// (the onboard estimate and previous move) with Clarabel and with the primal active set.
fn mpc_loop(spec: &Spec, seed: u64, steps: usize, stats: &mut QpStats) {
    let design = spec.design(0.01).unwrap();
    let mut cl_spec = spec.clone();
    cl_spec.mpc.solver = QpSolver::Clarabel;
    let mut clarabel = cl_spec.design(0.01).unwrap().mpc().unwrap();
    let cdesign = design.mpc().unwrap().control_design().unwrap();
    let nx = clarabel.n_states();
    let (h0, _, a0, _) = clarabel
        .qp_matrices(&vec![0.0; nx], &[0.0], &[0.0, 0.0])
        .unwrap();
    let mut primal = primal::ActiveSetSolver::new(&h0, &a0, Some(h0.nrows() - 1), 200).unwrap();
    let (lo, hi) = (clarabel.input_bounds().0[0], clarabel.input_bounds().1[0]);
    let m = clarabel.control_horizon();
    let mut onboard = Step::new(&cdesign).unwrap();
    let plant = spec.plant().unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 5e-4).unwrap();
    let start = |rng: &mut StdRng| {
        rip_core::plant::State::new(0.0, 0.0, rng.gen_range(-0.6..0.6), rng.gen_range(-1.0..1.0))
    };
    let mut x = start(&mut rng);
    let mut kick = 0.0;
    for k in 0..steps {
        let r = [if k % 600 < 300 { 0.0 } else { 1.0 }, 0.0];
        let y = [x[0] + noise.sample(&mut rng), x[2] + noise.sample(&mut rng)];
        let u_prev = onboard.last_input();
        let mv = onboard.step(Measurement {
            angles: y,
            reference: r,
        });
        assert_eq!(mv.status, Status::Nominal, "seed {seed} k={k}");
        let xhat = onboard.estimate().to_vec();
        let (h, f, ac, b) = clarabel.qp_matrices(&xhat, &[u_prev], &r).unwrap();
        let out = primal.solve(&f, &b, |z| {
            primal::project_inputs(z, &[u_prev], &[lo], &[hi], m)
        });
        // Its plan clamped to the bounds, as the controller applies it (the solver's hard
        // rows hold to its feasibility tolerance only).
        let mut z_primal = primal.solution().clone();
        let (mut acc, mut prev) = (u_prev, u_prev);
        for j in 0..m {
            acc += primal.solution()[j];
            let v = acc.clamp(lo, hi);
            z_primal[j] = v - prev;
            prev = v;
        }
        let a = (u_prev + z_primal[0]).clamp(lo, hi);
        let c = clarabel.solve(&xhat, &[u_prev], &r).unwrap().u[0];
        let a_ok = out.status == rip_core::mpc::QpStatus::Solved;
        let c_ok = clarabel.last_solution().status == rip_core::mpc::QpStatus::Solved;
        stats.reference_failures += usize::from(!a_ok) + usize::from(!c_ok);
        stats.clarabel_almost +=
            usize::from(clarabel.last_solution().status == rip_core::mpc::QpStatus::AlmostSolved);
        // The arbiter where they differ: feasibility and cost on the QP itself.
        let z_of = |sol: &rip_core::mpc::MpcSolution| {
            let mut z = DVector::zeros(h.nrows());
            let nd = h.nrows() - 1;
            z.rows_mut(0, nd).copy_from(&sol.du);
            z[0] = sol.u[0] - u_prev;
            z[nd] = sol.slack;
            z
        };
        let z_on = DVector::from_column_slice(onboard.qp_solution());
        // Each plan's cost with its optimal slack for its moves (the largest soft violation),
        // so that a reference's tolerance in ε does not count as a better plan.
        let (n_input, n_soft) = clarabel.constraint_layout();
        let cost = |z: &DVector<f64>| {
            let mut z = z.clone();
            let nd = z.len() - 1;
            z[nd] = 0.0;
            let az = &ac * &z - &b;
            z[nd] = (n_input..n_input + n_soft).fold(0.0f64, |e, i| e.max(az[i]));
            0.5 * z.dot(&(&h * &z)) + f.dot(&z)
        };
        let viol = (&ac * &z_on - &b).max();
        assert!(
            viol <= 1e-9 * (1.0 + b.amax()),
            "k={k}: infeasible by {viol:e}"
        );
        let mut best = f64::INFINITY;
        if a_ok {
            best = best.min(cost(&z_primal));
            stats.worst_vs_active_set = stats.worst_vs_active_set.max((mv.planned - a).abs());
        }
        if c_ok {
            best = best.min(cost(&z_of(clarabel.last_solution())));
            stats.worst_vs_clarabel = stats.worst_vs_clarabel.max((mv.planned - c).abs());
        }
        let c_on = cost(&z_on);
        stats.worst_cost_excess = stats
            .worst_cost_excess
            .max((c_on - best) / best.abs().max(1.0));
        stats.qps += 1;
        stats.max_iterations = stats.max_iterations.max(mv.iterations);
        stats.saturated += usize::from(mv.planned.abs() > 12.0 - 1e-9);
        stats.active_soft += usize::from(onboard.qp_solution()[m] > 1e-9);
        if k % 150 == 0 {
            kick = rng.gen_range(-0.03..0.03);
        } else if k % 150 == 10 {
            kick = 0.0;
        }
        for _ in 0..10 {
            plant.rk4_step(&mut x, mv.voltage, kick, 0.001);
        }
        if x[2].abs() > 1.0 {
            // The QPs are the subject, not the balance: start again from a new tilt.
            stats.restarts += 1;
            x = start(&mut rng);
            onboard.reset();
        }
    }
}

#[test]
fn the_dual_active_set_mpc_agrees_with_clarabel_on_ten_thousand_qps() {
    for (name, spec) in specs() {
        let mut s = QpStats {
            qps: 0,
            worst_vs_active_set: 0.0,
            worst_vs_clarabel: 0.0,
            max_iterations: 0,
            active_soft: 0,
            saturated: 0,
            restarts: 0,
            reference_failures: 0,
            clarabel_almost: 0,
            worst_cost_excess: f64::NEG_INFINITY,
        };
        for seed in 0..5 {
            mpc_loop(&spec, seed, 1200, &mut s);
        }
        eprintln!(
            "{name}: {} QPs, worst |Δu| vs active set {:e} V, vs Clarabel {:e} V, \
             max iterations {}, soft bound active {}, saturated {}, restarts {}, cost excess {:e}, reference failures {} (Clarabel almost-solved {})",
            s.qps, s.worst_vs_active_set, s.worst_vs_clarabel, s.max_iterations, s.active_soft, s.saturated, s.restarts, s.worst_cost_excess, s.reference_failures, s.clarabel_almost
        );
        assert!(s.qps >= 6000);
        assert!(
            s.saturated > 0 && s.active_soft > 0,
            "{name}: constraints never active"
        );
        // The decisive check: no onboard solution costs more than the better reference's, to
        // round-off. The moves then differ only along directions the cost hardly weighs (the
        // slack's, at ρ_ε = 100 beside output terms of 10⁴): by the primal active set's
        // feasibility tolerance 1e-9 (1 + |b|) and by Clarabel's interior-point accuracy.
        assert!(
            s.worst_cost_excess < 1e-10,
            "{name}: cost excess {:e}",
            s.worst_cost_excess
        );
        assert!(
            s.worst_vs_active_set < 1e-6,
            "{name}: {:e}",
            s.worst_vs_active_set
        );
        assert!(
            s.worst_vs_clarabel < 1e-5,
            "{name}: {:e}",
            s.worst_vs_clarabel
        );
    }
}

#[test]
fn a_design_travels_in_bytes_unchanged_and_corruption_is_refused() {
    let spec = Spec::default();
    let design = spec.design(0.01).unwrap();
    // LQG regulating its estimated outputs: the flag the device runs the law by travels too.
    let regulating = Spec::parse("[kalman]\nregulate_outputs = true\n")
        .unwrap()
        .design(0.01)
        .unwrap()
        .lqg()
        .unwrap()
        .control_design()
        .unwrap();
    assert!(regulating.regulates_outputs);
    let designs: Vec<CDesign> = vec![
        design.lqr().unwrap().control_design(),
        design.lqg().unwrap().control_design().unwrap(),
        design.mpc().unwrap().control_design().unwrap(),
        regulating,
    ];
    let mut buf = vec![0u8; 20_000];
    for d in &designs {
        let n = d.to_bytes(&mut buf).unwrap();
        assert_eq!(n, d.encoded_len());
        let back = CDesign::from_bytes(&buf[..n]).unwrap();
        assert_eq!(&back, d, "{:?}", d.kind);
        eprintln!("{}: {n} bytes", d.kind.name());
        // Every single-bit flip is refused (CRC-32 detects all of them).
        for i in (0..n).step_by(7) {
            buf[i] ^= 0x10;
            assert!(CDesign::from_bytes(&buf[..n]).is_err(), "flip at {i}");
            buf[i] ^= 0x10;
        }
        assert!(CDesign::from_bytes(&buf[..n - 1]).is_err());
        assert!(matches!(
            d.to_bytes(&mut buf[..n - 1]),
            Err(rip_control::DesignError::BufferTooSmall { needed }) if needed == n
        ));
    }
    assert_eq!(rip_control::crc32(b"123456789"), 0xCBF4_3926);
}

#[test]
fn at_the_iteration_bound_the_fallback_is_the_clamped_unconstrained_move_and_is_counted() {
    let mpc = Spec::default().design(0.01).unwrap().mpc().unwrap();
    let mut d = mpc.control_design().unwrap();
    d.max_iterations = 1;
    let mut onboard = Step::new(&d).unwrap();
    let mut limited = 0;
    for k in 0..50 {
        // A large tilt: the soft bound and the voltage bound are active, so one iteration
        // cannot finish.
        let y = [0.0, if k < 5 { 0.45 } else { 0.0 }];
        let u_prev = onboard.last_input();
        let mv = onboard.step(Measurement {
            angles: y,
            reference: [0.0, 0.0],
        });
        assert!(mv.voltage.is_finite() && mv.voltage.abs() <= 12.0);
        if mv.status != Status::IterationLimit {
            continue;
        }
        limited += 1;
        let (h, f, _, _) = mpc
            .qp_matrices(onboard.estimate(), &[u_prev], &[0.0, 0.0])
            .unwrap();
        let z = -h.cholesky().unwrap().solve(&f);
        let want = (u_prev + z[0]).clamp(-12.0, 12.0);
        assert!(
            (mv.voltage - want).abs() < 1e-9,
            "k={k}: {} vs {want}",
            mv.voltage
        );
    }
    assert!(limited > 0);
    assert_eq!(onboard.stats().iteration_limits, limited);
}

/// The design rounded to `f32` by the bytes it travels in, as a single-precision device reads it.
fn in_f32(d: &CDesign) -> rip_control::Design<f32> {
    let mut buf = vec![0u8; d.encoded_len()];
    d.to_bytes(&mut buf).unwrap();
    rip_control::Design::<f32>::from_bytes(&buf).unwrap()
}

/// The measurement behind the number format: each controller in `f32` follows the same
/// measurements as in `f64` over a 15 s nonlinear loop (0 → 1 rad step). The LQRs stay within
/// 30–60 µV; the estimators drift (paper LQG 12 V, MPC 17 V and 8 V apart by the end: the
/// slow Kalman error modes integrate `f32` round-off), so the device runs `f64`, where the moves
/// are the host's bit for bit. Should a better-conditioned `f32` form ever pass, this test
/// says so and the choice is to be revisited.
#[test]
fn single_precision_meets_one_millivolt_for_the_lqr_but_not_for_the_mpc() {
    let mut results = Vec::new();
    for (name, spec) in specs() {
        let design = spec.design(0.01).unwrap();
        let designs = [
            design.lqr().unwrap().control_design(),
            design.lqg().unwrap().control_design().unwrap(),
            design.mpc().unwrap().control_design().unwrap(),
        ];
        let plant = spec.plant().unwrap();
        for d in &designs {
            let mut c64 = Step::new(d).unwrap();
            let mut c32 = Step::new(&in_f32(d)).unwrap();
            let mut rng = StdRng::seed_from_u64(3);
            let noise = Normal::new(0.0, 5e-4).unwrap();
            let mut x = rip_core::plant::State::new(0.0, 0.0, 0.1, 0.0);
            let mut worst = 0.0f64;
            for k in 0..1500 {
                let r = [if k < 300 { 0.0 } else { 1.0 }, 0.0];
                let y = [x[0] + noise.sample(&mut rng), x[2] + noise.sample(&mut rng)];
                let m64 = c64.step(Measurement {
                    angles: y,
                    reference: r,
                });
                // The f32 controller's own estimate runs on: the comparison is of the two
                // arithmetics over a whole run, not of one step from a shared state.
                #[allow(clippy::cast_possible_truncation)]
                let m32 = c32.step(Measurement {
                    angles: y.map(|v| v as f32),
                    reference: r.map(|v| v as f32),
                });
                let diff = (m64.voltage - f64::from(m32.voltage)).abs();
                worst = worst.max(diff);
                for _ in 0..10 {
                    plant.rk4_step(&mut x, m64.voltage, 0.0, 0.001);
                }
            }
            eprintln!(
                "{name} {}: worst |u_f64 − u_f32| = {worst:e} V",
                d.kind.name()
            );
            results.push((name, d.kind, worst));
        }
    }
    for &(name, kind, worst) in &results {
        match kind {
            rip_control::Kind::Lqr => assert!(worst < 1e-3, "{name} LQR in f32: {worst:e} V"),
            rip_control::Kind::Mpc => assert!(worst > 1e-3, "{name} MPC in f32 now agrees"),
            rip_control::Kind::Lqg => {}
        }
    }
}

/// What the controllers are asked to do at a sample of [`mpcs_on_one_run`].
#[derive(Clone, Copy, PartialEq)]
enum Act {
    Step,
    Hold,
    /// Someone else's input (a supervisor's), then a restart from the true state.
    Observe,
    Seed,
}

/// The schedule of sample `k`: mostly steps, a missed sample every 97, and every 400 samples
/// a 10-sample stretch of an outside input ended by a seed, as a swing-up hands over.
fn act(k: usize) -> Act {
    match k % 400 {
        200..=209 => Act::Observe,
        210 => Act::Seed,
        _ if k % 97 == 50 => Act::Hold,
        _ => Act::Step,
    }
}

/// Worst move differences (V) and counts of [`mpcs_on_one_run`].
#[derive(Default)]
struct Agreement {
    /// Over the moves Clarabel solved to full accuracy.
    vs_clarabel: f64,
    vs_general_active_set: f64,
    moves: usize,
    saturated: usize,
    /// Moves Clarabel solved to full accuracy, and the saturated ones among them.
    solved: usize,
    solved_saturated: usize,
}

/// The assembly's run-time MPC (rip-control's controller, the device's code) in a closed loop
/// on the nonlinear plant through arm steps, sensor noise and torque kicks (up to `kicks`
/// N·m), with held, observed and seeded samples and the spec's compensation between the move
/// and the plant, against rip-core's general `Mpc` (its own estimator step and move
/// assembly) on the same samples:
///
/// - with Clarabel, an independent interior-point solver: its estimator takes every sample
///   with the input the loop applied, and each move is its own solve from its own estimate
///   (compared where Clarabel reports full accuracy).
///   Fed its own moves instead, a solver's 1e-9 would grow along the controller's own
///   dynamics (`A − L C − B K` is not stable for a balancing controller); run in a loop of
///   its own, the plant's Coulomb friction (stick or slip) would part the two loops;
/// - with the active set, as a `Controller` taking its own moves: the same QP solver, so any
///   difference is in the estimator, the hold, observe and seed, or the move.
fn mpcs_on_one_run(spec: &Spec, kicks: f64, seed: u64, steps: usize, out: &mut Agreement) {
    use rip_core::{Controller, StepStatus};
    let design = spec.design(0.01).unwrap();
    let mut general = design.mpc().unwrap();
    assert!(
        general.run_time_controller().is_some(),
        "the default MPC runs on rip-control"
    );
    let mut cl_spec = spec.clone();
    cl_spec.mpc.solver = QpSolver::Clarabel;
    // Its default bound stops a few of these solves short of full accuracy.
    cl_spec.mpc.max_iterations = 2000;
    let mut clarabel = cl_spec.design(0.01).unwrap().mpc().unwrap();
    assert!(clarabel.run_time_controller().is_none());
    let mut run_time = design.balance(ControllerKind::Mpc).unwrap();
    let law = design.compensation().copied();
    let limit = design.bounds().1;
    let plant = spec.plant().unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 1e-3).unwrap();
    let mut x = rip_core::plant::State::new(0.0, 0.0, 0.05, 0.0);
    let (mut u, mut v) = ([0.0], [0.0]);
    let mut kick = 0.0;
    for k in 0..steps {
        let r = [if (k / 300) % 2 == 0 { 0.0 } else { 1.0 }, 0.0];
        let y = [x[0] + noise.sample(&mut rng), x[2] + noise.sample(&mut rng)];
        match act(k) {
            Act::Step => {
                let u_prev = u;
                assert_eq!(run_time.step(&y, &r, &mut u), StepStatus::Nominal, "k={k}");
                assert_eq!(general.step(&y, &r, &mut v), StepStatus::Nominal, "k={k}");
                clarabel.observe(&y, &u);
                let estimate = clarabel.estimator().posterior().as_slice().to_vec();
                let sol = clarabel.solve(&estimate, &u_prev, &r).unwrap();
                let saturated = u[0].abs() >= limit - 1e-9;
                out.vs_general_active_set = out.vs_general_active_set.max((u[0] - v[0]).abs());
                out.moves += 1;
                out.saturated += usize::from(saturated);
                // Its reduced-accuracy solutions are no reference at this tolerance.
                if sol.status == QpStatus::Solved {
                    out.vs_clarabel = out.vs_clarabel.max((u[0] - sol.u[0]).abs());
                    out.solved += 1;
                    out.solved_saturated += usize::from(saturated);
                } else {
                    assert_eq!(sol.status, QpStatus::AlmostSolved, "k={k}");
                }
            }
            Act::Hold => {
                run_time.hold(&u);
                general.hold(&u);
                clarabel.hold(&u);
            }
            Act::Observe => {
                u[0] = (0.3 * k as f64).sin();
                run_time.observe(&y, &u);
                general.observe(&y, &u);
                clarabel.observe(&y, &u);
            }
            Act::Seed => {
                u[0] = 0.0;
                let s = [x[0], x[1], x[2], x[3]];
                run_time.seed(&s, &u);
                general.seed(&s, &u);
                clarabel.seed(&s, &u);
            }
        }
        // The voltage the plant receives, as the assembly's compensation writes it.
        let written = match law {
            Some(law) => law.apply(u[0], run_time.state_estimate().unwrap()[1]),
            None => u[0],
        };
        if k % 150 == 0 {
            kick = rng.gen_range(-kicks..kicks);
        } else if k % 150 == 10 {
            kick = 0.0;
        }
        for _ in 0..10 {
            plant.rk4_step(&mut x, written, kick, 0.001);
        }
        assert!(x[2].abs() < 1.0, "seed {seed} k={k}: fell");
    }
}

#[test]
fn the_run_time_mpc_moves_as_the_general_mpc_with_clarabel() {
    let dead_zone = Spec::parse("[plant]\npreset = 'qube_servo2'\nCr = 0.003\nVd = 0.4\n").unwrap();
    assert!(dead_zone.design(0.01).unwrap().compensation().is_some());
    // The kicks each pendulum survives while they saturate the input, and how many of its
    // moves Clarabel solves to full accuracy at least (on the QUBE's problems it mostly
    // stops at reduced accuracy, within 2e-4 V).
    let cases = [
        ("paper", Spec::default(), 0.04, 2000),
        ("qube_servo2 dead zone", dead_zone, 0.01, 100),
    ];
    for (name, spec, kicks, min_solved) in cases {
        let mut a = Agreement::default();
        for seed in 0..2 {
            mpcs_on_one_run(&spec, kicks, seed, 1200, &mut a);
        }
        eprintln!(
            "{name}: {} moves ({} saturated), {} solved by Clarabel ({} saturated); worst \
             |Δu| vs Clarabel {:e} V, vs the general active set {:e} V",
            a.moves,
            a.saturated,
            a.solved,
            a.solved_saturated,
            a.vs_clarabel,
            a.vs_general_active_set
        );
        assert!(a.moves >= 2000, "{name}: {}", a.moves);
        assert!(
            a.solved >= min_solved && a.solved_saturated > 0,
            "{name}: {} solved, {} saturated",
            a.solved,
            a.solved_saturated
        );
        // Clarabel's interior-point accuracy (3.5e-7 V at worst here).
        assert!(a.vs_clarabel < 1e-6, "{name}: {:e} V", a.vs_clarabel);
        // The same QP solver: the estimators and moves agree to round-off.
        assert!(
            a.vs_general_active_set < 1e-9,
            "{name}: {:e} V",
            a.vs_general_active_set
        );
    }
}

/// The one place the run-time MPC is chosen: rip-control's controller for the default
/// active set (seen by its fallback law at the iteration bound, which the general `Mpc` does
/// not share), the general `Mpc` for Clarabel.
#[test]
fn the_assembly_runs_the_mpc_on_rip_control_unless_clarabel_is_chosen() {
    use rip_core::{Controller, StepStatus};
    let mut spec = Spec::default();
    spec.mpc.max_iterations = 1;
    let design = spec.design(0.01).unwrap();
    let general = design.mpc().unwrap();
    let mut run_time = design.balance(ControllerKind::Mpc).unwrap();
    let mut u = [0.0];
    let mut limited = 0;
    for k in 0..50 {
        // A large tilt: the soft bound and the voltage bound are active, so one iteration
        // cannot finish.
        let y = [0.0, if k < 5 { 0.45 } else { 0.0 }];
        let u_prev = u[0];
        if run_time.step(&y, &[0.0, 0.0], &mut u) == StepStatus::Nominal {
            continue;
        }
        limited += 1;
        // rip-control's fallback: the unconstrained minimiser −H⁻¹f, clamped. The general
        // `Mpc` would apply the previous plan's next move instead.
        let x = run_time.state_estimate().unwrap();
        let (h, f, _, _) = general.qp_matrices(x, &[u_prev], &[0.0, 0.0]).unwrap();
        let z = -h.cholesky().unwrap().solve(&f);
        let want = (u_prev + z[0]).clamp(-12.0, 12.0);
        assert!((u[0] - want).abs() < 1e-9, "k={k}: {} vs {want}", u[0]);
    }
    assert!(limited > 0);
    assert!(general.run_time_controller().is_some());
    spec.mpc.solver = QpSolver::Clarabel;
    let clarabel = spec.design(0.01).unwrap().mpc().unwrap();
    assert!(clarabel.run_time_controller().is_none());
}

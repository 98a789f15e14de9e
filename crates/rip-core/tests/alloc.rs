//! The hot paths allocate nothing per call: every controller step and hold (regulators and the
//! MPC on its active-set backend), the estimator update and the RK4 step are counted with a global
//! allocator that tallies the allocations of the calling thread.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use std::sync::atomic::AtomicBool;

use rip_core::batch::{run_metrics, MetricsOptions, MonteCarlo};
use rip_core::mpc::paper::controller;
use rip_core::sim::{Reference, SensorModel};
use rip_core::spec::Param;
use rip_core::{Controller, FurutaParams, Lqg, Lqr, Plant, QpSolver, SimConfig, State};

struct Counting;

thread_local! {
    // Per thread, so tests running in parallel do not see each other's allocations.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|n| n.set(n.get() + 1));
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations_during(f: impl FnOnce()) -> usize {
    let before = ALLOCATIONS.with(Cell::get);
    f();
    ALLOCATIONS.with(Cell::get) - before
}

/// 200 samples of a tilted pendulum while the arm reference steps, some of them lost.
fn drive(ctrl: &mut dyn Controller) -> usize {
    let mut u = [0.0];
    // Warm up once: state initialised lazily on the first call may allocate.
    ctrl.step(&[0.0, 0.05], &[0.0, 0.0], &mut u);
    allocations_during(|| {
        for k in 0..200 {
            let t = k as f64 * 0.01;
            let y = [0.2 * t.sin(), 0.05 * (3.0 * t).cos()];
            let r = [if k > 50 { 1.0 } else { 0.0 }, 0.0];
            // Every seventh sample is lost on the wire: the controller holds instead.
            if k % 7 == 3 {
                ctrl.hold(&u);
            } else {
                ctrl.step(&y, &r, &mut u);
            }
            assert!(u[0].is_finite());
        }
    })
}

#[test]
fn regulator_steps_do_not_allocate() {
    assert_eq!(drive(&mut Lqr::paper().unwrap()), 0, "Lqr::step");
    assert_eq!(drive(&mut Lqg::paper().unwrap()), 0, "Lqg::step");
}

#[test]
fn compensated_steps_with_integral_action_do_not_allocate() {
    // A rig with a dead zone and arm friction, integral action on, the MPC on its active set.
    let spec = rip_core::Spec::parse(
        "[plant]\npreset = 'qube_servo2'\nVd = 0.65\nCr = 0.003\n\
         [lqr]\nintegral_weight = 20.0\n[mpc]\nsolver = 'active_set'\n",
    )
    .unwrap();
    let design = spec.design(0.01).unwrap();
    assert!(design.compensation().is_some() && design.integral_gain.is_some());
    for kind in rip_core::spec::ControllerKind::ALL {
        let mut c = design.controller(kind).unwrap();
        assert_eq!(drive(c.as_mut()), 0, "compensated {kind:?}");
    }
}

#[test]
fn active_set_mpc_step_does_not_allocate() {
    let mut mpc = controller(QpSolver::ActiveSet).unwrap();
    assert_eq!(drive(&mut mpc), 0, "Mpc::step (active set)");
}

#[test]
fn rk4_step_does_not_allocate() {
    let plant = Plant::paper();
    let mut x = State::new(0.0, 0.0, 0.1, 0.0);
    let n = allocations_during(|| {
        for _ in 0..1000 {
            plant.rk4_step(&mut x, 1.0, 0.0, 1e-3);
        }
    });
    assert_eq!(n, 0, "Plant::rk4_step");
}

#[test]
fn a_metrics_run_allocates_the_same_however_long_it_is() {
    let study = MonteCarlo {
        base: FurutaParams::paper(),
        perturbation: 0.05,
        parameters: vec![Param::Mr, Param::Lr, Param::Mp, Param::Lp],
        seed: 1,
    };
    let lqg = Lqg::paper().unwrap();
    let mpc = controller(QpSolver::ActiveSet).unwrap();
    let never = AtomicBool::new(false);
    let count = |duration: f64, make: &(dyn Fn() -> Box<dyn Controller> + Sync)| {
        let config = SimConfig {
            duration,
            x0: [0.0, 0.0, 0.05, 0.0],
            reference: Reference::Step {
                time: 0.5,
                value: [1.0, 0.0],
            },
            sensor: SensorModel {
                counts_per_rev: Some([2048.0, 2048.0]),
                noise_std: [1e-3, 1e-3],
                offsets: [0.0; 2],
            },
            ..Default::default()
        };
        let options = MetricsOptions::default();
        allocations_during(|| {
            let m = run_metrics(3, &|i| study.run(i), make, &config, &options, &never).unwrap();
            assert!(!m.fell);
        })
    };
    let make_lqg = || Box::new(lqg.clone()) as Box<dyn Controller>;
    let make_mpc = || Box::new(mpc.clone()) as Box<dyn Controller>;
    // 100 and 1000 samples: whatever a run allocates (its controller clone) is per run.
    assert_eq!(count(1.0, &make_lqg), count(10.0, &make_lqg), "Lqg");
    assert_eq!(
        count(1.0, &make_mpc),
        count(10.0, &make_mpc),
        "Mpc (active set)"
    );
}

#[test]
fn swing_up_supervisor_does_not_allocate() {
    use rip_core::{SwingUp, SwingUpSettings};
    let plant = Plant::paper();
    for balance in [
        Box::new(Lqg::paper().unwrap()) as Box<dyn Controller>,
        Box::new(controller(QpSolver::ActiveSet).unwrap()),
    ] {
        let mut sup = SwingUp::new(balance, &plant, SwingUpSettings::default()).unwrap();
        let mut x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
        let mut u = [0.0];
        sup.step(&[x[0], x[2]], &[0.0, 0.0], &mut u);
        // A simulated swing-up through catch and balance, with lost samples: every path of the
        // supervisor (seed, observe, catch, balance) runs inside the counted section.
        let n = allocations_during(|| {
            for k in 0..600 {
                if k % 7 == 3 {
                    sup.hold(&u);
                } else {
                    sup.step(&[x[0], x[2]], &[0.0, 0.0], &mut u);
                }
                plant.advance(&mut x, u[0], 0.0, 0.01, 10);
            }
        });
        assert_eq!(n, 0, "SwingUp::step");
        assert_eq!(sup.phase(), rip_core::Phase::Balance, "caught within 6 s");
    }
}

#[test]
fn excitation_signals_allocate_nothing_per_sample() {
    use rip_core::excitation::{Excitation, ExcitationSettings, Signal};
    for signal in Signal::ALL {
        let mut x = Excitation::new(ExcitationSettings::new(signal), 0.01).unwrap();
        let mut sum = 0.0;
        let n = allocations_during(|| {
            for k in 0..3000 {
                let t = k as f64 * 0.01;
                let e = x.value(t);
                sum += x.command(e, 0.3 * (0.5 * t).sin(), 0.15 * (0.5 * t).cos(), 3.0);
            }
            // Back in time: the PRBS restarts its register, still without allocating.
            sum += x.value(1.0);
        });
        assert_eq!(n, 0, "{signal}");
        assert!(sum.is_finite());
    }
}

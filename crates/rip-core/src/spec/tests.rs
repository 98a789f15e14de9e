use super::*;
use crate::controller::Controller;
use crate::linalg::c2d;
use crate::lqr::dlqr;
use crate::paper;
use crate::plant::{FurutaParams, Plant};

fn key_of(text: &str) -> String {
    match Spec::parse(text) {
        Ok(_) => panic!("{text:?} was accepted"),
        Err(e) => e.key,
    }
}

#[test]
fn empty_file_is_the_paper_setting() {
    let spec = Spec::parse("").unwrap();
    assert_eq!(spec, Spec::default());
    assert_eq!(spec.mpc.prediction_horizon, 50);
    assert_eq!(spec.mpc.control_horizon, 3);
    assert_eq!(spec.lqr.Q, [25.0, 0.0, 50.0, 0.0]);
    assert_eq!(spec.plant.params(), FurutaParams::paper());
    assert!(spec.plant.is_paper_model());
}

#[test]
fn printed_spec_reads_back_equal_and_names_every_key() {
    let mut spec = Spec::default();
    spec.plant.preset = Preset::QubeServo2;
    spec.plant.set(Param::Lp, Some(0.2));
    spec.mpc.solver = QpSolver::Clarabel;
    spec.monte_carlo.parameters = vec![Param::Mp, Param::Lp];
    let text = spec.to_toml();
    let back = Spec::parse(&text).unwrap();
    assert_eq!(back, spec.resolved());
    assert_eq!(back.to_toml(), text);
    assert_eq!(back.plant.params(), spec.plant.params());
    for key in [
        "controllers",
        "[plant]",
        "preset = \"qube_servo2\"",
        "Lp = 0.2",
        "Rm = 8.4",
        "substeps",
        "initial_state",
        "fall_limit",
        "[sensor]",
        "encoder_counts",
        "noise_std",
        "encoder_offsets = [0.0, 0.0]",
        "Cr = 0.0",
        "Cp = 0.0",
        "Vd = 0.0",
        "[reference]",
        "[lqr]",
        "Q = ",
        "R = ",
        "rate_cutoff",
        "[kalman]",
        "disturbance_gain",
        "measurement_noise",
        "[mpc]",
        "prediction_horizon",
        "input_rate_weights",
        "ecr_weight",
        "output_bounds = [[-inf, inf], ",
        "solver = \"clarabel\"",
        "[monte_carlo]",
        "parameters = [\"mp\", \"Lp\"]",
    ] {
        assert!(text.contains(key), "{key} missing from\n{text}");
    }
}

#[test]
fn unknown_keys_and_sections_are_named() {
    assert_eq!(
        key_of("[mpc]\nprediction_horizn = 10\n"),
        "mpc.prediction_horizn"
    );
    assert_eq!(key_of("[sefety]\nx = 1\n"), "sefety");
    assert_eq!(key_of("horizon = 1\n"), "horizon");
    // The old names of the runtime's own file are gone.
    assert_eq!(key_of("[mpc]\nhorizon = 20\n"), "mpc.horizon");
    assert_eq!(key_of("[lqg]\nR = 1\n"), "lqg");
}

#[test]
fn bad_values_are_named() {
    for (text, key) in [
        ("[plant]\npreset = 'pendulum9000'\n", "plant.preset"),
        ("[plant]\npreset = 'qube'\n", "plant.preset"),
        ("[plant]\nJr = 0.0\n", "plant.Jr"),
        ("[plant]\nDp = -1.0\n", "plant.Dp"),
        ("[plant]\nCr = -0.001\n", "plant.Cr"),
        ("[plant]\nCp = nan\n", "plant.Cp"),
        ("[plant]\nVd = -0.5\n", "plant.Vd"),
        (
            "[kalman]\ninput_disturbance = 0.1\nregulate_outputs = true\n",
            "kalman.regulate_outputs",
        ),
        ("[plant]\nVd = inf\n", "plant.Vd"),
        (
            "[sensor]\nencoder_offsets = [0.0, 4.0]\n",
            "sensor.encoder_offsets[1]",
        ),
        ("[plant]\nsubsteps = 100001\n", "plant.substeps"),
        ("[plant]\nsubsteps = 0\n", "plant.substeps"),
        (
            "[plant]\ninitial_state = [0.0, 0.0, 2.0, 0.0]\n",
            "plant.initial_state[2]",
        ),
        (
            "[plant]\ninitial_state = [0.0, 0.0, nan, 0.0]\n",
            "plant.initial_state[2]",
        ),
        (
            "[plant]\ninitial_state = [0.0, 0.0]\n",
            "plant.initial_state",
        ),
        ("[mpc]\ncontrol_horizon = 80\n", "mpc.control_horizon"),
        ("[mpc]\nprediction_horizon = 0\n", "mpc.prediction_horizon"),
        (
            "[mpc]\nprediction_horizon = 100000\n",
            "mpc.prediction_horizon",
        ),
        ("[mpc]\necr_weight = 0.0\n", "mpc.ecr_weight"),
        (
            "[mpc]\ninput_bounds = [[-inf, inf]]\n",
            "mpc.input_bounds[0]",
        ),
        (
            "[mpc]\noutput_bounds = [[-inf, inf], [0.5, -0.5]]\n",
            "mpc.output_bounds[1]",
        ),
        ("[mpc]\nsolver = 'osqp'\n", "mpc.solver"),
        (
            "[mpc]\noutput_weights = [1.0, -1.0]\n",
            "mpc.output_weights[1]",
        ),
        (
            "[sensor]\nnoise_std = [0.001, -1.0]\n",
            "sensor.noise_std[1]",
        ),
        (
            "[sensor]\nencoder_counts = [0.5, 2048]\n",
            "sensor.encoder_counts[0]",
        ),
        (
            "[sensor]\nencoder_counts = [0, 2048]\n",
            "sensor.encoder_counts[0]",
        ),
        ("[reference]\nduration = 'long'\n", "reference.duration"),
        ("[reference]\nduration = 0.001\n", "reference.duration"),
        ("[reference]\nduration = 1e6\n", "reference.duration"),
        ("[reference]\narm_step = 1e300\n", "reference.arm_step"),
        (
            "[kalman]\ndisturbance_gain = -0.01\n",
            "kalman.disturbance_gain",
        ),
        ("[lqr]\nrate_cutoff = 0.0\n", "lqr.rate_cutoff"),
        ("[lqr]\nR = 0\n", "lqr.R"),
        ("[lqr]\nQ = [1, 2, -3, 4]\n", "lqr.Q[2]"),
        ("[lqr]\nQ = [0, 2, 3, 4]\n", "lqr.Q[0]"),
        ("controllers = ['LQR', 'PID']\n", "controllers[1]"),
        ("controllers = ['LQR', 'LQR']\n", "controllers[1]"),
        ("controllers = []\n", "controllers"),
        (
            "[monte_carlo]\nperturbation = 1.0\n",
            "monte_carlo.perturbation",
        ),
        (
            "[monte_carlo]\nparameters = ['g']\n",
            "monte_carlo.parameters[0]",
        ),
        ("[monte_carlo]\nruns = -1\n", "monte_carlo.runs"),
    ] {
        assert_eq!(key_of(text), key, "{text}");
    }
}

#[test]
fn the_message_names_the_key_the_value_and_the_file() {
    let e = Spec::parse("[mpc]\nprediction_horizon = 0\n").unwrap_err();
    assert_eq!(
        e.to_string(),
        "mpc.prediction_horizon: must be in 1..=10000, got 0"
    );
    let e = e.in_file(std::path::Path::new("cfg.toml"));
    assert_eq!(
        e.to_string(),
        "cfg.toml: mpc.prediction_horizon: must be in 1..=10000, got 0"
    );
    let e = Spec::parse("[reference\n").unwrap_err();
    assert!(e.to_string().starts_with("invalid TOML"), "{e}");
}

#[test]
fn runtime_sections_pass_through_unchecked() {
    let (spec, runtime) =
        Spec::parse_with_runtime("[loop]\nperiod_ms = 5\n[safety]\nvoltage_limit = 6\n").unwrap();
    assert_eq!(spec, Spec::default());
    assert_eq!(runtime["loop"]["period_ms"].as_integer(), Some(5));
    assert!(runtime.contains_key("safety") && !runtime.contains_key("device"));
}

#[test]
fn parameters_override_the_preset() {
    let spec = Spec::parse("[plant]\npreset = 'qube_servo2'\nLp = 0.3\nkm = 0.05\n").unwrap();
    let p = spec.plant.params();
    let q = FurutaParams::qube_servo2();
    assert_eq!(p.lp, 0.3);
    assert_eq!(p.km, 0.05);
    assert_eq!(p.mr, q.mr);
    assert_eq!(p.jp, q.jp);
    // The paper preset with its own values written out is still the paper's model.
    let written = Spec::default().to_toml();
    assert!(Spec::parse(&written).unwrap().plant.is_paper_model());
    assert!(!Spec::parse("[plant]\nDp = 0.001\n")
        .unwrap()
        .plant
        .is_paper_model());
}

#[test]
fn default_design_is_the_papers() {
    let design = Spec::default().design(paper::TS).unwrap();
    let model = paper::discrete_model();
    assert_eq!(design.a, model.a);
    assert_eq!(design.b, model.b);
    let (q, r) = paper::lqr_weights();
    let k = dlqr(&model.a, &model.b, &q, &r, None).unwrap().k;
    assert_eq!(design.k, k);
    let reference = paper::kalman_design().unwrap();
    let kf = design.estimator.kalman();
    assert!((&kf.l - &reference.l).amax() < 1e-12);
    assert!((&kf.m - &reference.m).amax() < 1e-12);
    let lqg = design.lqg().unwrap();
    assert!((lqg.predictor_gain() - &reference.l).amax() < 1e-12);
    assert_eq!(lqg.gain(), k);
    let mpc = design.mpc().unwrap();
    assert!((&mpc.kalman_design().l - &reference.l).amax() < 1e-12);
    assert_eq!(mpc.prediction_horizon(), 50);
}

#[test]
fn other_plants_are_designed_on_their_own_linearisation_at_the_loop_period() {
    let spec = Spec::parse("[plant]\npreset = 'qube_servo2'\nDp = 0.0007\n").unwrap();
    let ts = 0.005;
    let design = spec.design(ts).unwrap();
    let plant = Plant::new(FurutaParams {
        dp: 0.0007,
        ..FurutaParams::qube_servo2()
    })
    .unwrap();
    let (ac, bc) = plant.linearize_upright();
    let (a, b) = c2d(&ac, &bc, ts).unwrap();
    assert!((&design.a - &a).amax() < 1e-14);
    assert!((&design.b - &b).amax() < 1e-14);
    assert_eq!(design.lqr().unwrap().ts(), ts);
    assert_eq!(design.mpc().unwrap().ts(), ts);
}

#[test]
fn lqg_with_output_scales_runs_the_mpcs_filter() {
    // The MPC's filter works on y/s_y; the LQG's, on y. Fed the same measurements, both must
    // hold the same estimate.
    let spec = Spec::parse("[mpc]\noutput_scales = [2.0, 0.5]\n").unwrap();
    let design = spec.design(paper::TS).unwrap();
    let (mut u, mut u_mpc) = ([0.0], [0.0]);
    let mut lqg = design.lqg().unwrap();
    let mut mpc = design.mpc().unwrap();
    let y = [0.1, -0.05];
    lqg.step(&y, &[0.0, 0.0], &mut u);
    mpc.step(&y, &[0.0, 0.0], &mut u_mpc);
    let a = lqg.state_estimate().unwrap().to_vec();
    let b = mpc.state_estimate().unwrap().to_vec();
    for (x, z) in a.iter().zip(&b) {
        assert!((x - z).abs() < 1e-12, "{a:?} vs {b:?}");
    }
}

#[test]
fn designs_that_fail_name_the_key() {
    let fails = |text: &str| {
        Spec::parse(text)
            .unwrap()
            .design(paper::TS)
            .and_then(|d| d.controllers().map(|_| ()))
            .unwrap_err()
    };
    let e = Spec::parse("[lqr]\nQ = [0.0, 0.0, 0.0, 0.0]\n").unwrap_err();
    assert_eq!(e.key, "lqr.Q[0]", "{e}");
    // R = 1e-300 is the cheap-control limit, solved like a singular R (the DARE needs only
    // BᵀXB + R invertible): it designs (riprs.dlqr of the paper's model at R = 1e-300 matches
    // scipy's R = 0 gain to 5e-9).
    let design = Spec::parse("[lqr]\nR = 1e-300\n")
        .unwrap()
        .design(paper::TS)
        .unwrap();
    assert!(design.k.iter().all(|v| v.is_finite()));
    let e = fails("[lqr]\nR = 1e308\n");
    assert_eq!(e.key, "lqr.R", "{e}");
    let e = fails("[mpc]\noutput_weights = [1e308, 1e308]\n");
    assert_eq!(e.key, "mpc.output_weights", "{e}");
}

#[test]
fn controllers_come_in_the_files_order() {
    let spec = Spec::parse("controllers = ['MPC', 'LQR']\n").unwrap();
    let built = spec.design(paper::TS).unwrap().controllers().unwrap();
    let kinds: Vec<_> = built.iter().map(|(k, _)| *k).collect();
    assert_eq!(kinds, [ControllerKind::Mpc, ControllerKind::Lqr]);
}

#[test]
fn friction_dead_zone_and_offsets_reach_the_plant_and_the_simulation() {
    let spec = Spec::parse(
        "[plant]\npreset = 'qube_servo2'\nCr = 0.002\nCp = 1e-5\nVd = 0.3\n\
         [sensor]\nencoder_offsets = [0.1, -0.2]\n",
    )
    .unwrap();
    let p = spec.plant.params();
    assert_eq!((p.cr, p.cp, p.vd), (0.002, 1e-5, 0.3));
    assert!(!spec.plant.is_paper_model());
    // The design model is the smooth part's: the same as without friction and dead zone.
    let smooth = Spec::parse("[plant]\npreset = 'qube_servo2'\n").unwrap();
    assert_eq!(
        spec.design(paper::TS).unwrap().a,
        smooth.design(paper::TS).unwrap().a
    );
    let cfg = spec.sim_config(paper::TS, 0);
    assert_eq!(cfg.sensor.offsets, [0.1, -0.2]);
}

#[test]
fn the_cable_reaches_the_plant_and_the_design_and_a_bad_one_is_named() {
    let spec = Spec::parse("[plant]\nKc = 2.384e-3\n").unwrap();
    assert_eq!(spec.plant.params().kc, 2.384e-3);
    assert!(!spec.plant.is_paper_model());
    assert_eq!(spec.plant().unwrap().params().kc, 2.384e-3);
    // A spring on the arm is smooth: the design model has it, the paper's has not.
    let a = spec.design(paper::TS).unwrap().a;
    assert!(a[(1, 0)] < 0.0, "{a}");
    assert_eq!(Spec::default().design(paper::TS).unwrap().a[(1, 0)], 0.0);
    for bad in ["-1e-3", "nan", "inf"] {
        assert_eq!(
            key_of(&format!("[plant]\nKc = {bad}\n")),
            "plant.Kc",
            "{bad}"
        );
    }
    let text = spec.to_toml();
    assert!(text.contains("Kc = 0.002384"), "{text}");
    assert_eq!(
        Spec::parse(&text).unwrap().plant.params(),
        spec.plant.params()
    );
}

#[test]
fn a_rig_without_dead_zone_or_friction_gets_the_controllers_unchanged() {
    for text in ["", "[plant]\npreset = 'qube_servo2'\n"] {
        let design = Spec::parse(text).unwrap().design(paper::TS).unwrap();
        assert!(design.compensation().is_none());
        assert_eq!(design.bounds(), (-12.0, 12.0));
        for kind in ControllerKind::ALL {
            let mut built = design.controller(kind).unwrap();
            let mut bare = design.balance(kind).unwrap();
            let (mut u, mut v) = ([0.0], [0.0]);
            for k in 0..40 {
                let y = [0.01 * f64::from(k), 0.02 * (f64::from(k) * 0.3).sin()];
                built.step(&y, &[1.0, 0.0], &mut u);
                bare.step(&y, &[1.0, 0.0], &mut v);
                assert_eq!(u[0].to_bits(), v[0].to_bits(), "{kind:?} step {k}");
            }
        }
    }
}

#[test]
fn the_compensation_follows_the_plant_and_shrinks_the_planned_bounds() {
    let text = "[plant]\npreset = 'qube_servo2'\nCr = 0.003\nVd = 0.4\n";
    let spec = Spec::parse(text).unwrap();
    let design = spec.design(paper::TS).unwrap();
    let p = spec.plant.params();
    let law = *design.compensation().unwrap();
    let vf = 0.003 * p.rm / p.kt;
    assert_eq!((law.dead_zone(), law.friction_voltage()), (0.4, vf));
    assert_eq!(law.bounds(), (-12.0, 12.0));
    let (lo, hi) = design.bounds();
    assert!((hi - (12.0 - 0.4 - vf)).abs() < 1e-12 && (lo + hi).abs() < 1e-12);
    assert_eq!(design.lqr().unwrap().input_bounds(), (lo, hi));
    // The MPC plans within the shrunk bounds: a large error saturates it there, and the
    // written voltage is the law's value of that, inside ±12 V.
    let mut mpc = design.balance(ControllerKind::Mpc).unwrap();
    let mut built = design.controller(ControllerKind::Mpc).unwrap();
    let (mut v, mut u) = ([0.0], [0.0]);
    mpc.step(&[0.0, 0.3], &[0.0, 0.0], &mut v);
    built.step(&[0.0, 0.3], &[0.0, 0.0], &mut u);
    assert!((v[0].abs() - hi).abs() < 1e-6, "{}", v[0]);
    assert!(u[0].abs() <= 12.0, "{}", u[0]);
    assert!((u[0] - v[0]).abs() > 0.1, "{} {}", u[0], v[0]);
    assert_eq!(u[0], law.apply(v[0], built.state_estimate().unwrap()[1]));
    // Explicit values and the switch.
    let own = Spec::parse(&format!(
        "{text}[compensation]\ndead_zone = 0.28\narm_friction = 0.0\n"
    ))
    .unwrap()
    .design(paper::TS)
    .unwrap();
    let own = own.compensation().unwrap();
    assert_eq!((own.dead_zone(), own.friction_voltage()), (0.28, 0.0));
    let off = Spec::parse(&format!("{text}[compensation]\nenabled = false\n"))
        .unwrap()
        .design(paper::TS)
        .unwrap();
    assert!(off.compensation().is_none());
    assert_eq!(off.bounds(), (-12.0, 12.0));
    // The resolved file reads back equal.
    let resolved = Spec::parse(&format!("{text}[compensation]\ndead_zone = 0.28\n")).unwrap();
    assert_eq!(
        Spec::parse(&resolved.to_toml()).unwrap(),
        resolved.resolved()
    );
}

#[test]
fn the_compensations_gains_multiply_what_it_compensates() {
    let text = "[plant]\npreset = 'qube_servo2'\nCr = 0.003\nVd = 0.4\n";
    let p = Spec::parse(text).unwrap().plant.params();
    let vf = 0.003 * p.rm / p.kt;
    let law = |extra: &str| {
        *Spec::parse(&format!("{text}[compensation]\n{extra}"))
            .unwrap()
            .design(paper::TS)
            .unwrap()
            .compensation()
            .unwrap()
    };
    let hedged = law("dead_zone_gain = 1.5\nfriction_gain = 2.0\n");
    assert_eq!(hedged.dead_zone(), 1.5 * 0.4);
    assert_eq!(hedged.friction_voltage(), 2.0 * 0.003 * p.rm / p.kt);
    // On the file's own values too, and the planned bounds shrink by what is applied.
    let own = law("dead_zone = 0.2\narm_friction = 0.001\ndead_zone_gain = 1.25\n");
    assert_eq!(own.dead_zone(), 1.25 * 0.2);
    assert_eq!(own.friction_voltage(), 0.001 * p.rm / p.kt);
    let design = Spec::parse(&format!("{text}[compensation]\nfriction_gain = 2.0\n"))
        .unwrap()
        .design(paper::TS)
        .unwrap();
    assert!((design.bounds().1 - (12.0 - 0.4 - 2.0 * vf)).abs() < 1e-12);
    // A gain that leaves no room is refused through it, with the bound it must stay below:
    // just below it is accepted, a little above it is not.
    let e = Spec::parse(&format!("{text}[compensation]\ndead_zone_gain = 40\n"))
        .unwrap()
        .design(paper::TS)
        .unwrap_err();
    assert_eq!(e.key, "compensation.dead_zone_gain", "{e}");
    let fits: f64 = e
        .to_string()
        .split("must be below ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no largest gain in: {e}"));
    assert!((fits - (12.0 - vf) / 0.4).abs() < 1e-3, "{fits}: {e}");
    let at = |g: f64| {
        Spec::parse(&format!("{text}[compensation]\ndead_zone_gain = {g}\n"))
            .unwrap()
            .design(paper::TS)
    };
    assert!(at(fits * (1.0 - 1e-6)).is_ok());
    assert!(at(fits + 0.01).is_err());
    let e = Spec::parse(&format!("{text}[compensation]\nfriction_gain = 1e6\n"))
        .unwrap()
        .design(paper::TS)
        .unwrap_err();
    assert_eq!(e.key, "compensation.friction_gain", "{e}");
}

#[test]
fn bad_compensation_values_name_the_key() {
    assert_eq!(
        key_of("[compensation]\nvoltage_scale = 0\n"),
        "compensation.voltage_scale"
    );
    assert_eq!(
        key_of("[compensation]\nvelocity_scale = -1\n"),
        "compensation.velocity_scale"
    );
    assert_eq!(
        key_of("[compensation]\ndead_zone = nan\n"),
        "compensation.dead_zone"
    );
    assert_eq!(
        key_of("[compensation]\narm_friction = -1\n"),
        "compensation.arm_friction"
    );
    assert_eq!(
        key_of("[compensation]\nenabled = 1\n"),
        "compensation.enabled"
    );
    assert_eq!(
        key_of("[compensation]\ndead_zone_gain = -0.5\n"),
        "compensation.dead_zone_gain"
    );
    assert_eq!(
        key_of("[compensation]\nfriction_gain = inf\n"),
        "compensation.friction_gain"
    );
    let e = Spec::parse("[compensation]\ndead_zone = 12.5\n")
        .unwrap()
        .design(paper::TS)
        .unwrap_err();
    assert_eq!(e.key, "compensation.dead_zone", "{e}");
}

#[test]
fn the_paper_mpc_is_the_default_specs_mpc() {
    use crate::mpc::{paper as mpc_paper, MpcSettings, QpSolver};
    // One profile: the file's [mpc] defaults, the spec's settings and the paper controller's.
    let spec = Spec::default();
    let mut from_spec = spec.design(paper::TS).unwrap().mpc().unwrap();
    let mut paper_mpc = mpc_paper::controller(QpSolver::default()).unwrap();
    assert_eq!(spec.mpc, MpcSettings::paper());
    assert_eq!(from_spec.settings(), paper_mpc.settings());
    assert_eq!(from_spec.settings().solver, QpSolver::ActiveSet);
    assert_eq!(Spec::parse("").unwrap().mpc, MpcSettings::paper());
    // ... and the same moves, bit for bit, along a step response that reaches the bounds.
    let (mut ua, mut ub) = ([0.0], [0.0]);
    for k in 0..300 {
        let y = [0.4 * (k as f64 * 0.05).sin(), 0.05 * (k as f64 * 0.2).cos()];
        let r = [1.0, 0.0];
        from_spec.step(&y, &r, &mut ua);
        paper_mpc.step(&y, &r, &mut ub);
        assert_eq!(ua[0].to_bits(), ub[0].to_bits(), "step {k}");
    }
}

#[test]
fn mpc_keys_deserialise_into_the_mpc_settings() {
    use crate::mpc::QpSolver;
    let spec = Spec::parse(
        "[mpc]\nprediction_horizon = 20\ncontrol_horizon = 4\noutput_weights = [1.0, 2.0]\n\
         input_rate_weights = [0.5]\ninput_weights = [0.1]\ninput_bounds = [[-5.0, 6.0]]\n\
         output_bounds = [[-1.0, 1.0], [-0.2, 0.2]]\necr_weight = 7.0\ninput_scales = [2.0]\n\
         output_scales = [3.0, 4.0]\nsolver = \"clarabel\"\nmax_iterations = 50\n",
    )
    .unwrap();
    let design = spec.design(paper::TS).unwrap();
    let mpc = design.mpc().unwrap();
    let s = mpc.settings();
    assert_eq!((s.prediction_horizon, s.control_horizon), (20, 4));
    assert_eq!(s.output_weights, [1.0, 2.0]);
    assert_eq!(s.input_rate_weights, [0.5]);
    assert_eq!(s.input_weights, [0.1]);
    assert_eq!(s.input_bounds, [(-5.0, 6.0)]);
    assert_eq!(s.output_bounds, [(-1.0, 1.0), (-0.2, 0.2)]);
    assert_eq!(s.ecr_weight, 7.0);
    assert_eq!(s.input_scales, [2.0]);
    assert_eq!(s.output_scales, [3.0, 4.0]);
    assert_eq!(s.solver, QpSolver::Clarabel);
    assert_eq!(s.max_iterations, 50);
    // Sizes and the condensed size are the spec's errors too, keyed.
    for (text, key) in [
        ("[mpc]\noutput_weights = [1.0]\n", "mpc.output_weights"),
        ("[mpc]\ninput_bounds = []\n", "mpc.input_bounds"),
        ("[mpc]\nmax_iterations = 0\n", "mpc.max_iterations"),
        (
            "[mpc]\nprediction_horizon = 10000\ncontrol_horizon = 5000\n",
            "mpc.prediction_horizon",
        ),
        ("[mpc]\nunknown = 1\n", "mpc.unknown"),
    ] {
        assert_eq!(Spec::parse(text).unwrap_err().key, key, "{text}");
    }
    // A soft equality is allowed, in the file as in the Rust and Python API.
    assert!(Spec::parse("[mpc]\noutput_bounds = [[-inf, inf], [0.0, 0.0]]\n").is_ok());
}

#[test]
fn a_key_that_moved_is_refused_naming_its_new_key() {
    for (old, new) in super::MOVED_KEYS {
        let (section, key) = old.split_once('.').unwrap();
        let text = format!("[{section}]\n{key} = 4096\n");
        let e = Spec::parse(&text).unwrap_err();
        assert_eq!(e.key, old, "{e}");
        assert!(e.reason.contains(new), "{e}");
        let e = super::rig_sections::parse_file(&text).unwrap_err();
        assert_eq!(e.key, old, "{e}");
    }
    // rip-rt's encoders are the file's one resolution, `[sensor] encoder_counts`.
    let (_, rig) =
        super::rig_sections::parse_file("[sensor]\nencoder_counts = [1024, 4096]\n").unwrap();
    assert_eq!(
        [
            rig.device.arm_counts_per_rev,
            rig.device.pendulum_counts_per_rev
        ],
        [1024, 4096]
    );
}

#[test]
fn an_update_is_a_deep_merge_checked_as_a_file() {
    let base =
        Spec::parse("[mpc]\nprediction_horizon = 20\n[sensor]\nnoise_std = [0.0, 0.0]\n").unwrap();
    let changes: toml::Table = "[mpc]\ncontrol_horizon = 2\n[sensor]\nnoise_std = [1e-3, 2e-3]\n"
        .parse()
        .unwrap();
    let updated = base.updated(changes).unwrap();
    let file = Spec::parse(
        "[mpc]\nprediction_horizon = 20\ncontrol_horizon = 2\n\
         [sensor]\nnoise_std = [1e-3, 2e-3]\n",
    )
    .unwrap();
    assert_eq!(updated.resolved(), file.resolved());
    // A new preset brings its parameters, except those set with it.
    let changes: toml::Table = "[plant]\npreset = \"qube_servo2\"\nmr = 0.1\n"
        .parse()
        .unwrap();
    let updated = Spec::default().updated(changes).unwrap();
    let file = Spec::parse("[plant]\npreset = \"qube_servo2\"\nmr = 0.1\n").unwrap();
    assert_eq!(updated.resolved(), file.resolved());
    // Bad and unknown keys are named, as in a file.
    for (text, key) in [
        ("[mpc]\nhorizon = 3\n", "mpc.horizon"),
        (
            "[mpc]\nprediction_horizon = \"x\"\n",
            "mpc.prediction_horizon",
        ),
        (
            "[sensor]\nnoise_std = [1e-3, -1.0]\n",
            "sensor.noise_std[1]",
        ),
        (
            "[device]\narm_counts_per_rev = 1024\n",
            "device.arm_counts_per_rev",
        ),
    ] {
        let e = Spec::default().updated(text.parse().unwrap()).unwrap_err();
        assert_eq!(e.key, key, "{text}: {e}");
    }
}

#[test]
fn the_study_steps_the_arm_reference_step_time_after_the_catch() {
    // `reference.step_time` is the time from the catch to the step on the rig (rip-rt's loop);
    // the simulated swing-up must use the same setting, not a constant of its own.
    use crate::sim::simulate;
    for step_time in [0.37, 1.6] {
        let spec = Spec::parse(&format!("[reference]\nstep_time = {step_time}\n")).unwrap();
        let design = spec.design(paper::TS).unwrap();
        let config = crate::SimConfig {
            duration: 6.0,
            ..study::hanging_config(&spec, paper::TS, 0)
        };
        let mut sup = study::supervised(&spec, &design, ControllerKind::Lqr).unwrap();
        let res = simulate(&spec.plant().unwrap(), sup.as_mut(), &config).unwrap();
        let tc = res.catch_time.expect("the paper rig is caught within 6 s");
        let first = res.t.iter().zip(&res.r).find(|(_, r)| r[0] != 0.0).unwrap();
        assert_eq!(first.1[0], spec.reference.arm_step);
        // The first sample at or after catch + step_time (the sample grid is Ts).
        assert!(
            *first.0 >= tc + step_time - 1e-9 && *first.0 < tc + step_time + paper::TS,
            "step at {}, catch {tc}, step_time {step_time}",
            first.0
        );
    }
}

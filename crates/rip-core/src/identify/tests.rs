use super::params;
use super::*;
use crate::excitation::{Excitation, ExcitationSettings, Signal};
use crate::plant::Plant;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// A rig riprs does not know: away from both presets, with friction and a dead zone.
pub(crate) fn hidden() -> FurutaParams {
    FurutaParams {
        rm: 6.1,
        kt: 0.051,
        km: 0.051,
        mr: 0.11,
        lr: 0.097,
        jr: 1.1e-4,
        mp: 0.031,
        lp: 0.152,
        jp: 6.5e-5,
        dr: 9e-4,
        dp: 2.4e-5,
        g: 9.81,
        cr: 2.5e-3,
        cp: 1.5e-5,
        vd: 0.35,
        kc: 0.0,
    }
}

#[test]
fn the_cable_is_held_at_the_start_sets_stiffness() {
    // The fit never moves kc (module docs): whatever values it tries, the start's stays.
    let start = FurutaParams {
        kc: 2.384e-3,
        ..hidden()
    };
    let values: [f64; NP] = std::array::from_fn(|k| 1.3 * params::get(&start, k));
    for tie_km in [true, false] {
        assert_eq!(params::with(start, &values, tie_km).kc, start.kc);
    }
    assert!(!FREE.contains(&Param::Kc) && !HELD.contains(&Param::Kc));
}

/// An excitation run of `plant` from hanging at rest: the excitation through the arm-centring
/// law on the measured arm angle, 2048-count encoders and 0.5 mrad of noise.
pub(crate) fn run(plant: &Plant, signal: Signal, duration: f64, seed: u64) -> LogData {
    let ts = 0.01;
    let mut settings = ExcitationSettings::new(signal);
    settings.duration = duration;
    settings.amplitude = 2.5;
    let mut exc = Excitation::new(settings, ts).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 5e-4).unwrap();
    let q = std::f64::consts::TAU / 2048.0;
    let mut x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    let n = (duration / ts).round() as usize;
    let (mut u, mut y) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for k in 0..n {
        let meas = [x[0], x[2]].map(|a| (a / q).round() * q + noise.sample(&mut rng));
        let e = exc.value(k as f64 * ts);
        // The logs these tests fit were made without the centring law's rate term.
        let uk = exc.command(e, meas[0], 0.0, 2.0).clamp(-10.0, 10.0);
        y.push(meas);
        u.push(uk);
        plant.advance(&mut x, uk, 0.0, ts, 10);
    }
    LogData { ts, u, y }
}

#[test]
fn recovers_a_hidden_rig_from_chirp_and_prbs_runs() {
    let truth = Plant::new(hidden()).unwrap();
    let logs = [
        run(&truth, Signal::Chirp, 30.0, 1),
        run(&truth, Signal::Prbs, 30.0, 2),
    ];
    let result = identify(&logs, &IdentifyOptions::default(), &AtomicBool::new(false)).unwrap();
    let (ad, bd) = truth
        .linearize_discrete(&State::zeros(), 0.0, 0.01)
        .unwrap();
    let mut worst = 0.0f64;
    for i in 0..4 {
        let row_scale = (0..5)
            .map(|j| {
                if j < 4 {
                    (ad[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs()
                } else {
                    bd[(i, 0)].abs()
                }
            })
            .fold(0.0, f64::max);
        for j in 0..5 {
            let (t, g) = if j < 4 {
                (ad[(i, j)], result.ad[(i, j)])
            } else {
                (bd[(i, 0)], result.bd[(i, 0)])
            };
            let dev = if j < 4 && i == j { t - 1.0 } else { t };
            let rel = (g - t).abs() / t.abs().max(1e-300);
            eprintln!("[{i}][{j}] true {t:.6e} identified {g:.6e} rel {rel:.2e}");
            if dev.abs() >= 0.05 * row_scale {
                worst = worst.max(rel);
            }
        }
    }
    eprintln!("{result:#?}");
    assert!(worst < 0.05, "worst relative error {worst}");
    for f in &result.fit_percent {
        assert!(f[0] >= 90.0 && f[1] >= 90.0, "{:?}", result.fit_percent);
    }
    // The friction and dead zone themselves.
    let p = result.params;
    assert!((p.vd - 0.35).abs() < 0.1 * 0.35, "vd {}", p.vd);
    assert!(
        result.not_identifiable.is_empty(),
        "{:?}",
        result.not_identifiable
    );
}

#[test]
fn bad_logs_are_refused_by_name() {
    let plant = Plant::new(hidden()).unwrap();
    let good = run(&plant, Signal::Chirp, 4.0, 1);
    let cancel = AtomicBool::new(false);
    let o = IdentifyOptions::default();
    let mut nan = good.clone();
    nan.y[17][1] = f64::NAN;
    let err = identify(&[good.clone(), nan], &o, &cancel).unwrap_err();
    assert!(
        err.to_string().contains("logs[1]") && err.to_string().contains("sample 17"),
        "{err}"
    );
    let short = LogData {
        u: good.u[..150].to_vec(),
        y: good.y[..150].to_vec(),
        ..good.clone()
    };
    assert!(identify(&[short], &o, &cancel)
        .unwrap_err()
        .to_string()
        .contains("too short"));
    let still = LogData {
        u: vec![0.0; 400],
        y: vec![[0.0, std::f64::consts::PI]; 400],
        ts: 0.01,
    };
    assert!(identify(&[still], &o, &cancel)
        .unwrap_err()
        .to_string()
        .contains("no excitation"));
    cancel.store(true, Ordering::Relaxed);
    assert!(matches!(
        identify(&[good], &o, &cancel),
        Err(RipError::Cancelled)
    ));
}

#[test]
fn the_verdict_trusts_a_good_fit_and_names_a_wrong_start() {
    let truth = Plant::new(hidden()).unwrap();
    let logs = [
        run(&truth, Signal::Chirp, 20.0, 3),
        run(&truth, Signal::Prbs, 20.0, 4),
    ];
    let cancel = AtomicBool::new(false);
    let names = vec!["chirp".to_string(), "prbs".to_string()];
    let good = IdentifyOptions {
        start: hidden(),
        names: names.clone(),
        ..Default::default()
    };
    let result = identify(&logs, &good, &cancel).unwrap();
    assert!(result.problems.is_empty(), "{:?}", result.problems);
    assert_eq!(result.covariance.len(), NP * NP);
    // A start whose pendulum is a third of the rig's mass and length: the scale it fixes is
    // wrong, and the verdict says so, naming a log or the measurement.
    let mut wrong = hidden();
    wrong.mp /= 3.0;
    wrong.lp /= 3.0;
    wrong.jp /= 27.0;
    let bad = IdentifyOptions {
        start: wrong,
        names,
        max_iterations: 20,
        ..Default::default()
    };
    match identify(&logs, &bad, &cancel) {
        Ok(r) => assert!(!r.problems.is_empty(), "accepted: {:?}", r.params),
        Err(e) => assert!(e.to_string().contains("lab file"), "{e}"),
    }
}

#[test]
fn a_held_out_part_at_rest_is_not_scored() {
    let truth = Plant::new(hidden()).unwrap();
    let mut log = run(&truth, Signal::Chirp, 8.0, 5);
    let rest = log.y.len() * 3 / 4;
    for k in rest..log.y.len() {
        log.u[k] = 0.0;
        log.y[k] = [0.1 + 1e-4 * (k % 3) as f64, std::f64::consts::PI - 1e-3];
    }
    let o = IdentifyOptions {
        max_iterations: 2,
        ..Default::default()
    };
    let result = identify(&[log], &o, &AtomicBool::new(false)).unwrap();
    assert!(result.fit_percent[0].iter().all(|f| f.is_nan()));
    assert!(result.held_out_motion[0]
        .iter()
        .all(|m| *m < MIN_HELDOUT_MOTION));
    // Not scored is not passed: the check is listed as not done, with what to record.
    assert_eq!(result.not_done.len(), 1, "{:?}", result.not_done);
    assert!(result.not_done[0].starts_with("logs[0]: held-out fit not done"));
    assert!(result.not_done[0].contains(&format!("at least {MIN_HELDOUT_MOTION} rad")));
}

/// A held value's prior reaches the estimates along `params::held_sensitivity`: moving the
/// held value and the estimates along it must leave the dynamics as they are (the logs cannot
/// tell the two apart), while moving the held value alone must not.
#[test]
fn the_held_values_move_the_estimates_along_directions_of_equal_dynamics() {
    let truth = hidden();
    let states = [
        State::new(0.3, -1.2, 2.5, 4.0),
        State::new(-0.8, 2.0, 0.4, -3.0),
        State::new(0.0, 0.1, std::f64::consts::PI - 0.2, 0.5),
    ];
    let derivatives = |p: &FurutaParams| -> Vec<f64> {
        let plant = Plant::new(*p).unwrap();
        states
            .iter()
            .flat_map(|x| [-4.0, 0.2, 3.0].map(|u| plant.derivative(x, u, 0.0)))
            .flat_map(|d| [d[1], d[3]])
            .collect()
    };
    let worst = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs() / x.abs().max(1e-3))
            .fold(0.0, f64::max)
    };
    let eps: f64 = 1e-4;
    for tie_km in [true, false] {
        let values: [f64; NP] = std::array::from_fn(|k| params::get(&truth, k));
        let at = derivatives(&params::with(truth, &values, tie_km));
        let held = if tie_km { &HELD[..4] } else { &HELD[..] };
        for &h in held {
            let mut start = truth;
            start.set(h, truth.get(h) * eps.exp());
            let s = params::held_sensitivity(&truth, h, tie_km);
            let moved: [f64; NP] = std::array::from_fn(|k| values[k] * (s[k] * eps).exp());
            let along = worst(&at, &derivatives(&params::with(start, &moved, tie_km)));
            let alone = worst(&at, &derivatives(&params::with(start, &values, tie_km)));
            assert!(along < 1e-6, "{h:?} (km tied {tie_km}): {along:e}");
            if h != Param::Mr {
                assert!(alone > 1e-6, "{h:?} (km tied {tie_km}): {alone:e}");
            }
        }
    }
}

/// An excitation run of `rig` from hanging at rest as `rip-rt excite` drives it (module
/// docs of [`crate::excitation`]), through the rig's encoders and angle noise.
pub(crate) fn rig_run(rig: &crate::rig::Rig, signal: Signal, seed: u64) -> LogData {
    rig_run_kicked(rig, signal, seed, 0.3)
}

/// [`rig_run`] with a free swing's kick of `kick` seconds.
fn rig_run_kicked(rig: &crate::rig::Rig, signal: Signal, seed: u64, kick: f64) -> LogData {
    let ts = 0.01;
    let plant = Plant::new(rig.params).unwrap();
    let mut settings = ExcitationSettings::new(signal);
    if signal == Signal::FreeSwing {
        settings.duration = 60.0;
        settings.amplitude = 6.0;
        settings.kick = kick;
    } else {
        settings.duration = 30.0;
        settings.amplitude = 2.5;
    }
    settings.seed = seed;
    let mut exc = Excitation::new(settings, ts).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let q = rig
        .encoder_counts
        .map(|c| std::f64::consts::TAU / f64::from(c));
    let noise = rig
        .noise_std
        .map(|s| Normal::new(0.0, s.max(1e-12)).unwrap());
    let mut x = State::new(0.0, 0.0, std::f64::consts::PI, 0.0);
    let n = (settings.duration / ts).round() as usize;
    let (mut u, mut y) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for k in 0..n {
        let meas: [f64; 2] = std::array::from_fn(|j| {
            let a = x[2 * j];
            (a / q[j]).round() * q[j] + noise[j].sample(&mut rng)
        });
        let e = exc.value(k as f64 * ts);
        let uk = exc.command(e, meas[0], 0.0, 2.0).clamp(-10.0, 10.0);
        y.push(meas);
        u.push(uk);
        plant.advance(&mut x, uk, 0.0, ts, 10);
    }
    LogData { ts, u, y }
}

/// The start set a lab file gives: the measured mp, Lp, mr, Lr, Rm, km over the QUBE-Servo 2
/// values, links as uniform rods.
pub(crate) fn lab_start(truth: &FurutaParams) -> FurutaParams {
    let mut p = FurutaParams::qube_servo2();
    p.mp = truth.mp;
    p.lp = truth.lp;
    p.mr = truth.mr;
    p.lr = truth.lr;
    p.rm = truth.rm;
    p.km = truth.km;
    p.kt = truth.km;
    p.jp = p.mp * p.lp * p.lp / 12.0;
    p.jr = p.mr * p.lr * p.lr / 12.0;
    p
}

/// Largest relative error over the non-structural-zero entries of the continuous [A B], and
/// the relative error of the unstable eigenvalue.
pub(crate) fn linear_error(got: &FurutaParams, truth: &FurutaParams) -> (f64, f64, [f64; 10]) {
    let (a, b) = Plant::new(*got).unwrap().linearize_upright();
    let (a0, b0) = Plant::new(*truth).unwrap().linearize_upright();
    let mut worst = 0.0f64;
    let mut each = [0.0; 10];
    let mut n = 0;
    for i in [1, 3] {
        for j in 0..5 {
            let (g, t) = if j < 4 {
                (a[(i, j)], a0[(i, j)])
            } else {
                (b[(i, 0)], b0[(i, 0)])
            };
            if t.abs() > 1e-12 {
                let rel = (g - t).abs() / t.abs();
                worst = worst.max(rel);
                each[n] = rel;
            }
            n += 1;
        }
    }
    let eig = |m: &Mat| {
        m.clone()
            .complex_eigenvalues()
            .iter()
            .map(|c| c.re)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let (l, l0) = (eig(&a), eig(&a0));
    (worst, (l - l0).abs() / l0, each)
}

/// The excitation the docs' rig path records: a chirp and a PRBS run of 30 s at 2.5 V, and a
/// free swing of 60 s after a kick of 6 V for 0.3 s (a wide swing, for the damping).
pub(crate) fn rig_logs(rig: &crate::rig::Rig, seed: u64) -> [LogData; 3] {
    [
        rig_run(rig, Signal::Chirp, 10 * seed + 1),
        rig_run(rig, Signal::Prbs, 10 * seed + 2),
        rig_run(rig, Signal::FreeSwing, 10 * seed + 3),
    ]
}

/// The `--kick` of the wider free swing a problem of the verdict asks for, if it asks for one.
fn advised_kick(problem: &str) -> Option<f64> {
    let rest = &problem[problem.find("swings wider")?..];
    let after = &rest[rest.find("--kick ")? + "--kick ".len()..];
    after.split_whitespace().next()?.parse().ok()
}

/// Of [`envelope_rigs`], how many at least are trusted from their lab file (with the verdict's
/// remedy where it asks for a wider free swing): 9 of the 10 measure trusted from the first
/// logs, the tenth (seed 4, a lightly damped pendulum) asks for the wider swing.
const MIN_TRUSTED_FROM_LAB: usize = 9;

/// The rigs of [`rigs_across_the_envelope_meet_the_bar_or_are_refused`]: eight of the shared
/// generator and both presets (2048-count encoders, 0.5 mrad of noise); at the small scale
/// (`RIPRS_TEST_SCALE`, [`envelope_rigs_at_scale`]) three of them.
fn envelope_rigs() -> Vec<crate::rig::Rig> {
    let mut rigs: Vec<_> = (1..=8u64).map(crate::rig::Rig::random).collect();
    // RIPRS_ENVELOPE_SEEDS=4,6 runs only those (to look into one rig).
    if let Ok(only) = std::env::var("RIPRS_ENVELOPE_SEEDS") {
        let only: Vec<u64> = only
            .split(',')
            .filter_map(|v| v.trim().parse().ok())
            .collect();
        rigs.retain(|r| only.contains(&r.seed));
        return rigs;
    }
    for (seed, params) in [
        (101, FurutaParams::paper()),
        (102, FurutaParams::qube_servo2()),
    ] {
        rigs.push(crate::rig::Rig {
            seed,
            params,
            encoder_counts: [2048, 2048],
            noise_std: [5e-4, 5e-4],
        });
    }
    rigs
}

/// [`envelope_rigs`] at this run's scale: all ten at the full one; at the small one seed 4 (a
/// lightly damped pendulum, the one the verdict sends back for a wider free swing), seed 1
/// and the QUBE-Servo 2 preset (102).
fn envelope_rigs_at_scale() -> Vec<crate::rig::Rig> {
    rip_test_scale::cases(envelope_rigs(), |r| [1, 4, 102].contains(&r.seed))
}

/// Rigs of the shared generator across the envelope and both presets: every trusted result,
/// from the lab file's values or from the default start, meets the bar (every
/// non-structural-zero entry of the continuous [A B] within 2 %, the pendulum-damping entries
/// included, the unstable eigenvalue within 1 %); a refusal names what to add or measure.
/// Prints the table of errors.
#[test]
fn rigs_across_the_envelope_meet_the_bar_or_are_refused() {
    let cancel = AtomicBool::new(false);
    let mut trusted_from_lab = Vec::new();
    let mut trusted_after_remedy = Vec::new();
    let rigs = envelope_rigs_at_scale();
    for rig in &rigs {
        let rig = rig.clone();
        let seed = rig.seed;
        let logs = rig_logs(&rig, seed);
        let names = vec!["chirp".into(), "prbs".into(), "free-swing".into()];
        let lab = IdentifyOptions {
            start: lab_start(&rig.params),
            fixed: vec!["Lr".into()],
            names: names.clone(),
            ..Default::default()
        };
        let default = IdentifyOptions {
            names,
            ..Default::default()
        };
        for (what, o) in [("lab", &lab), ("default", &default)] {
            let t0 = std::time::Instant::now();
            let r = match identify(&logs, o, &cancel) {
                Ok(r) => r,
                Err(e) => {
                    assert!(
                        what == "default" && e.to_string().contains("lab file"),
                        "{e}"
                    );
                    eprintln!("rig {seed} {what}: refused: {e}");
                    continue;
                }
            };
            let (worst, eig, each) = linear_error(&r.params, &rig.params);
            let (ad, bd) = Plant::new(rig.params)
                .unwrap()
                .linearize_discrete(&State::zeros(), 0.0, 0.01)
                .unwrap();
            let worst_d = (0..4)
                .flat_map(|i| (0..5).map(move |j| (i, j)))
                .map(|(i, j)| {
                    let (t, g) = if j < 4 {
                        (ad[(i, j)], r.ad[(i, j)])
                    } else {
                        (bd[(i, 0)], r.bd[(i, 0)])
                    };
                    if t.abs() > 1e-12 {
                        (g - t).abs() / t.abs()
                    } else {
                        0.0
                    }
                })
                .fold(0.0, f64::max);
            eprintln!(
                "rig {seed} {what}: {} [A B] {:.3} % (damping {:.3} %, its rse {:.2} %), \
                 eigenvalue {:.3} %, [A_d B_d] {:.3} %, {} starts, {:.1} s{}",
                if r.problems.is_empty() {
                    "trusted"
                } else {
                    "refused"
                },
                100.0 * worst,
                100.0 * each[3].max(each[8]),
                100.0 * r.linear_rse[2].max(r.linear_rse[6]),
                100.0 * eig,
                100.0 * worst_d,
                r.starts,
                t0.elapsed().as_secs_f64(),
                if r.problems.is_empty() {
                    String::new()
                } else {
                    format!(": {}", r.problems.join(" | "))
                }
            );
            if r.problems.is_empty() {
                assert!(
                    worst < 0.02 && eig < 0.01,
                    "rig {seed} {what}: trusted, [A B] {worst}, eigenvalue {eig}"
                );
                if what == "lab" {
                    trusted_from_lab.push(seed);
                }
            } else if let Some(kick) = (what == "lab")
                .then(|| r.problems.iter().find_map(|p| advised_kick(p)))
                .flatten()
            {
                // The verdict's remedy: the free swing it names, with a longer kick.
                let mut wider = logs.clone();
                wider[2] = rig_run_kicked(&rig, Signal::FreeSwing, 10 * seed + 4, kick);
                let again = identify(&wider, o, &cancel).unwrap();
                let (worst, eig, each) = linear_error(&again.params, &rig.params);
                eprintln!(
                    "rig {seed} lab, free swing kicked {kick} s: {} [A B] {:.3} % (damping {:.3} %, its \
                     rse {:.2} %), eigenvalue {:.3} %{}",
                    if again.problems.is_empty() {
                        "trusted"
                    } else {
                        "refused"
                    },
                    100.0 * worst,
                    100.0 * each[3].max(each[8]),
                    100.0 * again.linear_rse[2].max(again.linear_rse[6]),
                    100.0 * eig,
                    if again.problems.is_empty() {
                        String::new()
                    } else {
                        format!(": {}", again.problems.join(" | "))
                    }
                );
                if again.problems.is_empty() {
                    assert!(
                        worst < 0.02 && eig < 0.01,
                        "rig {seed}, wider swing: trusted, [A B] {worst}, eigenvalue {eig}"
                    );
                    trusted_after_remedy.push(seed);
                }
            }
        }
    }
    eprintln!("trusted from the lab file after the verdict's remedy: {trusted_after_remedy:?}");
    eprintln!("trusted from the lab file: {trusted_from_lab:?}");
    let filtered = std::env::var("RIPRS_ENVELOPE_SEEDS").is_ok();
    // As many misses at most as the full sweep allows.
    let allowed_misses = envelope_rigs().len() - MIN_TRUSTED_FROM_LAB;
    assert!(
        filtered || trusted_from_lab.len() + trusted_after_remedy.len() + allowed_misses >= rigs.len(),
        "trusted from the lab file: {trusted_from_lab:?}, after the remedy {trusted_after_remedy:?}"
    );
}

/// Monte Carlo check of the covariance: re-identifications of one rig from logs with new noise
/// (and the encoders' quantisation) each time, fixed seeds; the 95 % intervals of the
/// parameters reported identifiable hold the truth in at least 90 % of all (parameter, run)
/// pairs, and no parameter of the upright linearisation is ever reported not identifiable.
/// `RIPRS_COVERAGE_RUNS` sets the number of runs (by default 12 at the small scale,
/// `RIPRS_TEST_SCALE`, and 50 at the full one, the docs' figure).
#[test]
fn the_95_percent_intervals_cover_the_truth() {
    let runs: u64 = std::env::var("RIPRS_COVERAGE_RUNS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| rip_test_scale::size(12, 50));
    let truth_params = hidden();
    let truth = Plant::new(truth_params).unwrap();
    let cancel = AtomicBool::new(false);
    let (mut covered, mut pairs) = (0usize, 0usize);
    let mut per_param = [(0usize, 0usize); NP];
    for run_seed in 0..runs {
        let logs = [
            run(&truth, Signal::Chirp, 20.0, 1000 + 3 * run_seed),
            run(&truth, Signal::Prbs, 20.0, 1001 + 3 * run_seed),
            run(&truth, Signal::FreeSwing, 20.0, 1002 + 3 * run_seed),
        ];
        let o = IdentifyOptions {
            start: hidden(),
            ..Default::default()
        };
        let r = identify(&logs, &o, &cancel).unwrap();
        for name in LINEAR.map(Param::name) {
            assert!(
                !r.not_identifiable.contains(&name) && !r.at_bounds.contains(&name),
                "run {run_seed}: {name} {:?} {:?}",
                r.not_identifiable,
                r.at_bounds
            );
        }
        for k in 0..NP {
            if r.not_identifiable.contains(&FREE[k].name()) || r.at_bounds.contains(&FREE[k].name())
            {
                continue;
            }
            let se = r.covariance[k * NP + k].sqrt();
            let z = (r.values[k].ln() - params::get(&truth_params, k).ln()) / se;
            let inside = z.abs() <= 1.96;
            covered += usize::from(inside);
            pairs += 1;
            per_param[k].0 += usize::from(inside);
            per_param[k].1 += 1;
        }
    }
    let coverage = covered as f64 / pairs as f64;
    eprintln!(
        "coverage {covered}/{pairs} = {:.1} % over {runs} runs; per parameter {:?}",
        100.0 * coverage,
        FREE.iter().zip(per_param).collect::<Vec<_>>()
    );
    assert!(coverage >= 0.9, "coverage {coverage}");
}

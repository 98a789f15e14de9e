//! Tuning on the issue's rigs and on rigs drawn across the envelope.

use rip_core::preflight::{self, Verdict};
use rip_core::rig::{NamedRig, Rig};
use rip_core::spec::{ControllerKind, Spec};
use rip_core::tune::{assess, tune, Bar};

/// The issue's table of rigs but the paper preset (which keeps its Tab. 1), by label.
pub fn issue_rigs() -> Vec<(&'static str, String)> {
    NamedRig::ALL
        .into_iter()
        .filter(|r| *r != NamedRig::Paper)
        .map(|r| (r.label(), r.to_toml()))
        .collect()
}

/// The generated rigs, fixed before any was run: `Rig::random(1..=16)`.
const SEEDS: std::ops::RangeInclusive<u64> = 1..=16;

/// The generated rigs at this run's scale (`RIPRS_TEST_SCALE`): all of [`SEEDS`] at the full
/// one; at the small one seed 9 (the known miss, [`KNOWN_MISSES`]) and seed 14.
fn seeds() -> Vec<u64> {
    rip_test_scale::cases(SEEDS, |s| [9, 14].contains(s))
}

/// Generated rigs on which some tuned controller still misses the bar for a reason that is
/// neither its sensor nor a fall the pre-flight refuses (each named with what it misses).
/// The test asserts that they still miss, so that a fix shows here.
const KNOWN_MISSES: [(u64, &str); 1] = [(
    9,
    "a weak motor (k_t 0.020, R_m 9.9 ohm) against arm Coulomb friction worth 2.2 V and \
         a 0.7 V dead zone (24 % of the 12 V bound): the tuned LQR and LQG balance in limit \
         cycles of 0.13 and 0.06 rad (LQR's is the friction's: 0.016 rad on the rig without \
         it); the MPC falls on the 1 rad step and the pre-flight refuses it, though it \
         balances within the bar at rest, on a 0.5 rad step, or at 16 V (diagnose_seed9)",
)];

/// Whether an LQR with any of a range of weights balances the rig's model from its start:
/// the independent evidence that it can be balanced at its voltage bound.
fn some_lqr_balances(spec: &Spec) -> bool {
    let plant = spec.plant().unwrap();
    [0.1, 1.0, 10.0, 100.0].into_iter().any(|r| {
        let mut s = spec.clone();
        s.lqr.R = r;
        s.lqr.integral_weight = 0.0;
        let d = s.design(0.01).unwrap();
        let mut c = d.controller(ControllerKind::Lqr).unwrap();
        let run = rip_core::simulate(&plant, c.as_mut(), &s.sim_config(0.01, 5)).unwrap();
        !run.fell && !run.diverged
    })
}

/// The tuned design of `spec`'s controller `kind` re-run, on other noise seeds than the
/// tuning's, with the finest sensor of the envelope (8192 counts, 0.1 mrad noise): whether it
/// then meets the steady-state bar (the check behind a "the sensor's" verdict).
fn meets_bar_with_a_fine_sensor(spec: &Spec, kind: ControllerKind, bar: &Bar) -> bool {
    let mut s = spec.clone();
    s.sensor.encoder_counts = [8192, 8192];
    s.sensor.noise_std = [1e-4, 1e-4];
    let d = s.design(0.01).unwrap();
    let plant = s.plant().unwrap();
    [21, 22].into_iter().all(|seed| {
        let mut c = d.controller(kind).unwrap();
        let run = rip_core::simulate(&plant, c.as_mut(), &s.sim_config(0.01, seed)).unwrap();
        let (pp, alpha, offset) = rip_core::tune::steady_state(&run, bar.window);
        !run.fell && pp <= bar.arm_peak_to_peak && alpha <= bar.pendulum && offset <= bar.offset
    })
}

/// How one rig came out: `Ok` with a line per controller, or `Err` with what is wrong.
type Judged = Result<Vec<String>, String>;

/// Tunes the rig of `text` and judges each controller: meets the bar, refused by the
/// pre-flight, or short of the bar through its sensor (checked with a fine one).
fn judge(name: &str, text: &str, bar: &Bar) -> Judged {
    let spec = Spec::parse(text).unwrap();
    let t = tune(&spec, 0.01, bar).unwrap();
    let design = t.spec.design(0.01).unwrap();
    let balanceable = some_lqr_balances(&spec);
    let mut lines = Vec::new();
    let mut bad = Vec::new();
    for a in &t.assessments {
        let verdict = if a.balances(bar) && !a.saturated {
            "meets the bar".to_string()
        } else if a.fell || !balanceable {
            let report = preflight::run(&preflight::Input {
                design: &design,
                controller: a.kind,
                rig_file: None,
                arm_limit: Some(3.0),
                swing_up: false,
            });
            if !report.refused() {
                bad.push(format!(
                    "{:?} falls but the pre-flight passes it: {report}",
                    a.kind
                ));
            }
            format!("refused by the pre-flight: {report}")
        } else if a.sensor_limited(bar) && !a.saturated {
            if !meets_bar_with_a_fine_sensor(&t.spec, a.kind, bar) {
                bad.push(format!(
                    "{:?}: said to be the sensor's, but misses the bar with a fine sensor too",
                    a.kind
                ));
            }
            format!(
                "misses the bar through the sensor (exact: {:?})",
                a.exact_sensor
            )
        } else {
            bad.push(format!("{:?} misses the bar: {a:?}", a.kind));
            "misses".to_string()
        };
        let m = &a.margins;
        lines.push(format!(
            "{name}: {:?} p-p {:.3} |alpha| {:.3} offset {:.3} peak {:.1} V | GM {:.1}/{:.1} dB \
             PM {:.0} deg disk {:.2} ({}) | q {}: {verdict}",
            a.kind,
            a.arm_peak_to_peak,
            a.pendulum,
            a.offset,
            a.peak_voltage,
            m.gain_margin_db,
            m.gain_reduction_db,
            m.phase_margin_deg,
            m.disk_margin,
            if a.margins_ok(bar) {
                "margins met"
            } else {
                "margins short"
            },
            t.weights.recovery,
        ));
    }
    if bad.is_empty() {
        Ok(lines)
    } else {
        Err(format!("{}\n  {}", lines.join("\n"), bad.join("\n  ")))
    }
}

#[test]
fn tuned_controllers_meet_the_bar_on_the_issue_rigs_and_generated_rigs() {
    let bar = Bar::default();
    let mut rigs: Vec<(String, String, Option<u64>)> = issue_rigs()
        .into_iter()
        .map(|(n, t)| (n.to_string(), t, None))
        .collect();
    for seed in seeds() {
        rigs.push((
            format!("generated rig {seed}"),
            Rig::random(seed).to_toml(),
            Some(seed),
        ));
    }
    // Two at a time: the machines this runs on have two cores.
    let results: Vec<(String, Option<u64>, Judged)> = std::thread::scope(|scope| {
        let chunks: Vec<_> = rigs.chunks(rigs.len().div_ceil(2)).collect();
        let handles: Vec<_> = chunks
            .into_iter()
            .map(|chunk| {
                scope.spawn(move || {
                    chunk
                        .iter()
                        .map(|(name, text, seed)| (name.clone(), *seed, judge(name, text, &bar)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    let mut failures = Vec::new();
    for (name, seed, r) in &results {
        let known = seed.and_then(|s| KNOWN_MISSES.iter().find(|(k, _)| *k == s));
        match (r, known) {
            (Ok(lines), None) => println!("{}", lines.join("\n")),
            (Err(e), Some((_, why))) => println!("{e}\n  (known: {why})"),
            (Err(e), None) => failures.push(e.clone()),
            (Ok(_), Some(_)) => failures.push(format!(
                "{name} now meets the bar: drop it from KNOWN_MISSES"
            )),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_rig_whose_controller_falls_is_refused_by_the_preflight() {
    // Seed 9: a weak motor (k_t 0.020, R_m 9.9 Ω) against arm friction worth 2.2 V.
    let spec = Spec::parse(&Rig::random(9).to_toml()).unwrap();
    let t = tune(&spec, 0.01, &Bar::default()).unwrap();
    let falls = t
        .assessments
        .iter()
        .find(|a| a.kind == ControllerKind::Mpc)
        .unwrap();
    assert!(falls.fell, "{falls:?}");
    let design = t.spec.design(0.01).unwrap();
    let report = preflight::run(&preflight::Input {
        design: &design,
        controller: falls.kind,
        rig_file: None,
        arm_limit: Some(3.0),
        swing_up: false,
    });
    let p = report.finding("prediction").unwrap();
    assert_eq!(p.verdict, Verdict::Refuse, "{report}");
    assert!(p.message.contains("predicted to fall"), "{}", p.message);
    // The refusal is the 1 rad step's at 12 V, not the rig's: 2.86 V of its 12 go to the dead
    // zone and the arm's Coulomb friction, yet the same MPC balances it within the bar at rest.
    let params = spec.plant.params();
    let lost = params.vd + params.cr * params.rm / params.kt;
    assert!((2.7..3.0).contains(&lost), "{lost}");
    let mut at_rest = t.spec.clone();
    at_rest.reference.arm_step = 0.0;
    let d = at_rest.design(0.01).unwrap();
    let plant = at_rest.plant().unwrap();
    let mut mpc = d.controller(ControllerKind::Mpc).unwrap();
    let run = rip_core::simulate(&plant, mpc.as_mut(), &at_rest.sim_config(0.01, 11)).unwrap();
    let (pp, alpha, offset) = rip_core::tune::steady_state(&run, 3.0);
    assert!(
        !run.fell && pp <= 0.05 && alpha <= 0.02 && offset <= 0.02,
        "{pp} {alpha} {offset}"
    );
}

/// Steady state `(fell, arm peak-to-peak)` of `spec`'s LQR on its rig, noise seed 11.
fn lqr_steady(spec: &Spec) -> (bool, f64) {
    let d = spec.design(0.01).unwrap();
    let plant = spec.plant().unwrap();
    let mut c = d.controller(ControllerKind::Lqr).unwrap();
    let run = rip_core::simulate(&plant, c.as_mut(), &spec.sim_config(0.01, 11)).unwrap();
    (
        run.fell || run.diverged,
        rip_core::tune::steady_state(&run, 3.0).0,
    )
}

#[test]
fn seed_9s_limit_cycle_is_its_arm_friction_read_through_the_sensor() {
    // Generated rig 9's LQR (the file's weights, R x 3) holds a limit cycle outside the bar.
    // Removing one cause at a time: not the voltage bound (at 20 V it stays), not the dead
    // zone; the arm's Coulomb friction (without it the same design meets the bar) as the
    // compensation sees it through the sensor (with exact angles it meets the bar too): the
    // friction feed-forward (2.17 V each way) follows the sign of the arm-rate estimate, and
    // near rest that sign is the quantisation and noise of the 2384-count arm encoder.
    use rip_core::spec::Param;
    let base = Spec::parse(&Rig::random(9).to_toml()).unwrap();
    let mut spec = base.clone();
    spec.lqr.R *= 3.0;
    spec.mpc.input_rate_weights[0] *= 3f64.sqrt();
    let bar = Bar::default().arm_peak_to_peak;
    let cycle = |s: &Spec| {
        let (fell, pp) = lqr_steady(s);
        assert!(!fell);
        pp
    };
    assert!(cycle(&spec) > 2.0 * bar, "{}", cycle(&spec));
    let mut wide = spec.clone();
    wide.set_input_bounds(-20.0, 20.0);
    assert!(cycle(&wide) > 2.0 * bar, "{}", cycle(&wide));
    let mut no_dead_zone = spec.clone();
    no_dead_zone
        .plant
        .set(Param::from_name("Vd").unwrap(), Some(0.0));
    assert!(cycle(&no_dead_zone) > 2.0 * bar, "{}", cycle(&no_dead_zone));
    let mut no_friction = spec.clone();
    no_friction
        .plant
        .set(Param::from_name("Cr").unwrap(), Some(0.0));
    assert!(cycle(&no_friction) <= bar, "{}", cycle(&no_friction));
    let mut exact = spec.clone();
    exact.sensor.encoder_counts = [1 << 24; 2];
    exact.sensor.noise_std = [0.0; 2];
    assert!(cycle(&exact) <= bar, "{}", cycle(&exact));
}

#[test]
#[ignore]
fn explore() {
    let bar = Bar::default();
    let mut rigs = issue_rigs()
        .into_iter()
        .map(|(n, t)| (n.to_string(), t))
        .collect::<Vec<_>>();
    let seeds: Vec<u64> = std::env::var("SEEDS")
        .map(|v| v.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or_else(|_| (1..=10).collect());
    if std::env::var("SEEDS").is_ok() {
        rigs.clear();
    }
    for seed in seeds {
        println!("random {seed}: {:?}", Rig::random(seed).params);
        rigs.push((format!("random {seed}"), Rig::random(seed).to_toml()));
    }
    for (name, text) in rigs {
        let spec = Spec::parse(&text).unwrap();
        let t0 = std::time::Instant::now();
        for a in assess(&spec, 0.01, &bar).unwrap() {
            println!(
                "{name:22} file {:?}: pp {:.3} alpha {:.3} off {:.3} fell {} sat {} peak {:.1} gm {:.1}/{:.1} pm {:.0} disk {:.2}",
                a.kind, a.arm_peak_to_peak, a.pendulum, a.offset, a.fell, a.saturated, a.peak_voltage,
                a.margins.gain_margin_db, a.margins.gain_reduction_db, a.margins.phase_margin_deg, a.margins.disk_margin
            );
        }
        let t = tune(&spec, 0.01, &bar).unwrap();
        println!(
            "{name:22} tuned {:?} works {} tried {} in {:.1?}",
            t.weights,
            t.works,
            t.tried,
            t0.elapsed()
        );
        for a in &t.assessments {
            println!(
                "{name:22}   {:?}: pp {:.3} alpha {:.3} off {:.3} fell {} sat {} peak {:.1} gm {:.1}/{:.1} pm {:.0} disk {:.2}",
                a.kind, a.arm_peak_to_peak, a.pendulum, a.offset, a.fell, a.saturated, a.peak_voltage,
                a.margins.gain_margin_db, a.margins.gain_reduction_db, a.margins.phase_margin_deg, a.margins.disk_margin
            );
        }
    }
}

#[test]
#[ignore]
fn explore_kalman() {
    for (name, text) in issue_rigs() {
        let base = Spec::parse(&text).unwrap();
        for g in [1.0] {
            for mn in [0.1, 0.03, 0.01, 0.003, 0.001] {
                let mut spec = base.clone();
                spec.kalman.disturbance_gain *= g;
                spec.kalman.measurement_noise = [mn, mn];
                let d = spec.design(0.01).unwrap();
                let l = d.margins(rip_core::spec::ControllerKind::Lqg).unwrap();
                let m = d.margins(rip_core::spec::ControllerKind::Mpc).unwrap();
                println!("{name:20} g x{g} mn {mn}: LQG gm {:.1}/{:.1} pm {:.0} disk {:.2} | MPC gm {:.1}/{:.1} pm {:.0} disk {:.2}",
                    l.gain_margin_db, l.gain_reduction_db, l.phase_margin_deg, l.disk_margin,
                    m.gain_margin_db, m.gain_reduction_db, m.phase_margin_deg, m.disk_margin);
            }
        }
    }
}

#[test]
#[ignore]
fn diagnose() {
    let seed: u64 = std::env::var("SEED").unwrap().parse().unwrap();
    let rig = Rig::random(seed);
    println!("counts {:?} noise {:?}", rig.encoder_counts, rig.noise_std);
    let base = Spec::parse(&rig.to_toml()).unwrap();
    let t = tune(&base, 0.01, &Bar::default()).unwrap();
    println!("tuned {:?}", t.weights);
    type Variant = (&'static str, Box<dyn Fn(&mut Spec)>);
    let variants: Vec<Variant> = vec![
        ("tuned", Box::new(|_s: &mut Spec| {})),
        (
            "no noise",
            Box::new(|s: &mut Spec| s.sensor.noise_std = [0.0, 0.0]),
        ),
        (
            "no quant",
            Box::new(|s: &mut Spec| s.sensor.encoder_counts = [1 << 30, 1 << 30]),
        ),
        (
            "no noise/quant",
            Box::new(|s: &mut Spec| {
                s.sensor.noise_std = [0.0, 0.0];
                s.sensor.encoder_counts = [1 << 30, 1 << 30];
            }),
        ),
        (
            "smooth plant",
            Box::new(|s: &mut Spec| {
                for n in ["Vd", "Cr", "Cp"] {
                    s.plant
                        .set(rip_core::spec::Param::from_name(n).unwrap(), Some(0.0));
                }
            }),
        ),
        ("20 s", Box::new(|s: &mut Spec| s.reference.duration = 20.0)),
    ];
    for (name, f) in variants {
        let mut s = t.spec.clone();
        f(&mut s);
        let Ok(d) = s.design(0.01) else {
            println!("{name}: design failed");
            continue;
        };
        let plant = s.plant().unwrap();
        for kind in ControllerKind::ALL {
            let mut c = d.controller(kind).unwrap();
            let run = rip_core::simulate(&plant, c.as_mut(), &s.sim_config(0.01, 11)).unwrap();
            let ss = rip_core::tune::steady_state(&run, 3.0);
            let n = run.len();
            let tail: Vec<String> = (0..n)
                .step_by(25)
                .filter(|&k| run.t[k] >= run.t[n - 1] - 4.0)
                .map(|k| format!("{:.3}", run.x[k][0]))
                .collect();
            println!(
                "{name:14} {kind:?}: pp {:.3} a {:.3} off {:.3} fell {} | {}",
                ss.0,
                ss.1,
                ss.2,
                run.fell,
                tail.join(" ")
            );
        }
    }
}

#[test]
#[ignore]
fn grid() {
    use rip_core::tune::Weights;
    let seed: u64 = std::env::var("SEED").unwrap().parse().unwrap();
    let base = Spec::parse(&Rig::random(seed).to_toml()).unwrap();
    let bar = Bar::default();
    for arm in [1.0, 4.0, 16.0, 64.0, 256.0] {
        for input in [1.0, 3.0, 10.0, 30.0] {
            for mn in [10.0, 1.0, 0.1, 0.01] {
                let w = Weights {
                    arm,
                    pendulum: 1.0,
                    input,
                    integral_weight: 0.0,
                    measurement_noise: mn,
                    recovery: 1.0,
                };
                let s = w.apply(&base);
                let Ok(a) = assess(&s, 0.01, &bar) else {
                    continue;
                };
                let line: Vec<String> = a
                    .iter()
                    .map(|a| {
                        format!(
                            "{:?} pp {:.3} a {:.3} {}{} disk {:.2}",
                            a.kind,
                            a.arm_peak_to_peak,
                            a.pendulum,
                            if a.fell { "F" } else { "" },
                            if a.saturated { "S" } else { "" },
                            a.margins.disk_margin
                        )
                    })
                    .collect();
                println!("arm {arm:5} R {input:4} mn {mn:5}: {}", line.join(" | "));
            }
        }
    }
}

/// For the generated rigs of `SEEDS` (default 3,4,5,8,14,15,16), every candidate whose
/// recovered margins all meet the bar, and how it misses the steady-state bar or the
/// voltage bound: why the margin-meeting weights are not what `tune` keeps there.
#[test]
#[ignore]
fn margin_meeting_candidates() {
    use rip_core::tune::{candidates, choose_recovery, Weights};
    let bar = Bar::default();
    let seeds: Vec<u64> = std::env::var("SEEDS")
        .map(|v| v.split(',').map(|x| x.parse().unwrap()).collect())
        .unwrap_or_else(|_| vec![3, 4, 5, 8, 14, 15, 16]);
    for seed in seeds {
        let spec = Spec::parse(&Rig::random(seed).to_toml()).unwrap();
        let mut found = 0;
        for w in std::iter::once(Weights::FILE).chain(candidates(&spec)) {
            let w = choose_recovery(&spec, w, 0.01, &bar);
            let s = w.apply(&spec);
            let Ok(a) = assess(&s, 0.01, &bar) else {
                continue;
            };
            if !a.iter().all(|a| a.margins_ok(&bar)) {
                continue;
            }
            found += 1;
            let line: Vec<String> = a
                .iter()
                .map(|a| {
                    format!(
                        "{:?} pp {:.3} a {:.3} off {:.3}{}{}",
                        a.kind,
                        a.arm_peak_to_peak,
                        a.pendulum,
                        a.offset,
                        if a.fell { " FELL" } else { "" },
                        if a.saturated { " SAT" } else { "" }
                    )
                })
                .collect();
            println!("seed {seed} {w:?}: {}", line.join(" | "));
        }
        println!("seed {seed}: {found} candidates meet every margin");
    }
}

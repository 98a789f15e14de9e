//! The balance bars of tuning (`rip_core::tune::Bar`), asserted on the presets, the named
//! rigs and rigs drawn across the envelope: every controller the tuning says works meets its
//! rig's bar when simulated here, the compensation's errors and the stiction applied by hand;
//! of every other the tuning says what it misses and the pre-flight refuses it with the same
//! words through the record; in the full tier, at most 3 of the 16 generated rigs have a
//! controller refused (the bar). How often the verdict holds on noise seeds the
//! tuning never used is printed.

use std::path::Path;

use rip_core::preflight::{self, Verdict};
use rip_core::rig::{NamedRig, Rig};
use rip_core::spec::{ControllerKind, Param, Spec};
use rip_core::tune::{self, tune, Bar, OFF_COMPENSATION};

/// The generated rigs, fixed before any was run: `Rig::random(1..=16)`.
const SEEDS: std::ops::RangeInclusive<u64> = 1..=16;

/// Noise seeds the tuning never used: how often its verdict holds there is printed.
const UNSEEN_SEEDS: [u64; 2] = [21, 22];

/// The generated rigs at this run's scale (`RIPRS_TEST_SCALE`): all of [`SEEDS`] at the full
/// one; at the small one seed 9 (a weak motor against 2.2 V of friction) and seed 12 (a
/// coarse, noisy sensor).
fn seeds() -> Vec<u64> {
    rip_test_scale::cases(SEEDS, |s| [9, 12].contains(s))
}

/// The presets and the named rigs (NamedRig::ALL, the paper preset among them), by label.
fn named_rigs() -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = NamedRig::ALL
        .into_iter()
        .map(|r| (r.label().to_string(), r.to_toml()))
        .collect();
    out.push((
        "qube_servo2 preset".to_string(),
        "[plant]\npreset = \"qube_servo2\"\n".to_string(),
    ));
    out
}

/// The sensor's floor measured here, apart from `Bar::for_rig`: the file's LQR on the rig
/// with its dead zone, Coulomb friction and stiction taken out by hand.
fn floor(spec: &Spec) -> f64 {
    let mut s = spec.clone();
    for name in ["Vd", "Cr", "Cp"] {
        s.plant.set(Param::from_name(name).unwrap(), Some(0.0));
    }
    s.plant.arm_breakaway = None;
    s.compensation.enabled = false;
    let d = s.design(0.01).unwrap();
    let plant = s.plant().unwrap();
    let mut worst = 0.0f64;
    for seed in tune::SEEDS {
        let mut c = d.controller(ControllerKind::Lqr).unwrap();
        let run = rip_core::simulate(&plant, c.as_mut(), &s.sim_config(0.01, seed)).unwrap();
        if run.fell {
            return f64::INFINITY;
        }
        worst = worst.max(tune::steady_state(&run, 3.0).0);
    }
    worst
}

/// `spec` with its compensation `factor` times the plant's dead zone and arm friction and the
/// arm's breakaway torque twice its Coulomb friction: the bar's rig written out here, apart
/// from `tune::off_compensation`.
fn compensation_off(spec: &Spec, factor: f64) -> Spec {
    let p = spec.plant.params();
    let mut s = spec.clone();
    s.compensation.dead_zone = Some(factor * p.vd);
    s.compensation.arm_friction = Some(factor * p.cr);
    if p.cr > 0.0 {
        s.plant.arm_breakaway = Some(2.0 * p.cr);
    }
    s
}

/// Whether `kind` of `spec` meets `bar` on the noise `seeds`, with the compensation exact and
/// 0.7 and 1.3 times the plant's; `Err` says what it missed.
fn meets_bar(spec: &Spec, kind: ControllerKind, bar: &Bar, seeds: &[u64]) -> Result<(), String> {
    let d = spec.design(0.01).unwrap();
    let m = d.margins(kind).unwrap();
    if !bar.margins_ok(kind, &m) {
        return Err(format!("margins {m:?}"));
    }
    let plant = spec.plant().unwrap();
    for &seed in seeds {
        let mut c = d.controller(kind).unwrap();
        let run = rip_core::simulate(&plant, c.as_mut(), &spec.sim_config(0.01, seed)).unwrap();
        let (pp, alpha, offset) = tune::steady_state(&run, bar.window);
        if run.fell || pp > bar.arm_peak_to_peak || alpha > bar.pendulum || offset > bar.offset {
            return Err(format!(
                "seed {seed}: fell {} p-p {pp:.3} |alpha| {alpha:.3} offset {offset:.3}",
                run.fell
            ));
        }
    }
    let p = spec.plant.params();
    if p.vd == 0.0 && p.cr == 0.0 {
        return Ok(());
    }
    for e in [-OFF_COMPENSATION, OFF_COMPENSATION] {
        let off = compensation_off(spec, 1.0 + e);
        let d = off.design(0.01).unwrap();
        let plant = off.plant().unwrap();
        for &seed in seeds {
            let mut c = d.controller(kind).unwrap();
            let run = rip_core::simulate(&plant, c.as_mut(), &off.sim_config(0.01, seed)).unwrap();
            let pp = tune::steady_state(&run, bar.window).0;
            if run.fell || pp > bar.off_limit(kind) {
                return Err(format!(
                    "compensation x{:.1}, seed {seed}: fell {} p-p {pp:.3}",
                    1.0 + e,
                    run.fell
                ));
            }
        }
    }
    Ok(())
}

/// The pre-flight's prediction finding for `kind` of the tuned file written with its record
/// in `dir`.
fn preflight_with_record(t: &tune::Tuned, kind: ControllerKind, dir: &Path) -> preflight::Finding {
    let file = dir.join("tuned.toml");
    std::fs::write(&file, t.spec.to_toml()).unwrap();
    let record = tune::record(t, 0.01).unwrap();
    std::fs::write(preflight::tune_record_path(&file), record.to_toml()).unwrap();
    let design = t.spec.design(0.01).unwrap();
    let report = preflight::run(&preflight::Input {
        design: &design,
        controller: kind,
        rig_file: Some(&file),
        arm_limit: Some(3.0),
        swing_up: false,
    });
    report.finding("prediction").unwrap().clone()
}

/// How one rig came out: the table's lines, whether a controller is short of the bar, what
/// is wrong (empty when nothing is), and of the controllers that work, how many also meet the
/// bar on [`UNSEEN_SEEDS`] and how many were checked there.
struct Judged {
    lines: Vec<String>,
    short: bool,
    wrong: Vec<String>,
    unseen: (usize, usize),
}

/// Tunes the rig of `text` and checks each controller against its rig's bar (module docs).
fn judge(name: &str, text: &str) -> Judged {
    let spec = Spec::parse(text).unwrap();
    let t = tune(&spec, 0.01).unwrap();
    let bar = t.bar;
    let mut out = Judged {
        lines: Vec::new(),
        short: false,
        wrong: Vec::new(),
        unseen: (0, 0),
    };
    let f = floor(&spec);
    let expected = if f.is_finite() {
        (2.0 * f).max(0.05)
    } else {
        0.05
    };
    if (bar.arm_peak_to_peak - expected).abs() > 1e-12 {
        out.wrong.push(format!(
            "{name}: the bar {:.4} is not max(0.05, 2 x the floor {f:.4})",
            bar.arm_peak_to_peak
        ));
    }
    let dir = std::env::temp_dir().join(format!(
        "riprs-tune-rigs-{}-{}",
        std::process::id(),
        name.replace([' ', ',', '.'], "_")
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let shortfalls = t.shortfalls();
    for a in &t.assessments {
        let shortfall = shortfalls.iter().find(|(k, _)| *k == a.kind);
        let verdict = match shortfall {
            None => {
                if let Err(e) = meets_bar(&t.spec, a.kind, &bar, &tune::SEEDS) {
                    out.wrong.push(format!(
                        "{name}: {:?} said to work, but simulated here: {e}",
                        a.kind
                    ));
                }
                out.unseen.1 += 1;
                match meets_bar(&t.spec, a.kind, &bar, &UNSEEN_SEEDS) {
                    Ok(()) => {
                        out.unseen.0 += 1;
                        "meets the bar".to_string()
                    }
                    Err(e) => format!("meets the bar; on unseen seeds: {e}"),
                }
            }
            Some((_, why)) => {
                out.short = true;
                // Refused by the pre-flight, with the reason the tuning stored.
                let p = preflight_with_record(&t, a.kind, &dir);
                if p.verdict != Verdict::Refuse || (!a.fell && !p.message.contains(why.as_str())) {
                    out.wrong.push(format!(
                        "{name}: {:?} short of the bar ({why}) but the pre-flight says: {} {}",
                        a.kind,
                        p.verdict.name(),
                        p.message
                    ));
                }
                format!("short: {why}")
            }
        };
        let m = &a.margins;
        let off = a.off_compensation.map_or("-".to_string(), |o| {
            let (falls, runs) = o.fall_check;
            if o.fell {
                "falls".to_string()
            } else if falls > 0 {
                format!("falls on {falls} of {runs} further runs")
            } else {
                format!("{:.3}", o.arm_peak_to_peak)
            }
        });
        out.lines.push(format!(
            "{name} | {:?} | {:.3} / {:.3} | {:.3} | {:.3} | {off} | {:.1}/{:.1} dB {:.0} deg | {:.2} | {verdict}",
            a.kind,
            a.arm_peak_to_peak,
            bar.arm_peak_to_peak,
            a.pendulum,
            a.offset,
            m.gain_margin_db,
            m.gain_reduction_db,
            m.phase_margin_deg,
            m.disk_margin,
        ));
    }
    std::fs::remove_dir_all(&dir).ok();
    out
}

/// How often the controllers that work also met the bar on [`UNSEEN_SEEDS`].
fn print_unseen(judged: &[Judged]) {
    let (met, of) = judged
        .iter()
        .fold((0, 0), |(m, o), j| (m + j.unseen.0, o + j.unseen.1));
    println!(
        "on unseen noise seeds {UNSEEN_SEEDS:?}: {met} of {of} working controllers met the bar"
    );
}

/// Tunes `rigs` two at a time (the machines this runs on have two cores).
fn judge_all(rigs: &[(String, String)]) -> Vec<Judged> {
    std::thread::scope(|scope| {
        let chunks: Vec<_> = rigs.chunks(rigs.len().div_ceil(2)).collect();
        let handles: Vec<_> = chunks
            .into_iter()
            .map(|chunk| {
                scope.spawn(move || {
                    chunk
                        .iter()
                        .map(|(name, text)| judge(name, text))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    })
}

#[test]
fn tuned_controllers_meet_the_bar_or_say_what_they_miss_on_the_presets_and_named_rigs() {
    let judged = judge_all(&named_rigs());
    let mut wrong = Vec::new();
    for j in &judged {
        println!("{}", j.lines.join("\n"));
        wrong.extend(j.wrong.iter().cloned());
    }
    print_unseen(&judged);
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn tuned_controllers_meet_the_bar_or_say_what_they_miss_on_generated_rigs() {
    let rigs: Vec<(String, String)> = seeds()
        .into_iter()
        .map(|s| (format!("generated rig {s}"), Rig::random(s).to_toml()))
        .collect();
    let judged = judge_all(&rigs);
    let mut wrong = Vec::new();
    let mut short = 0;
    for j in &judged {
        println!("{}", j.lines.join("\n"));
        wrong.extend(j.wrong.iter().cloned());
        short += usize::from(j.short);
    }
    println!(
        "{short} of {} generated rigs have a controller short of the bar",
        rigs.len()
    );
    print_unseen(&judged);
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // The bar on the whole set: at most 3 of the 16 rigs refused a controller. The
    // pull-request tier's two rigs are the two known hard ones, so only the whole set counts.
    if rip_test_scale::full() {
        assert!(
            short <= 3,
            "{short} of {} generated rigs have a controller refused, more than the 3 the bar \
             allows",
            rigs.len()
        );
    }
}

#[test]
fn a_rig_whose_controller_falls_is_refused_by_the_preflight() {
    // Seed 9: a weak motor (k_t 0.020, R_m 9.9 Ω) against arm friction worth 2.2 V; its
    // file's own MPC falls on the 1 rad step.
    let spec = Spec::parse(&Rig::random(9).to_toml()).unwrap();
    let bar = Bar::for_rig(&spec, 0.01).unwrap();
    let falls = tune::assess(&spec, 0.01, &bar)
        .unwrap()
        .into_iter()
        .find(|a| a.kind == ControllerKind::Mpc)
        .unwrap();
    assert!(falls.fell, "{falls:?}");
    let design = spec.design(0.01).unwrap();
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
    let mut at_rest = spec.clone();
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
fn the_compensations_gains_are_kept_where_the_bar_needs_them() {
    // Generated rig 2: with the compensation's gains at 1, no shared weights tried bring LQG
    // within the bar (an identified dead zone and friction 30 % low leave it in a limit
    // cycle). The tuning compensates more than identified, and every controller meets the
    // bar simulated here, the identification's error applied by hand to the identified
    // values (the gains stay: they are what the file does with what it identified); the same
    // file with the gains at 1 misses the share of the bar the tuning holds its simulations
    // to (`Bar::guarded`).
    let spec = Spec::parse(&Rig::random(2).to_toml()).unwrap();
    let t = tune(&spec, 0.01).unwrap();
    let gains = tune::gains::gains(&t.spec);
    assert!(t.works, "{:?}", t.shortfalls());
    assert!(gains.0 > 1.0 || gains.1 > 1.0, "{gains:?}");
    for kind in ControllerKind::ALL {
        if let Err(e) = meets_bar(&t.spec, kind, &t.bar, &tune::SEEDS) {
            panic!("{kind:?} with the gains {gains:?}: {e}");
        }
    }
    let plain = tune::gains::with_gains(&t.spec, (1.0, 1.0));
    let guarded = t.bar.guarded();
    let short: Vec<_> = ControllerKind::ALL
        .into_iter()
        .filter_map(|k| meets_bar(&plain, k, &guarded, &tune::SEEDS).err())
        .collect();
    assert!(
        !short.is_empty(),
        "every controller meets the bar without the gains {gains:?}"
    );
}

/// Tunes generated rig `seed` and asserts that the tuning set `kind`'s own key `key`
/// (`get`), that `kind` then meets the whole bar simulated here, and that the same file with
/// the key cleared (`clear`) does not.
fn own_key_meets_the_bar_where_the_shared_does_not(
    seed: u64,
    kind: ControllerKind,
    key: &str,
    get: fn(&Spec) -> f64,
    clear: fn(&mut Spec),
) {
    let spec = Spec::parse(&Rig::random(seed).to_toml()).unwrap();
    let t = tune(&spec, 0.01).unwrap();
    let value = get(&t.spec);
    assert!(value > 0.0, "{key} not set: {:?}", t.shortfalls());
    assert!(t.shortfalls().iter().all(|(k, _)| *k != kind));
    if let Err(e) = meets_bar(&t.spec, kind, &t.bar, &tune::SEEDS) {
        panic!("{kind:?} with {key} = {value}: {e}");
    }
    let mut without = t.spec.clone();
    clear(&mut without);
    assert!(meets_bar(&without, kind, &t.bar.guarded(), &tune::SEEDS).is_err());
}

#[test]
fn lqg_cancelling_an_input_disturbance_meets_the_bar_where_the_shared_filter_does_not() {
    // Generated rig 5, the rig path's rig: on the shared filter no weights tried bring LQG
    // within the bar with the compensation 30 % low (a limit cycle of 0.14 rad). Its own
    // filter, with a disturbance at the plant input its law cancels, holds it: the tuning
    // keeps it, and simulated here (errors and stiction applied by hand) it meets the whole
    // bar, margins included; the same file on the shared filter does not.
    own_key_meets_the_bar_where_the_shared_does_not(
        5,
        ControllerKind::Lqg,
        "kalman.input_disturbance",
        |s| s.kalman.input_disturbance,
        |s| s.kalman.input_disturbance = 0.0,
    );
}

#[test]
fn lqg_regulating_the_estimated_outputs_meets_the_bar_where_the_papers_law_does_not() {
    // Generated rig 8: a pendulum encoder of 716 counts a turn. On the shared filter the
    // paper's LQG, which regulates the plant part of the estimate and leaves out eq. (1)'s
    // output disturbance, is short even with no friction at all (about 0.07 rad peak-to-peak
    // where LQR holds 0.04). Regulating the estimated outputs, as the MPC's cost does, LQG meets the
    // whole bar: the tuning keeps it, and simulated here it meets the bar, margins (measured
    // with that law in the loop) included; the same file with the paper's law does not.
    own_key_meets_the_bar_where_the_shared_does_not(
        8,
        ControllerKind::Lqg,
        "kalman.regulate_outputs",
        |s| f64::from(u8::from(s.kalman.regulate_outputs)),
        |s| s.kalman.regulate_outputs = false,
    );
}

#[test]
fn lqr_cancelling_an_input_disturbance_meets_the_bar_where_the_paper_lqr_does_not() {
    // Generated rig 4: no shared weights tried bring the paper's LQR within the bar (a
    // stick-slip cycle of 0.18 rad with the compensation 30 % low). With an observer of the
    // disturbance at the plant input, whose estimate its law cancels, it holds the arm: the
    // tuning keeps it, and simulated here (errors and stiction applied by hand) it meets the
    // whole bar, its margins (measured with the observer in the loop) included; the same
    // file without the observer does not.
    own_key_meets_the_bar_where_the_shared_does_not(
        4,
        ControllerKind::Lqr,
        "lqr.disturbance_bandwidth",
        |s| s.lqr.disturbance_bandwidth,
        |s| s.lqr.disturbance_bandwidth = 0.0,
    );
}

#[test]
fn a_cost_that_holds_the_pendulum_harder_brings_lqr_within_the_bar_on_a_coarse_pendulum_encoder() {
    // Generated rig 3: a pendulum encoder of 792 counts a turn (7.9 mrad a count). With every
    // weight of the first grid LQR's |α| stayed at 0.017–0.022 rad against the guarded 0.016:
    // its differenced rate passes each count's step to the voltage. The second grid, whose
    // cost holds the pendulum harder than the arm, has weights with which all three
    // controllers meet the bar: the tuning keeps them, and simulated here each meets the
    // whole bar; the file's own LQR does not.
    let spec = Spec::parse(&Rig::random(3).to_toml()).unwrap();
    let t = tune(&spec, 0.01).unwrap();
    assert!(t.works, "{:?}", t.shortfalls());
    let chosen = t.weights.with_recovery(1.0);
    assert!(
        tune::pendulum_led_candidates(&spec).contains(&chosen),
        "{chosen:?} is not of the second grid"
    );
    assert!(chosen.pendulum > chosen.arm, "{chosen:?}");
    for kind in ControllerKind::ALL {
        if let Err(e) = meets_bar(&t.spec, kind, &t.bar, &tune::SEEDS) {
            panic!("{kind:?} with {chosen:?}: {e}");
        }
    }
    assert!(meets_bar(&spec, ControllerKind::Lqr, &t.bar.guarded(), &tune::SEEDS).is_err());
}

#[test]
fn a_controller_that_falls_on_further_noise_seeds_is_short_of_the_bar() {
    // Generated rig 9 as the tuning chose it over its second grid before the fall check: its
    // MPC meets the bar on the tuning's four noise seeds, yet falls on others with the
    // compensation 30 % high (counted here on 60 seeds of their own). The fall check finds it
    // short, with the count in its words.
    let rig = Spec::parse(&Rig::random(9).to_toml()).unwrap();
    let bar = Bar::for_rig(&rig, 0.01).unwrap().guarded();
    let spec = Spec::parse(include_str!("data/rig9_mpc_falls_on_further_seeds.toml")).unwrap();
    let mut assessed = tune::assess(&spec, 0.01, &bar).unwrap();
    let mpc = |a: &[tune::Assessment]| a[2];
    assert_eq!(mpc(&assessed).kind, ControllerKind::Mpc);
    assert!(
        mpc(&assessed).works(&bar),
        "{:?}",
        mpc(&assessed).misses(&bar)
    );
    let high = compensation_off(&spec, 1.0 + OFF_COMPENSATION);
    let (design, plant) = (high.design(0.01).unwrap(), high.plant().unwrap());
    let falls = (200..260u64)
        .filter(|&seed| {
            let mut c = design.controller(ControllerKind::Mpc).unwrap();
            let run = rip_core::simulate(&plant, c.as_mut(), &high.sim_config(0.01, seed));
            run.unwrap().fell
        })
        .count();
    assert!(falls >= 3, "{falls} of 60");
    tune::check_falls(&spec, 0.01, &bar, &mut assessed).unwrap();
    let (fell, runs) = mpc(&assessed).off_compensation.unwrap().fall_check;
    let per_way = tune::FALL_CHECK_SEEDS.count() as u32;
    assert!(fell > 0 && runs == 2 * per_way, "{fell} of {runs}");
    assert!(!mpc(&assessed).works(&bar));
    let misses = mpc(&assessed).misses(&bar).join("; ");
    assert!(misses.contains("runs on further noise seeds"), "{misses}");
    // The check runs only on controllers that work: the same rig's LQG, short already, is
    // left as it was.
    assert!(!assessed[1].works(&bar));
    assert_eq!(assessed[1].off_compensation.unwrap().fall_check, (0, 0));
}

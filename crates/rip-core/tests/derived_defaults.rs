//! Defaults that follow from other keys, or are checked against them: a file that writes one
//! key and leaves the other at its default must be refused, if at all, through a key it
//! wrote, with the range of that key that would work. Each case is a hostile file and a sweep
//! over the written key's allowed values.

use std::collections::BTreeSet;

use rip_core::spec::rig_sections::{parse_file, COUNTS_PER_REV};
use rip_core::spec::{Spec, SpecError};

/// The whole check a file gets from `riprs.load_config` and `rip-rt config`: both sections'
/// validation and the design at the paper's sample time.
fn check(text: &str) -> Result<(), SpecError> {
    let (spec, _) = parse_file(text)?;
    spec.check(rip_core::paper::TS)
}

/// Every key path the file writes, `section.key`.
fn written(text: &str) -> BTreeSet<String> {
    let table: toml::Table = text.parse().unwrap();
    let mut out = BTreeSet::new();
    for (section, v) in &table {
        match v.as_table() {
            Some(t) => out.extend(t.keys().map(|k| format!("{section}.{k}"))),
            None => {
                out.insert(section.clone());
            }
        }
    }
    out
}

/// The error's key without an index (`sensor.encoder_counts[0]` → `sensor.encoder_counts`).
fn base_key(e: &SpecError) -> &str {
    e.key.split('[').next().unwrap_or("")
}

/// Asserts that `text` passes, or is refused through a key it writes.
fn passes_or_names_a_written_key(text: &str) -> Option<SpecError> {
    match check(text) {
        Ok(()) => None,
        Err(e) => {
            assert!(
                written(text).contains(base_key(&e)),
                "{text:?} is refused through a key it does not write: {e}"
            );
            Some(e)
        }
    }
}

#[test]
fn a_coarse_encoder_is_refused_by_its_own_key_and_every_allowed_count_passes() {
    let e = check("[sensor]\nencoder_counts = [64, 64]\n").unwrap_err();
    assert_eq!(e.key, "sensor.encoder_counts[0]", "{e}");
    assert!(
        e.reason
            .contains(&format!("must be in {}..=", COUNTS_PER_REV.start())),
        "{e}"
    );
    let e = check("[sensor]\nencoder_counts = [4096, 100]\n").unwrap_err();
    assert_eq!(e.key, "sensor.encoder_counts[1]", "{e}");
    // Every count the rule allows up to 8192, and the powers of two to its end, on either
    // joint: the rest rates' defaults follow them.
    let start = *COUNTS_PER_REV.start();
    let counts = (start..=8192).chain((13..=24).map(|k| 1u32 << k));
    for c in counts {
        for text in [
            format!("[sensor]\nencoder_counts = [{c}, 2048]\n"),
            format!("[sensor]\nencoder_counts = [2048, {c}]\n"),
        ] {
            let (_, rig) = parse_file(&text).unwrap_or_else(|e| panic!("{text}: {e}"));
            assert!(rig.calibration.rest_arm_rate > 0.0);
        }
    }
    // Below the rule's start, the key written is the one refused.
    for c in [0, 1, 63, 64, 100, 124, start - 1] {
        let text = format!("[sensor]\nencoder_counts = [{c}, 2048]\n");
        let e = passes_or_names_a_written_key(&text).expect("refused");
        assert_eq!(e.key, "sensor.encoder_counts[0]", "{e}");
    }
}

/// The largest value of `key` (in `[plant]`) the refusal says would work, read from its
/// reason "… must be below X …".
fn stated_bound(e: &SpecError) -> f64 {
    let rest = e.reason.split("must be below ").nth(1).expect("a bound");
    rest.split([' ', ',', ';'])
        .next()
        .unwrap()
        .parse()
        .unwrap_or_else(|_| panic!("no number in {e}"))
}

#[test]
fn arm_friction_too_large_to_compensate_is_refused_through_plant_cr() {
    let e = check("[plant]\nCr = 0.5\n").unwrap_err();
    assert_eq!(e.key, "plant.Cr", "{e}");
    assert!(e.reason.contains("compensation"), "{e}");
    // A sweep over Cr, on both presets, with and without a dead zone: every refusal names
    // plant.Cr (or plant.Vd, when the dead zone alone leaves no room) and states the bound
    // that works, which does.
    for preset in ["paper", "qube_servo2"] {
        for vd in [None, Some(0.5), Some(5.0)] {
            let mut refused = 0;
            for i in 0..=100 {
                let cr = 0.002 * f64::from(i) * f64::from(i);
                let vd_line = vd.map_or(String::new(), |v| format!("Vd = {v}\n"));
                let text = format!("[plant]\npreset = \"{preset}\"\nCr = {cr}\n{vd_line}");
                let Some(e) = passes_or_names_a_written_key(&text) else {
                    continue;
                };
                refused += 1;
                assert_eq!(e.key, "plant.Cr", "{text}: {e}");
                let bound = stated_bound(&e);
                assert!(bound > 0.0 && bound < cr, "{text}: {e}");
                let fixed = format!(
                    "[plant]\npreset = \"{preset}\"\nCr = {}\n{vd_line}",
                    bound * 0.999
                );
                check(&fixed).unwrap_or_else(|e| panic!("{fixed}: {e}"));
            }
            assert!(refused > 0, "{preset} {vd:?}: the sweep reaches no refusal");
        }
    }
}

#[test]
fn a_dead_zone_too_large_to_compensate_is_refused_through_the_key_written() {
    for (text, key) in [
        ("[plant]\nVd = 13.0\n", "plant.Vd"),
        ("[plant]\nVd = 12.0\n", "plant.Vd"),
        (
            "[compensation]\ndead_zone = 12.5\n",
            "compensation.dead_zone",
        ),
        (
            "[plant]\nVd = 11.0\n[compensation]\narm_friction = 0.1\n",
            "compensation.arm_friction",
        ),
        (
            "[plant]\nVd = 0.5\n[mpc]\ninput_bounds = [[0.0, 12.0]]\n",
            "",
        ),
    ] {
        let e = passes_or_names_a_written_key(text).expect("refused");
        if !key.is_empty() {
            assert_eq!(e.key, key, "{text}: {e}");
        }
    }
    for i in 0..=130 {
        let vd = 0.1 * f64::from(i);
        passes_or_names_a_written_key(&format!("[plant]\nVd = {vd}\n"));
        passes_or_names_a_written_key(&format!("[compensation]\ndead_zone = {vd}\n"));
    }
}

/// The key a sweep writes, the file for a value of it, and the values swept.
type Sweep = (
    &'static str,
    fn(f64) -> String,
    std::ops::RangeInclusive<f64>,
);

#[test]
fn rig_limits_written_alone_never_blame_a_default_they_are_checked_against() {
    let cases: [Sweep; 7] = [
        (
            "calibration.rest_window_s",
            |v| format!("[calibration]\nrest_window_s = {v}\n"),
            0.2..=10.0,
        ),
        (
            "safety.pendulum_limit",
            |v| format!("[safety]\npendulum_limit = {v}\n"),
            0.001..=std::f64::consts::FRAC_PI_2,
        ),
        (
            "loop.period_ms",
            |v| format!("[loop]\nperiod_ms = {v}\n"),
            1.0..=20.0,
        ),
        (
            "safety.arm_limit",
            |v| format!("[safety]\narm_limit = {v}\n"),
            0.01..=std::f64::consts::TAU,
        ),
        (
            "safety.arm_limit",
            |v| format!("[safety]\narm_limit = {v}\n[swing_up]\nmax_voltage = 6.0\n"),
            0.01..=std::f64::consts::TAU,
        ),
        (
            "plant.fall_limit",
            |v| format!("[plant]\nfall_limit = {v}\n"),
            0.001..=3.0,
        ),
        (
            "mpc.prediction_horizon",
            |v| format!("[mpc]\nprediction_horizon = {}\n", v.round()),
            1.0..=60.0,
        ),
    ];
    for (key, text, range) in cases {
        for i in 0..=200 {
            let v = range.start() + (range.end() - range.start()) * f64::from(i) / 200.0;
            if let Some(e) = passes_or_names_a_written_key(&text(v)) {
                assert_eq!(e.key, key, "{}: {e}", text(v));
            }
        }
    }
}

#[test]
fn the_swing_up_keys_written_alone_never_blame_a_default() {
    for (text, key) in [
        ("[swing_up]\narm_limit = 0.5\n", "swing_up.arm_limit"),
        ("[swing_up]\ncatch_angle = 0.8\n", "swing_up.catch_angle"),
        ("[swing_up]\narm_limit = 0.15\n", "swing_up.arm_limit"),
        (
            "[swing_up]\nbalance_angle = 0.1\n",
            "swing_up.balance_angle",
        ),
        (
            "[safety]\narm_limit = 1.2\n[swing_up]\nmax_voltage = 6.0\n",
            "safety.arm_limit",
        ),
        (
            "[safety]\npendulum_limit = 0.5\n[swing_up]\nmax_voltage = 6.0\n",
            "safety.pendulum_limit",
        ),
        (
            "[safety]\nvoltage_limit = 5.0\n[swing_up]\narm_limit = 1.0\n",
            "safety.voltage_limit",
        ),
    ] {
        let e = passes_or_names_a_written_key(text).expect("refused");
        assert_eq!(e.key, key, "{text}: {e}");
    }
    for i in 1..=100 {
        let v = 0.0314 * f64::from(i);
        passes_or_names_a_written_key(&format!("[swing_up]\narm_limit = {v}\n"));
        passes_or_names_a_written_key(&format!("[swing_up]\ncatch_angle = {}\n", v / 2.0));
        passes_or_names_a_written_key(&format!("[swing_up]\nbalance_angle = {v}\n"));
    }
}

#[test]
fn the_spec_alone_names_the_key_written_too() {
    // Spec::parse (riprs compare's reader, no rig sections) goes through the same rules.
    let e = Spec::parse("[plant]\nfall_limit = 0.01\n").unwrap_err();
    assert_eq!(e.key, "plant.fall_limit", "{e}");
    let e = Spec::parse("[mpc]\nprediction_horizon = 2\n").unwrap_err();
    assert_eq!(e.key, "mpc.prediction_horizon", "{e}");
}

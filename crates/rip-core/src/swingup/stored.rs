//! The feasibility verdict stored in the tuning record: `riprs tune` computes it when the rig
//! file is made and writes it as the record's `[swing_up]` table
//! (beside the rig file, `crate::preflight::tune_record_path`); the swing_up check of `rip-rt
//! run --swing-up`'s pre-flight (`crate::preflight::swing`) reads it while its checksum matches
//! the inputs and computes it again otherwise.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::checksum::fnv1a64;
use crate::plant::Plant;

use super::feasibility::{feasibility, Feasibility, Verdict};
use super::SwingUpSettings;

/// Version of the verdict's definition, part of its checksum: a riprs whose energy balance
/// differs computes it again instead of trusting an old record.
const DEFINITION: &str = "swing-up feasibility v1";

/// The checksum of everything [`feasibility`] reads: every physical parameter of the nominal
/// model, the voltage bound and the arm travel, and the definition's version (64-bit FNV-1a,
/// as [`crate::preflight::design_checksum`]).
pub fn feasibility_inputs(plant: &Plant, settings: &SwingUpSettings) -> String {
    let p = plant.params();
    let values = [
        p.rm,
        p.kt,
        p.km,
        p.mr,
        p.lr,
        p.jr,
        p.mp,
        p.lp,
        p.jp,
        p.dr,
        p.dp,
        p.g,
        p.cr,
        p.cp,
        p.vd,
        settings.max_voltage,
        settings.arm_limit,
    ];
    let bits: Vec<u8> = values
        .iter()
        .flat_map(|v| v.to_bits().to_le_bytes())
        .collect();
    fnv1a64(&[DEFINITION.as_bytes(), &bits])
}

/// A [`Feasibility`] as the tuning record's `[swing_up]` table stores it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredFeasibility {
    /// [`feasibility_inputs`] of the model and settings it was computed from.
    pub inputs: String,
    /// [`Verdict::name`].
    pub verdict: String,
    /// [`Feasibility::gain`] (J).
    pub gain: f64,
    /// [`Feasibility::loss`] (J).
    pub loss: f64,
    /// [`Feasibility::gravity`] (J).
    pub gravity: f64,
    /// [`Feasibility::voltage_needed`] (V).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub voltage_needed: Option<f64>,
    /// [`Feasibility::arm_travel_needed`] (rad).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arm_travel_needed: Option<f64>,
    /// [`Feasibility::time_estimate`] (s; `inf` when impossible).
    pub time_estimate: f64,
}

impl StoredFeasibility {
    /// The verdict on `plant` with `settings`, computed now, ready to store.
    pub fn compute(plant: &Plant, settings: &SwingUpSettings) -> Self {
        let f = feasibility(plant, settings);
        Self {
            inputs: feasibility_inputs(plant, settings),
            verdict: f.verdict.name().to_string(),
            gain: f.gain,
            loss: f.loss,
            gravity: f.gravity,
            voltage_needed: f.voltage_needed,
            arm_travel_needed: f.arm_travel_needed,
            time_estimate: f.time_estimate,
        }
    }

    /// The record's `[swing_up]` table, with a comment saying what it is.
    pub fn to_section(&self) -> String {
        #[derive(Serialize)]
        struct Section<'a> {
            swing_up: &'a StoredFeasibility,
        }
        format!(
            "\n# The swing-up feasibility verdict (rip_core::swingup::feasibility), read by rip-rt\n\
             # run --swing-up while `inputs` is the checksum of its model and swing-up bounds.\n{}",
            toml::to_string(&Section { swing_up: self }).expect("every value has a TOML form")
        )
    }

    /// The `[swing_up]` table of the TOML `text`, if it has one that parses.
    pub fn from_record(text: &str) -> Option<Self> {
        let mut table: toml::Table = toml::from_str(text).ok()?;
        table.remove("swing_up")?.try_into().ok()
    }

    /// The stored verdict as a [`Feasibility`]; `None` for a verdict name this riprs does not
    /// know.
    pub fn feasibility(&self) -> Option<Feasibility> {
        let verdict = [Verdict::NotExcluded, Verdict::Impossible]
            .into_iter()
            .find(|v| v.name() == self.verdict)?;
        Some(Feasibility {
            verdict,
            gain: self.gain,
            loss: self.loss,
            gravity: self.gravity,
            voltage_needed: self.voltage_needed,
            arm_travel_needed: self.arm_travel_needed,
            time_estimate: self.time_estimate,
        })
    }
}

/// Where a verdict came from ([`stored_or_computed`]).
#[derive(Debug, Clone, PartialEq)]
pub enum VerdictSource {
    /// Read from this tuning record, whose checksum matched.
    Stored(PathBuf),
    /// Computed now; the reason (no rig file, no record, no `[swing_up]` table in it, a stale
    /// checksum).
    Computed(String),
}

impl std::fmt::Display for VerdictSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Stored(path) => write!(f, "stored by riprs tune in {}", path.display()),
            Self::Computed(why) => write!(f, "computed now ({why})"),
        }
    }
}

/// The verdict on `plant` with `settings`: the one stored in the tuning record at `record`
/// (beside the rig file, `crate::preflight::tune_record_path`) when its checksum is
/// [`feasibility_inputs`]'s, otherwise computed now.
pub fn stored_or_computed(
    plant: &Plant,
    settings: &SwingUpSettings,
    record: Option<&Path>,
) -> (Feasibility, VerdictSource) {
    let computed = |why: String| (feasibility(plant, settings), VerdictSource::Computed(why));
    let Some(path) = record else {
        return computed("no rig file".into());
    };
    let path = path.to_path_buf();
    // The pre-flight's reader: a FIFO or a device named like the record must not hang the run
    // (the pre-flight then refuses a record it cannot read).
    let text = match crate::files::read_regular(&path).map(String::from_utf8) {
        Ok(Ok(text)) => text,
        Err(_) if !path.exists() => {
            return computed(format!("no tuning record {}", path.display()));
        }
        Err(e) => return computed(format!("{}: cannot read: {e}", path.display())),
        Ok(Err(_)) => return computed(format!("{} is not UTF-8 text", path.display())),
    };
    let Some(stored) = StoredFeasibility::from_record(&text) else {
        return computed(format!("{} has no [swing_up] verdict", path.display()));
    };
    if stored.inputs != feasibility_inputs(plant, settings) {
        return computed(format!("{} is stale, from other inputs", path.display()));
    }
    match stored.feasibility() {
        Some(f) => (f, VerdictSource::Stored(path)),
        None => computed(format!("{} has an unknown verdict", path.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_section_round_trips_beside_a_tuning_record() {
        let plant = Plant::qube_servo2();
        for max_voltage in [12.0, 0.05] {
            let s = SwingUpSettings {
                max_voltage,
                ..SwingUpSettings::default()
            };
            let stored = StoredFeasibility::compute(&plant, &s);
            let text = format!(
                "inputs = \"fnv1a64:0\"\nruns = \"x\"\n[prediction.LQR]\nfell = false\n{}",
                stored.to_section()
            );
            let back = StoredFeasibility::from_record(&text).unwrap();
            assert_eq!(back, stored);
            assert_eq!(back.feasibility().unwrap(), feasibility(&plant, &s));
        }
    }

    #[test]
    fn the_checksum_follows_every_input() {
        let plant = Plant::paper();
        let s = SwingUpSettings::default();
        let base = feasibility_inputs(&plant, &s);
        assert_eq!(base, feasibility_inputs(&plant, &s.clone()));
        let more_volts = SwingUpSettings {
            max_voltage: 12.5,
            ..s.clone()
        };
        let less_arm = SwingUpSettings {
            arm_limit: 1.4,
            ..s.clone()
        };
        let damped = Plant::new(crate::plant::FurutaParams {
            dp: plant.params().dp * 1.01,
            ..*plant.params()
        })
        .unwrap();
        for other in [
            feasibility_inputs(&plant, &more_volts),
            feasibility_inputs(&plant, &less_arm),
            feasibility_inputs(&damped, &s),
        ] {
            assert_ne!(other, base);
        }
        // A setting the verdict does not read leaves it unchanged.
        let later = SwingUpSettings {
            max_time: 30.0,
            ..s
        };
        assert_eq!(feasibility_inputs(&plant, &later), base);
    }
}

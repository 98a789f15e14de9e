//! The experiment spec: one TOML file, read by `riprs compare`, `riprs.load_config`,
//! `rip-rt run` and `rip-rt emulate`, defined here once.
//!
//! ```toml
//! controllers = ["LQR", "LQG", "MPC"]   # what riprs compare runs
//! [plant]        # preset and physical parameters, simulation settings   (PlantSpec)
//! [sensor]       # encoders and measurement noise                        (SensorSpec)
//! [reference]    # the arm step and the run length                       (ReferenceSpec)
//! [lqr]          # eq. (13) weights shared by LQR and LQG, rate filter   (LqrSpec)
//! [kalman]       # the estimator LQG and MPC share                       (KalmanSpec)
//! [mpc]          # section 3's MPC                                       (MpcSettings)
//! [compensation] # dead zone and arm friction compensated                (CompensationSpec)
//! [monte_carlo]  # runs over seeds and parameter perturbations           (MonteCarloSpec)
//! [swing_up]     # swing-up from rest and catch                          (SwingUpSettings)
//! ```
//!
//! Every key is optional; each default is declared once, in its section's `Default`, and is
//! the paper's setting. Unknown keys, wrong types and out-of-range values are errors naming
//! the key path and the file, e.g. `cfg.toml: mpc.prediction_horizon: must be in 1..=10000,
//! got 0`. The sections [`RUNTIME_SECTIONS`] belong to `rip-rt` (`[loop]`, `[device]`,
//! `[safety]`, `[calibration]`), which checks them; this crate passes them through untouched
//! ([`Spec::parse_with_runtime`]).
//!
//! [`Spec::to_toml`] prints the resolved spec (every default and every plant parameter filled
//! in); parsing that text gives the same spec back. [`Spec::design`](Spec::design) builds the
//! controllers from it (module `assembly`).

mod assembly;
mod controllers;
pub mod rig_sections;
mod sections;
pub mod study;

use std::fmt;
use std::path::Path;

use serde::{Deserialize, Serialize};

pub use crate::files::{read_regular, MAX_FILE_BYTES};
pub use crate::mpc::{MpcSettings, QpSolver};
pub use crate::plant::Param;
pub use assembly::{Design, Start, SWING_UP_ALLOWANCE};
pub use controllers::{CompensationSpec, KalmanSpec, LqrSpec};
pub use sections::{
    ControllerKind, MonteCarloSpec, PlantSpec, Preset, ReferenceSpec, SensorSpec, MAX_DURATION,
    MAX_MONTE_CARLO_RUNS,
};

/// Keys that moved, each with the key that replaced it: a file that still sets one is
/// refused, naming the new key, whichever command reads it.
pub const MOVED_KEYS: [(&str, &str); 2] = [
    // One file describes the rig for the simulation, the emulator and rip-rt alike.
    ("device.arm_counts_per_rev", "sensor.encoder_counts[0]"),
    ("device.pendulum_counts_per_rev", "sensor.encoder_counts[1]"),
];

/// The first key of [`MOVED_KEYS`] that `table` (a whole file) sets, as an error naming the
/// key that replaced it.
fn refuse_moved_keys(table: &toml::Table) -> Result<(), SpecError> {
    for (old, new) in MOVED_KEYS {
        let mut node = Some(table);
        let mut path = old.split('.').peekable();
        while let Some(part) = path.next() {
            let value = node.and_then(|t| t.get(part));
            if path.peek().is_none() && value.is_some() {
                return Err(SpecError::new(old, format!("moved to {new}: set it there")));
            }
            node = value.and_then(toml::Value::as_table);
        }
    }
    Ok(())
}

/// The text of the file at `path`, the one reader of every experiment file and of the
/// records beside one ([`read_regular`]: regular files only, bounded): an unreadable file or
/// one that is not UTF-8 is an error naming it; a leading byte-order mark is dropped.
pub fn read_text(path: &Path) -> Result<String, SpecError> {
    let bytes = read_regular(path)
        .map_err(|e| SpecError::new("", format!("cannot read: {e}")).in_file(path))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        SpecError::new("", format!("invalid TOML: not UTF-8 text ({e})")).in_file(path)
    })?;
    // Editors on some systems start a UTF-8 file with a byte-order mark.
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// Top-level tables that belong to `rip-rt` and are not checked here.
pub const RUNTIME_SECTIONS: [&str; 4] = ["loop", "device", "safety", "calibration"];

/// A bad file, key or value. Displays as `FILE: KEY: REASON` (`FILE: REASON` when no single
/// key is at fault, e.g. a TOML syntax error).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SpecError {
    /// The file, when the spec came from one.
    pub file: Option<String>,
    /// The key path (`mpc.prediction_horizon`, `sensor.noise_std[1]`), empty for the file.
    pub key: String,
    /// What is wrong.
    pub reason: String,
}

impl SpecError {
    /// An error at `key`.
    pub fn new(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self {
            file: None,
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// A section's own error ([`KeyError`](crate::error::KeyError), keyed relative to the
    /// section) at its key path in the file: `mpc` and `output_bounds[1]` give
    /// `mpc.output_bounds[1]`.
    pub fn in_section(section: &str, e: crate::error::KeyError) -> Self {
        Self::new(format!("{section}.{}", e.key), e.reason)
    }

    /// The same error, located in `file`.
    pub fn in_file(mut self, file: &Path) -> Self {
        self.file = Some(file.display().to_string());
        self
    }
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = &self.file {
            write!(f, "{file}: ")?;
        }
        if !self.key.is_empty() {
            write!(f, "{}: ", self.key)?;
        }
        f.write_str(&self.reason)
    }
}

impl std::error::Error for SpecError {}

/// The whole experiment (module docs). `Default` is the paper's setting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Spec {
    /// The controllers `riprs compare` runs, in this order.
    pub controllers: Vec<ControllerKind>,
    /// `[plant]`
    pub plant: PlantSpec,
    /// `[sensor]`
    pub sensor: SensorSpec,
    /// `[reference]`
    pub reference: ReferenceSpec,
    /// `[lqr]`
    pub lqr: LqrSpec,
    /// `[kalman]`
    pub kalman: KalmanSpec,
    /// `[mpc]`: the MPC's own settings ([`MpcSettings`], the paper profile by default); its
    /// `output_disturbance` and `measurement_noise` come from `[kalman]`
    /// ([`mpc_settings`](Self::mpc_settings)).
    pub mpc: MpcSettings,
    /// `[compensation]`: dead zone and arm friction compensated on every controller's voltage
    pub compensation: CompensationSpec,
    /// `[monte_carlo]`
    pub monte_carlo: MonteCarloSpec,
    /// `[swing_up]`: the swing-up and its supervisor
    /// ([`SwingUpSettings`](crate::swingup::SwingUpSettings), whose `Default` declares each
    /// default).
    pub swing_up: crate::swingup::SwingUpSettings,
}

impl Default for Spec {
    fn default() -> Self {
        Self {
            controllers: ControllerKind::ALL.to_vec(),
            plant: PlantSpec::default(),
            sensor: SensorSpec::default(),
            reference: ReferenceSpec::default(),
            lqr: LqrSpec::default(),
            kalman: KalmanSpec::default(),
            mpc: MpcSettings::paper(),
            compensation: CompensationSpec::default(),
            monte_carlo: MonteCarloSpec::default(),
            swing_up: crate::swingup::SwingUpSettings::default(),
        }
    }
}

/// Deserialises `value` into `T`, naming the key path of any failure under `prefix`.
pub fn from_value<T: serde::de::DeserializeOwned>(
    value: toml::Value,
    prefix: &str,
) -> Result<T, SpecError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let mut key = e.path().to_string();
        let full = e.inner().to_string();
        // The TOML deserialiser appends "in `section`"; the key path already says where.
        let reason = full
            .split("\nin `")
            .next()
            .unwrap_or(&full)
            .trim_end()
            .to_string();
        // An unknown key fails before the path reaches it; name it all the same.
        if let Some(name) = reason
            .strip_prefix("unknown field `")
            .and_then(|r| r.split('`').next())
        {
            if key == "." || key.is_empty() {
                key = name.to_string();
            } else if !(key == name || key.ends_with(&format!(".{name}"))) {
                key = format!("{key}.{name}");
            }
        }
        if key == "." {
            key.clear();
        }
        let key = match (prefix.is_empty(), key.is_empty()) {
            (true, _) => key,
            (false, true) => prefix.to_string(),
            (false, false) => format!("{prefix}.{key}"),
        };
        SpecError::new(key, reason)
    })
}

/// Merges `changes` into `base`: tables key by key, any other value replaced.
fn merge(base: &mut toml::Table, changes: toml::Table) {
    for (k, v) in changes {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(c)) => merge(b, c),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// Parses TOML text into a table; a syntax error names no key and is one line (where, then
/// what: the parser's excerpt with its caret is left out).
pub fn parse_table(text: &str) -> Result<toml::Table, SpecError> {
    text.parse::<toml::Table>().map_err(|e| {
        let full = e.to_string();
        let lines: Vec<&str> = full
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .collect();
        let reason = match (lines.first(), lines.last()) {
            (Some(first), Some(last)) if lines.len() > 1 => format!("{first}: {last}"),
            _ => full.trim().to_string(),
        };
        SpecError::new("", format!("invalid TOML: {reason}"))
    })
}

impl Spec {
    /// Parses and checks TOML text; the sections of [`RUNTIME_SECTIONS`] are ignored.
    pub fn parse(text: &str) -> Result<Self, SpecError> {
        Self::parse_with_runtime(text).map(|(spec, _)| spec)
    }

    /// Parses and checks TOML text, returning the spec and the untouched runtime sections
    /// ([`RUNTIME_SECTIONS`]) for `rip-rt` to read.
    pub fn parse_with_runtime(text: &str) -> Result<(Self, toml::Table), SpecError> {
        let mut table = parse_table(text)?;
        refuse_moved_keys(&table)?;
        let mut runtime = toml::Table::new();
        for name in RUNTIME_SECTIONS {
            if let Some(v) = table.remove(name) {
                runtime.insert(name.to_string(), v);
            }
        }
        let spec = Self::from_table(table)?;
        Ok((spec, runtime))
    }

    /// Builds and checks a spec from a TOML table holding only its own sections.
    pub fn from_table(table: toml::Table) -> Result<Self, SpecError> {
        let spec: Spec = from_value(toml::Value::Table(table), "")?;
        spec.validate()?;
        Ok(spec)
    }

    /// Reads, parses and checks a file; errors name it.
    pub fn load(path: &Path) -> Result<Self, SpecError> {
        Self::load_with_runtime(path).map(|(spec, _)| spec)
    }

    /// The whole file as `riprs.load_config` and `rip-rt config` read it: rip-rt's sections
    /// validated too ([`rig_sections::load_file`]), and [`check`](Self::check) at sample time
    /// `ts`, refused if any controller cannot be designed.
    pub fn load_checked(path: &Path, ts: f64) -> Result<Self, SpecError> {
        let (spec, _rig) = rig_sections::load_file(path)?;
        spec.check(ts).map_err(|e| e.in_file(path))?;
        Ok(spec)
    }

    /// Checks that every controller kind can be designed at sample time `ts` (s), naming the
    /// key whose value makes a design fail.
    pub fn check(&self, ts: f64) -> Result<(), SpecError> {
        self.design(ts).and_then(|d| d.controllers().map(|_| ()))
    }

    /// [`load`](Self::load), also returning the runtime sections.
    pub fn load_with_runtime(path: &Path) -> Result<(Self, toml::Table), SpecError> {
        Self::parse_with_runtime(&read_text(path)?).map_err(|e| e.in_file(path))
    }

    /// Checks every value; the error names the first bad key. Values that are valid alone but
    /// fail together in a design are found by [`design`](Self::design).
    pub fn validate(&self) -> Result<(), SpecError> {
        sections::validate_sections(self)
    }

    /// The resolved spec: every plant parameter written out.
    pub fn resolved(&self) -> Self {
        Self {
            plant: self.plant.resolved(),
            ..self.clone()
        }
    }

    /// A copy with `changes` (tables shaped like a file's, e.g. `{monte_carlo = {runs = 10}}`)
    /// merged in and checked as a file is; the error names the first bad or unknown key.
    ///
    /// The merge is deep: a table in `changes` changes only the keys it holds, any other value
    /// (an array included) replaces the old one. A new `plant.preset` brings its own
    /// parameters, except those `changes` sets.
    pub fn updated(&self, changes: toml::Table) -> Result<Self, SpecError> {
        refuse_moved_keys(&changes)?;
        let mut base = match toml::Value::try_from(self.resolved()) {
            Ok(toml::Value::Table(t)) => t,
            _ => unreachable!("a spec serialises to a table"),
        };
        let new_preset = changes
            .get("plant")
            .and_then(toml::Value::as_table)
            .is_some_and(|p| p.contains_key("preset"));
        if let (true, Some(toml::Value::Table(plant))) = (new_preset, base.get_mut("plant")) {
            for p in Param::ALL {
                plant.remove(p.name());
            }
        }
        merge(&mut base, changes);
        Self::from_table(base)
    }

    /// The resolved spec as TOML (every default filled in); [`parse`](Self::parse) reads it
    /// back to an equal spec.
    pub fn to_toml(&self) -> String {
        toml::to_string(&self.resolved()).expect("every spec value has a TOML form")
    }
}

#[cfg(test)]
mod tests;

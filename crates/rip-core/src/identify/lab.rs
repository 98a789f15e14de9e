//! The lab file: what a lab measures on its rig with a scale, a ruler, a multimeter and the
//! encoders' data sheets, read by `rip-rt excite --lab` (which carries it into the log's
//! header) and by `riprs identify --lab`. Its one definition.
//!
//! ```toml
//! [lab]
//! mp = 0.024      # pendulum mass (kg)
//! Lp = 0.129      # pendulum length (m)
//! mr = 0.095      # arm mass (kg)
//! Lr = 0.085      # arm length, motor axis to pendulum joint (m)
//! Rm = 8.4        # motor terminal resistance (ohm)
//! km = 0.042      # motor back-EMF constant (V s/rad)
//! kt = 0.042      # motor torque constant (N m/A)
//! arm_counts = 2048        # arm encoder counts per revolution
//! pendulum_counts = 2048   # pendulum encoder counts per revolution
//! ```
//!
//! Every key is optional; each value must be a positive finite number (the counts an integer
//! of at least 16), and unknown keys are refused, naming the file and the key.

use std::path::Path;

use crate::plant::Param;
use crate::spec::SpecError;

/// The keys of a lab file's `[lab]` table and what each is, in the file's order: the measured
/// parameters by their [`Param`] names, then the encoders' resolutions.
pub const LAB_KEYS: [(&str, &str); 9] = [
    (Param::Mp.name(), "pendulum mass (kg)"),
    (Param::Lp.name(), "pendulum length (m)"),
    (Param::Mr.name(), "arm mass (kg)"),
    (
        Param::Lr.name(),
        "arm length, motor axis to pendulum joint (m)",
    ),
    (Param::Rm.name(), "motor terminal resistance (ohm)"),
    (Param::Km.name(), "motor back-EMF constant (V s/rad)"),
    (Param::Kt.name(), "motor torque constant (N m/A)"),
    ("arm_counts", "arm encoder counts per revolution"),
    ("pendulum_counts", "pendulum encoder counts per revolution"),
];

/// Fewest encoder counts per revolution a lab file may give.
pub const MIN_COUNTS: i64 = 16;

/// A lab file's measurements, `(key, value)` in [`LAB_KEYS`]' order, only those given.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Lab {
    /// The measured values.
    pub values: Vec<(&'static str, f64)>,
}

impl Lab {
    /// Parses a lab file's text (module docs).
    pub fn parse(text: &str) -> Result<Self, SpecError> {
        let doc: toml::Table = text
            .parse()
            .map_err(|e: toml::de::Error| SpecError::new("", format!("not a TOML file: {e}")))?;
        let keys = LAB_KEYS.map(|(k, _)| k).join(", ");
        let table = match doc.get("lab") {
            Some(toml::Value::Table(t)) if doc.len() == 1 => t,
            _ => {
                return Err(SpecError::new(
                    "",
                    format!("a lab file holds one [lab] table (keys: {keys})"),
                ))
            }
        };
        for key in table.keys() {
            if !LAB_KEYS.iter().any(|(k, _)| k == key) {
                return Err(SpecError::new(
                    format!("lab.{key}"),
                    format!("unknown key; the keys are {keys}"),
                ));
            }
        }
        let mut values = Vec::new();
        for (key, _) in LAB_KEYS {
            let Some(v) = table.get(key) else { continue };
            let value = if key.ends_with("_counts") {
                match v {
                    toml::Value::Integer(n) if *n >= MIN_COUNTS => *n as f64,
                    _ => {
                        return Err(SpecError::new(
                            format!("lab.{key}"),
                            format!("must be an integer >= {MIN_COUNTS}, got {v}"),
                        ))
                    }
                }
            } else {
                match v {
                    toml::Value::Float(x) if x.is_finite() && *x > 0.0 => *x,
                    toml::Value::Integer(n) if *n > 0 => *n as f64,
                    _ => {
                        return Err(SpecError::new(
                            format!("lab.{key}"),
                            format!("must be a positive number, got {v}"),
                        ))
                    }
                }
            };
            values.push((key, value));
        }
        Ok(Self { values })
    }

    /// Reads and parses the lab file at `path`; errors name the file.
    pub fn load(path: &Path) -> Result<Self, SpecError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SpecError::new("", format!("cannot read: {e}")).in_file(path))?;
        Self::parse(&text).map_err(|e| e.in_file(path))
    }

    /// The value of `key`, if measured.
    pub fn get(&self, key: &str) -> Option<f64> {
        self.values.iter().find(|(k, _)| *k == key).map(|(_, v)| *v)
    }

    /// The `(key, value)` lines a log header carries (`lab.mp: 0.024`, ...).
    pub fn header(&self) -> Vec<(String, String)> {
        self.values
            .iter()
            .map(|(k, v)| (format!("lab.{k}"), v.to_string()))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lab_files_are_read_and_bad_keys_named() {
        let lab = Lab::parse("[lab]\nmp = 0.06\nLp = 0.25\narm_counts = 2048\n").unwrap();
        assert_eq!(lab.get("mp"), Some(0.06));
        assert_eq!(lab.get("arm_counts"), Some(2048.0));
        assert_eq!(lab.get("Rm"), None);
        assert_eq!(lab.header()[1], ("lab.Lp".to_string(), "0.25".to_string()));
        for (text, key) in [
            ("[lab]\nmass = 0.1\n", "lab.mass"),
            ("[lab]\nRm = -8.4\n", "lab.Rm"),
            ("[lab]\narm_counts = 20.5\n", "lab.arm_counts"),
            ("[lab]\narm_counts = 8\n", "lab.arm_counts"),
        ] {
            assert_eq!(Lab::parse(text).unwrap_err().key, key, "{text}");
        }
        assert!(Lab::parse("mp = 0.1\n")
            .unwrap_err()
            .reason
            .contains("one [lab] table"));
    }
}

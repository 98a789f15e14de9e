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

use crate::plant::{FurutaParams, Param};
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
        let table = match doc.get("lab") {
            Some(toml::Value::Table(t)) if doc.len() == 1 => t,
            _ => {
                return Err(SpecError::new(
                    "",
                    format!("a lab file holds one [lab] table (keys: {})", Self::keys()),
                ))
            }
        };
        let mut values = Vec::new();
        for (key, value) in table {
            let key = Self::key(key)?;
            let number = match value {
                toml::Value::Integer(n) => *n as f64,
                toml::Value::Float(x) if !Self::is_count(key) => *x,
                _ => f64::NAN,
            };
            values.push((key, Self::checked(key, number, &value.to_string())?));
        }
        values.sort_by_key(|(k, _)| LAB_KEYS.iter().position(|(l, _)| l == k));
        Ok(Self { values })
    }

    /// Measurements given as values (a log header's, or Python's `riprs.identify(lab=...)`),
    /// checked like a file's: the error names `lab.KEY`.
    pub fn from_values<'a>(
        given: impl IntoIterator<Item = (&'a str, f64)>,
    ) -> Result<Self, SpecError> {
        let mut values = Vec::new();
        for (key, value) in given {
            let key = Self::key(key)?;
            values.push((key, Self::checked(key, value, &value.to_string())?));
        }
        values.sort_by_key(|(k, _)| LAB_KEYS.iter().position(|(l, _)| l == k));
        Ok(Self { values })
    }

    /// The identification's start set: `start` with the measured parameters in place. A
    /// measured link's centroidal inertia restarts as that of a uniform rod
    /// ([`FurutaParams::rod_inertia`]), since its old inertia belongs to another mass and
    /// length; a measured `km` is the start of `kt` too (SI units, the same motor constant).
    /// A measured `kt` alone leaves `km` as it is: not measured, the fit holds it equal to
    /// `kt` ([`super::IdentifyOptions::km_tied`]).
    pub fn start(&self, start: &FurutaParams) -> FurutaParams {
        let mut p = *start;
        for (key, value) in &self.values {
            if let Some(param) = Param::from_name(key) {
                p.set(param, *value);
            }
        }
        let given = |param: Param| self.get(param.name()).is_some();
        if given(Param::Km) && !given(Param::Kt) {
            p.kt = p.km;
        }
        if given(Param::Mp) || given(Param::Lp) {
            p.jp = FurutaParams::rod_inertia(p.mp, p.lp);
        }
        if given(Param::Mr) || given(Param::Lr) {
            p.jr = FurutaParams::rod_inertia(p.mr, p.lr);
        }
        p
    }

    fn keys() -> String {
        LAB_KEYS.map(|(k, _)| k).join(", ")
    }

    fn is_count(key: &str) -> bool {
        key.ends_with("_counts")
    }

    /// `key` as one of [`LAB_KEYS`], or the error naming it.
    fn key(key: &str) -> Result<&'static str, SpecError> {
        LAB_KEYS
            .iter()
            .map(|(k, _)| *k)
            .find(|k| *k == key)
            .ok_or_else(|| {
                SpecError::new(
                    format!("lab.{key}"),
                    format!("unknown key; the keys are {}", Self::keys()),
                )
            })
    }

    /// The one range rule of a measurement: counts an integer of at least [`MIN_COUNTS`],
    /// the rest positive and finite (`shown` is the value as given, for the error).
    fn checked(key: &'static str, value: f64, shown: &str) -> Result<f64, SpecError> {
        if Self::is_count(key) {
            if value.fract() == 0.0 && value >= MIN_COUNTS as f64 {
                return Ok(value);
            }
            return Err(SpecError::new(
                format!("lab.{key}"),
                format!("must be an integer >= {MIN_COUNTS}, got {shown}"),
            ));
        }
        if value.is_finite() && value > 0.0 {
            return Ok(value);
        }
        Err(SpecError::new(
            format!("lab.{key}"),
            format!("must be a positive number, got {shown}"),
        ))
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
        let given = Lab::from_values([("Lp", 0.25), ("mp", 0.06), ("arm_counts", 2048.0)]);
        assert_eq!(given.unwrap(), lab);
        for (key, value) in [("mass", 0.1), ("Rm", f64::NAN), ("arm_counts", 20.5)] {
            let err = Lab::from_values([(key, value)]).unwrap_err();
            assert_eq!(err.key, format!("lab.{key}"));
        }
        assert!(Lab::parse("mp = 0.1\n")
            .unwrap_err()
            .reason
            .contains("one [lab] table"));
    }

    #[test]
    fn a_measured_link_restarts_as_a_uniform_rod() {
        let q = FurutaParams::qube_servo2();
        let p = Lab::parse("[lab]\nmp = 0.06\nkm = 0.05\n")
            .unwrap()
            .start(&q);
        // Jp = m L²/12 with the new mass and the start's length: 0.06 · 0.129² / 12.
        assert!((p.jp - 0.06 * 0.129 * 0.129 / 12.0).abs() < 1e-15);
        assert_eq!((p.mp, p.lp, p.km, p.kt), (0.06, q.lp, 0.05, 0.05));
        assert_eq!((p.jr, p.mr, p.rm), (q.jr, q.mr, q.rm));
        let both = Lab::parse("[lab]\nkm = 0.05\nkt = 0.04\nLr = 0.1\n")
            .unwrap()
            .start(&q);
        assert_eq!((both.km, both.kt), (0.05, 0.04));
        assert!((both.jr - q.mr * 0.01 / 12.0).abs() < 1e-15);
        assert_eq!(Lab::default().start(&q), q);
    }
}

//! The rig settings an excitation log's header records (`rip-rt excite` writes them, `# key:
//! value` lines) and the rig file's keys they become: the identified rig file carries what
//! `rip-rt run` needs of the rig as it was excited. Each value is checked by the rig file's own
//! check ([`rig_sections::parse_file`]), so that identification never writes a file that
//! `riprs config` or `rip-rt run` refuses; the error names the header key.

use crate::spec::rig_sections;
use crate::spec::SpecError;

/// Each header key and the rig file key it is written to, in the file's order.
pub const HEADER_SETTINGS: [(&str, &str); 8] = [
    ("period_ms", "loop.period_ms"),
    ("arm_counts_per_rev", "sensor.encoder_counts[0]"),
    ("pendulum_counts_per_rev", "sensor.encoder_counts[1]"),
    ("pendulum_zero", "device.pendulum_zero"),
    ("arm_sign", "device.arm_sign"),
    ("pendulum_sign", "device.pendulum_sign"),
    ("voltage_limit", "safety.voltage_limit"),
    ("arm_limit", "safety.arm_limit"),
];

fn header_error(key: &str, reason: impl Into<String>) -> SpecError {
    SpecError::new(format!("header {key}"), reason)
}

/// The rig file's `[loop]`, `[sensor]`, `[device]` and `[safety]` tables of the header
/// settings `given` (`(log, header key, text)`: the log whose header gave the value; keys not
/// in [`HEADER_SETTINGS`] are ignored), checked as the rig file is. The counts per revolution
/// are the file's one resolution, `[sensor] encoder_counts`, written when both are given. The
/// error's key is `header KEY` (the header key whose value the file would refuse) and its file
/// the log that gave it.
pub fn rig_settings<'a>(
    given: impl IntoIterator<Item = (&'a str, &'a str, &'a str)>,
) -> Result<toml::Table, SpecError> {
    let mut table = toml::Table::new();
    let mut counts: [Option<i64>; 2] = [None, None];
    let mut sources: Vec<(&str, &str)> = Vec::new();
    let in_log = |e: SpecError, log: &str| SpecError {
        file: Some(log.to_string()),
        ..e
    };
    for (log, key, text) in given {
        let Some((_, path)) = HEADER_SETTINGS.iter().find(|(k, _)| *k == key) else {
            continue;
        };
        sources.push((key, log));
        let text = text.trim();
        let value = match key {
            "pendulum_zero" => toml::Value::String(text.to_string()),
            "arm_counts_per_rev" | "pendulum_counts_per_rev" => {
                let n = text.parse::<i64>().map_err(|_| {
                    let e = header_error(key, format!("not a whole number of counts: {text:?}"));
                    in_log(e, log)
                })?;
                counts[usize::from(key.starts_with("pendulum"))] = Some(n);
                continue;
            }
            _ => {
                toml::Value::Float(text.parse::<f64>().map_err(|_| {
                    in_log(header_error(key, format!("not a number: {text:?}")), log)
                })?)
            }
        };
        let (section, field) = path.split_once('.').expect("a section and a key");
        section_of(&mut table, section).insert(field.to_string(), value);
    }
    if let [Some(arm), Some(pendulum)] = counts {
        section_of(&mut table, "sensor").insert(
            "encoder_counts".to_string(),
            toml::Value::Array(vec![arm.into(), pendulum.into()]),
        );
    }
    let text = toml::to_string(&table).expect("a table of numbers and strings has a TOML form");
    rig_sections::parse_file(&text).map_err(|e| {
        let e = to_header(&e);
        let key = e.key.trim_start_matches("header ");
        let log = sources.iter().find(|(k, _)| *k == key).or(sources.first());
        in_log(e, log.map_or("", |(_, l)| l))
    })?;
    Ok(table)
}

fn section_of<'t>(table: &'t mut toml::Table, section: &str) -> &'t mut toml::Table {
    table
        .entry(section)
        .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        .as_table_mut()
        .expect("sections are tables")
}

/// A rig file's error as the header's: keyed by the header key written to the file's key, or
/// by the one the reason names (a relation between keys, such as the reply timeout that must
/// be shorter than the period).
fn to_header(e: &SpecError) -> SpecError {
    if let Some((key, _)) = HEADER_SETTINGS.iter().find(|(_, path)| *path == e.key) {
        return header_error(key, e.reason.clone());
    }
    let named = HEADER_SETTINGS
        .iter()
        .find(|(_, path)| e.reason.contains(path.split('[').next().unwrap_or(path)));
    let key = named.map_or("settings", |(k, _)| *k);
    header_error(
        key,
        format!("the rig file would be refused: {}: {}", e.key, e.reason),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_values_the_rig_file_refuses_are_named_by_their_header_key() {
        let good = [
            ("period_ms", "10"),
            ("arm_counts_per_rev", "2048"),
            ("pendulum_counts_per_rev", "4096"),
            ("pendulum_zero", "down"),
            ("arm_sign", "-1"),
            ("voltage_limit", "6"),
            ("arm_limit", "1.2"),
            ("lab.mp", "0.024"),
        ];
        let logs = |given: &[(&'static str, &'static str)]| {
            given
                .iter()
                .map(|(k, v)| (if *k == "arm_limit" { "b.csv" } else { "a.csv" }, *k, *v))
                .collect::<Vec<_>>()
        };
        let table = rig_settings(logs(&good)).unwrap();
        let (_, rig) = rig_sections::parse_file(&toml::to_string(&table).unwrap()).unwrap();
        assert_eq!(rig.device.arm_counts_per_rev, 2048);
        assert_eq!(rig.device.pendulum_counts_per_rev, 4096);
        assert_eq!((rig.device.arm_sign, rig.safety.voltage_limit), (-1.0, 6.0));
        for (key, text) in [
            ("arm_counts_per_rev", "0"),
            ("pendulum_counts_per_rev", "-5"),
            ("arm_counts_per_rev", "2048.5"),
            ("period_ms", "0"),
            ("period_ms", "nan"),
            ("period_ms", "ten"),
            ("pendulum_zero", "sideways"),
            ("arm_sign", "2"),
            ("voltage_limit", "inf"),
            ("arm_limit", "0.1"),
        ] {
            let mut given = good.to_vec();
            given.retain(|(k, _)| *k != key);
            given.push((key, text));
            let e = rig_settings(logs(&given)).unwrap_err();
            assert_eq!(e.key, format!("header {key}"), "{key}: {text}: {e}");
            let log = if key == "arm_limit" { "b.csv" } else { "a.csv" };
            assert_eq!(e.file.as_deref(), Some(log), "{e}");
        }
    }
}

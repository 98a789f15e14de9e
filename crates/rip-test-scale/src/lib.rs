//! The size of the test suite's sweeps, read from `RIPRS_TEST_SCALE` (docs/contributing.md):
//! `small` (the default: the quick and the pull-request tier) or `full` (the full tier). A
//! sweep shrinks inside its test, never by dropping the test: at its small size it keeps the
//! cases that once failed, named at the sweep, and a spread of the rest.
//!
//! `tests/conftest.py` reads the same variable for pytest, by the same rule.

use std::sync::OnceLock;

/// The environment variable that sets the scale.
pub const VARIABLE: &str = "RIPRS_TEST_SCALE";

/// The size the suite's sweeps run at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Each sweep at its small size (the quick and the pull-request tier).
    Small,
    /// Each sweep at its full size (the full tier).
    Full,
}

/// The scale of this run: `RIPRS_TEST_SCALE`, `small` when it is unset.
///
/// # Panics
/// On any other value than `small` or `full`, naming the variable: a typo must not run the
/// small sweeps in a run that asked for the full ones.
pub fn scale() -> Scale {
    static SCALE: OnceLock<Scale> = OnceLock::new();
    *SCALE.get_or_init(|| match std::env::var(VARIABLE) {
        Err(std::env::VarError::NotPresent) => Scale::Small,
        Ok(v) if v == "small" => Scale::Small,
        Ok(v) if v == "full" => Scale::Full,
        Ok(v) => panic!("{VARIABLE} must be \"small\" or \"full\", got {v:?}"),
        Err(e) => panic!("{VARIABLE}: {e}"),
    })
}

/// Whether the sweeps run at their full size.
pub fn full() -> bool {
    scale() == Scale::Full
}

/// `full` at the full scale, else `small`: a sweep's size.
pub fn size<T>(small: T, full: T) -> T {
    match scale() {
        Scale::Small => small,
        Scale::Full => full,
    }
}

/// The cases of a sweep at this scale: every case at the full scale; at the small one the
/// cases for which `keep` holds (those that once failed, and a spread of the rest).
pub fn cases<T>(all: impl IntoIterator<Item = T>, keep: impl FnMut(&T) -> bool) -> Vec<T> {
    let all = all.into_iter();
    match scale() {
        Scale::Full => all.collect(),
        Scale::Small => all.filter(keep).collect(),
    }
}

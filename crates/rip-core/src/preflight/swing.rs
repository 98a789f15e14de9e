//! The pre-flight's **swing_up** check: whether the rig can be swung up at all, for a run that
//! starts hanging (`rip-rt run --swing-up`).
//!
//! The verdict is rip-core's energy balance of the last swing
//! ([`crate::swingup::feasibility()`]): the one `riprs tune` stored in the tuning record beside
//! the rig file ([`super::tune_record_path`]) while its checksum matches the model and the
//! swing-up's bounds, otherwise computed now ([`crate::swingup::stored_or_computed`]). A rig
//! the balance declares impossible refuses, naming the key whose bound is short and what it
//! would need; a rig it does not exclude passes, saying where the verdict came from. The
//! balance is a necessary condition: a rig that passes may still not swing up. Where the
//! record also holds the swing-up search of `riprs tune` ([`crate::tune::swing`]) made on this
//! design, a rig whose search did not find a swing-up that every controller holds (each
//! one's Wilson lower bound of the catches held at least the one the search needed, and its
//! share of runs within two passes over the top too) refuses for every
//! controller, naming those that fell short: the swing is the same whichever controller
//! catches, and a rig whose catches one controller cannot hold is a rig whose swing-up was
//! not found, however its other controllers did on that sample.

use crate::swingup::{stored_or_computed, Feasibility, SwingUpMethod, Verdict as Balance};
use serde::{Deserialize, Serialize};

use crate::spec::ControllerKind;

use super::{tune_record_path, Finding, Input, Verdict};

/// The key a refusal names: the voltage where more of it would do (or where nothing named
/// would), otherwise the arm travel, the one bound left that could.
fn short_key(f: &Feasibility) -> &'static str {
    if f.voltage_needed.is_some() || f.arm_travel_needed.is_none() {
        "swing_up.max_voltage"
    } else {
        "swing_up.arm_limit"
    }
}

/// The swing_up check (module docs); `None` when the run does not swing up.
pub fn swing_up(input: &Input<'_>) -> Option<Finding> {
    if !input.swing_up {
        return None;
    }
    let spec = input.design.spec();
    let plant = match spec.plant() {
        Ok(p) => p,
        Err(e) => return Some(Finding::new("swing_up", Verdict::Refuse, e.to_string())),
    };
    let record = input.rig_file.map(tune_record_path);
    let (f, source) = stored_or_computed(&plant, &spec.swing_up, record.as_deref());
    Some(match f.verdict {
        Balance::Impossible => Finding::new(
            "swing_up",
            Verdict::Refuse,
            format!(
                "{}: {f} (verdict {source}); change the rig or its [swing_up] settings, or \
                 pass --force",
                short_key(&f)
            ),
        ),
        Balance::NotExcluded => match stored_search(input, record.as_deref()) {
            Some(search) if search.verdict != SwingVerdict::Found => Finding::new(
                "swing_up",
                Verdict::Refuse,
                format!(
                    "swing_up: riprs tune found no swing-up that every controller holds \
                     (verdict {}): {}; change the rig or its [swing_up] settings and tune \
                     again, or pass --force",
                    search.verdict.name(),
                    search.shortfalls()
                ),
            ),
            Some(search) => Finding::new(
                "swing_up",
                Verdict::Pass,
                format!(
                    "{f}; {} (verdict {source})",
                    search.describe(input.controller)
                ),
            ),
            None => Finding::new("swing_up", Verdict::Pass, format!("{f} (verdict {source})")),
        },
    })
}

/// The swing-up search `riprs tune` stored in the record at `record`, when it was made on
/// this design (its `[swing_up]` included); a stale or unreadable one is not used.
fn stored_search(input: &Input<'_>, record: Option<&std::path::Path>) -> Option<StoredSwingSearch> {
    let text = crate::spec::read_text(record?).ok()?;
    StoredSwingSearch::from_record(&text)
        .filter(|s| s.inputs == super::design_checksum(input.design))
}

/// What the swing-up search of `riprs tune` found (`crate::tune::swing`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SwingVerdict {
    /// Every controller's lower bound at least the one needed
    /// (`crate::tune::swing::FOUND_LOWER_BOUND`), and its share of runs within two passes
    /// over the top too (`crate::tune::swing::FOUND_WITHIN_TWO`).
    Found,
    /// The best settings tried leave a controller short of either.
    NotFound,
    /// The energy bound forbids a swing-up of the nominal rig.
    Impossible,
}

impl SwingVerdict {
    /// `"found"`, `"not_found"` or `"impossible"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Found => "found",
            Self::NotFound => "not_found",
            Self::Impossible => "impossible",
        }
    }
}

/// One controller's confirmation as the tuning record stores it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredStudy {
    /// Runs judged: the draws less those excluded by the energy bound.
    pub runs: u64,
    /// Draws excluded by the energy bound.
    pub excluded: u64,
    /// Successes (caught and held 3 s).
    pub held: u64,
    /// The Wilson 95 % lower bound of the success rate.
    pub lower_bound: f64,
    /// Runs that passed over the top at most twice before the catch (0 in a record written
    /// before it was stored).
    #[serde(default)]
    pub within_two: u64,
}

impl StoredStudy {
    /// The share of the runs that passed over the top at most twice before the catch.
    pub fn within_two_share(&self) -> f64 {
        self.within_two as f64 / self.runs as f64
    }
}

/// The planned swing-up a search kept (`swing_up.method = "trajectory"`), as the record
/// stores it: how long it takes and what it leaves of the bounds on the nominal model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredPlan {
    /// From hanging at rest to upright (s).
    pub duration_s: f64,
    /// The swing-up's voltage bound (after the compensation's share) less the plan's
    /// largest `|u|` (V).
    pub voltage_left: f64,
    /// `swing_up.arm_limit` less the plan's largest `|θ|` (rad).
    pub arm_left: f64,
    /// How many times the plan's pendulum rises into the upper half (`|α| < π/2`), the last
    /// time to upright: 1 where the plan reaches upright on its first rise
    /// (`crate::swingup::plan::rises`); 0 in a record written before it was stored.
    #[serde(default)]
    pub rises: u32,
}

/// A swing-up search (`crate::tune::swing::SwingSearch`) as the tuning record's
/// `[swing_up_search]` table stores it, for `rip-rt run --swing-up`'s pre-flight.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredSwingSearch {
    /// [`crate::preflight::design_checksum`] of the tuned design, its `[swing_up]` the
    /// settings kept.
    pub inputs: String,
    /// The search's verdict.
    pub verdict: SwingVerdict,
    /// The Wilson lower bound a controller needed to hold its catches.
    pub needed: f64,
    /// The share of runs within two passes over the top a controller needed (0 in a record
    /// written before it was asked for).
    #[serde(default)]
    pub needed_within_two: f64,
    /// The method kept (`swing_up.method`); a record written before the method was stored
    /// reads as the energy law, the only one searched then.
    #[serde(default)]
    pub method: SwingUpMethod,
    /// The plan's margins, when the method kept is the plan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<StoredPlan>,
    /// Per controller (`"LQR"`, `"LQG"`, `"MPC"`), its confirmation.
    #[serde(default)]
    pub confirmed: std::collections::BTreeMap<String, StoredStudy>,
}

impl StoredSwingSearch {
    /// The record's `[swing_up_search]` table, with a comment saying what it is.
    pub fn to_section(&self) -> String {
        #[derive(Serialize)]
        struct Section<'a> {
            swing_up_search: &'a StoredSwingSearch,
        }
        format!(
            "\n# The swing-up's settings searched by Monte Carlo (rip_core::tune::swing), read by\n\
             # rip-rt run --swing-up while `inputs` is the checksum of its design.\n{}",
            toml::to_string(&Section {
                swing_up_search: self
            })
            .expect("every value has a TOML form")
        )
    }

    /// The `[swing_up_search]` table of the TOML `text`, if it has one that parses.
    pub fn from_record(text: &str) -> Option<Self> {
        let mut table: toml::Table = toml::from_str(text).ok()?;
        table.remove("swing_up_search")?.try_into().ok()
    }

    /// Whether the search found a swing-up that `controller` holds: its own confirmation's
    /// lower bound of the catches held at least the one `needed`, and its share of runs
    /// within two passes over the top at least the one needed (the rig's verdict is *found*
    /// when every controller's are).
    pub fn holds(&self, controller: ControllerKind) -> bool {
        self.confirmed.get(controller.name()).is_some_and(|s| {
            s.lower_bound >= self.needed && s.within_two_share() >= self.needed_within_two
        })
    }

    /// The controllers that do not hold their catches ([`Self::holds`]), each in one phrase;
    /// the verdict alone when no controller was confirmed.
    pub fn shortfalls(&self) -> String {
        let short: Vec<String> = ControllerKind::ALL
            .into_iter()
            .filter(|&k| self.confirmed.contains_key(k.name()) && !self.holds(k))
            .map(|k| self.describe(k))
            .collect();
        if short.is_empty() {
            format!("the swing-up search was {}", self.verdict.name())
        } else {
            short.join("; ")
        }
    }

    /// What the stored search says of `controller`, in one phrase.
    pub fn describe(&self, controller: ControllerKind) -> String {
        match self.confirmed.get(controller.name()) {
            Some(s) => {
                let mut said = format!(
                    "the searched swing-up held {} of {} catches 3 s with the {} (Wilson 95 % \
                     lower bound {:.1} %, {:.0} % needed)",
                    s.held,
                    s.runs,
                    controller.name(),
                    100.0 * s.lower_bound,
                    100.0 * self.needed
                );
                if s.within_two_share() < self.needed_within_two {
                    said += &format!(
                        " and passed over the top at most twice before the catch in {} of {} \
                         runs ({:.0} % needed)",
                        s.within_two,
                        s.runs,
                        100.0 * self.needed_within_two
                    );
                }
                said
            }
            None => format!("the swing-up search was {}", self.verdict.name()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preflight::run;
    use crate::spec::{ControllerKind, Spec};

    fn report(text: &str, swing_up: bool) -> crate::preflight::Report {
        let design = Spec::parse(text).unwrap().design(crate::paper::TS).unwrap();
        run(&Input {
            design: &design,
            controller: ControllerKind::Lqr,
            rig_file: None,
            arm_limit: Some(2.0),
            swing_up,
        })
    }

    #[test]
    fn a_rig_too_weak_to_swing_up_is_refused_naming_the_voltage_it_needs() {
        let weak = report("[swing_up]\nmax_voltage = 0.05\n", true);
        let f = weak.finding("swing_up").unwrap();
        assert_eq!(f.verdict, Verdict::Refuse, "{weak}");
        assert!(f.message.starts_with("swing_up.max_voltage: "), "{f}");
        assert!(f.message.contains("no swing-up is possible"), "{f}");
        assert!(f.message.contains("it would need about"), "{f}");
        assert!(f.message.contains("computed now (no rig file)"), "{f}");
        assert!(f.message.ends_with("or pass --force"), "{f}");
        // The balance controller is not what is refused.
        assert_eq!(weak.refusals().count(), 1, "{weak}");
    }

    #[test]
    fn the_default_rig_passes_and_a_balance_run_is_not_checked() {
        let swing = report("", true);
        let f = swing.finding("swing_up").unwrap();
        assert_eq!(f.verdict, Verdict::Pass, "{swing}");
        assert!(f.message.contains("a swing-up is not excluded"), "{f}");
        assert!(!swing.refused(), "{swing}");
        let balance = report("[swing_up]\nmax_voltage = 0.05\n", false);
        assert!(balance.finding("swing_up").is_none(), "{balance}");
    }
}

//! The pre-flight check: what is known, before the motor is enabled, about whether a controller
//! will balance the rig it is about to run on (and, for a run that starts hanging, whether the
//! rig can be swung up at all).
//!
//! One list of checks ([`CHECKS`]) runs over the same input ([`Input`]: the designed
//! controllers of the experiment file, the controller chosen, the rig file, whether the run
//! swings up); each gives a [`Finding`] that passes, warns or refuses with its reason. `rip-rt
//! run` runs them after the controller design and before the port is opened, and refuses a
//! run that any check refuses (exit 16) unless `--force` is given.
//!
//! The checks, in order:
//!
//! - **identification** — the rig file was written by `riprs identify --force` despite failed
//!   checks: its header carries the line `# UNTRUSTED`, or the identification file beside it
//!   (`rig.identification.toml`) says `[identification] trusted = false`, or the tuning record
//!   beside it (`rig.tune.toml`, [`untrusted_section`]) carries that verdict from the rig
//!   `riprs tune` tuned; or that identification file is there but cannot say (not a regular
//!   file, too large, not UTF-8, not TOML, no `[identification] trusted` true or false),
//!   which refuses too.
//! - **voltage** — no controller can balance the rig at the voltage bound. Near upright the
//!   linearised plant `ẋ = A_c x + B_c u` has one unstable pole `p > 0`; with `wᵀ` its left
//!   eigenvector, the unstable mode `z = wᵀ x` obeys `ż = p z + (wᵀ B_c) u` whatever the
//!   controller, so it returns towards 0 only while
//!
//!   ```text
//!   |u_effective| > p |z| / |wᵀ B_c| = V_mode(x)
//!   ```
//!
//!   The voltage that reaches the motor is the written one less the dead zone `V_d` and the
//!   voltage `V_f = C_r R_m / k_t` that balances the arm's Coulomb friction, so a rig whose
//!   `V_mode(x₀) + V_d + V_f` (at the start state `x₀`) exceeds the bound cannot be balanced
//!   from `x₀` by any controller: the finding names that voltage. It is a necessary
//!   condition only; a rig that passes it may still fail, which the next check finds.
//! - **prediction** — the controller as it runs (its compensation and integral action
//!   included) in closed loop with the rig's nonlinear model (`[plant]`, its dead zone,
//!   friction and stiction; `[sensor]`; the `[reference]` step), three noise seeds of at most
//!   [`PREDICTION_HORIZON`] seconds, faster than real time. A run that falls, diverges or
//!   carries the arm past `safety.arm_limit` refuses, naming the seed, the time and the
//!   angle. A controller too slow to simulate within [`PREDICTION_BUDGET`] is not predicted
//!   (a warning): the loop's timing probe judges it. A current tuning record beside the rig
//!   file ([`tune_record_path`]) stands for the simulation; a record that is there but cannot
//!   be read (not a regular file, too large, not a record) refuses, and so does a controller
//!   the record says misses the rig's bar (`riprs tune`'s `SHORT`), with the tuning's reason.
//! - **swing_up** — for a run that swings up ([`Input::swing_up`]) only: the rig cannot be
//!   swung up at all by rip-core's energy balance of the last swing
//!   ([`crate::swingup::feasibility()`]), whatever the law. The verdict is the one `riprs tune`
//!   stored in the tuning record beside the rig file while its checksum matches, otherwise
//!   computed now ([`crate::swingup::stored_or_computed`]). A refusal names the key whose
//!   bound is short (`swing_up.max_voltage` or `swing_up.arm_limit`) and what it would need; a
//!   pass says where the verdict came from ([`swing`]).
//!
//! Every file beside the rig file is read as the experiment file is
//! ([`crate::spec::read_text`]): regular files only, bounded in size, so that a FIFO or a
//! device named like a record can neither hang the check nor fill its memory.
//!
//! Further checks (a stored tuning's verdict) join by adding a function to [`CHECKS`]; each
//! returns `None` when it does not apply to the input.

use std::fmt;
use std::path::{Path, PathBuf};

use nalgebra::DMatrix;

use serde::{Deserialize, Serialize};

use crate::linalg::Mat;

pub mod motion;
pub mod swing;
use crate::sim::simulate;
use crate::spec::{ControllerKind, Design};
pub use motion::{
    check_excitation, check_swing_up, fit_swing_up, largest_excitation_amplitude,
    largest_swing_arm_limit,
};

/// Longest simulated run (s) of the prediction check: long enough to see a limit cycle build
/// up or the arm settle after the paper's step at 1 s.
pub const PREDICTION_HORIZON: f64 = 10.0;

/// Longest time (s) the prediction check may take; a controller whose simulation would take
/// longer is not predicted (a warning).
pub const PREDICTION_BUDGET: f64 = 3.0;

/// Noise seeds of the prediction check.
pub const PREDICTION_SEEDS: [u64; 3] = [1, 2, 3];

/// What a check concluded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Nothing against the run.
    Pass,
    /// Something to know, not enough to refuse.
    Warn,
    /// The run is refused unless forced.
    Refuse,
}

impl Verdict {
    /// `"pass"`, `"warn"` or `"refuse"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Pass => "pass",
            Self::Warn => "warn",
            Self::Refuse => "refuse",
        }
    }
}

/// One check's conclusion and its reason (the prediction, the margin, the voltage needed).
#[derive(Debug, Clone, PartialEq)]
pub struct Finding {
    /// The check (`"identification"`, `"voltage"`, `"prediction"`, ...).
    pub check: &'static str,
    /// What it concluded.
    pub verdict: Verdict,
    /// Why, in a sentence a user can act on.
    pub message: String,
}

impl Finding {
    fn new(check: &'static str, verdict: Verdict, message: impl Into<String>) -> Self {
        Self {
            check,
            verdict,
            message: message.into(),
        }
    }
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} [{}]: {}",
            self.check,
            self.verdict.name(),
            self.message
        )
    }
}

/// What the checks look at.
#[derive(Debug, Clone, Copy)]
pub struct Input<'a> {
    /// The designed controllers of the experiment file (at the loop's sample time, with the
    /// input bounds the loop will send).
    pub design: &'a Design,
    /// The controller about to run.
    pub controller: ControllerKind,
    /// The experiment file the rig came from, if any (for the identification's marker).
    pub rig_file: Option<&'a Path>,
    /// `safety.arm_limit` (rad), when the caller enforces one: a predicted arm beyond it is a
    /// refusal.
    pub arm_limit: Option<f64>,
    /// Whether the run starts hanging and swings up (`rip-rt run --swing-up`): only then does
    /// the swing_up check apply.
    pub swing_up: bool,
}

/// A check: `None` when it does not apply to the input.
pub type Check = fn(&Input<'_>) -> Option<Finding>;

/// Every check, in the order they run (module docs).
pub const CHECKS: [Check; 4] = [identification, voltage, prediction, swing::swing_up];

/// The findings of every check.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// One per check that applied, in [`CHECKS`] order.
    pub findings: Vec<Finding>,
}

impl Report {
    /// Whether any check refused the run.
    pub fn refused(&self) -> bool {
        self.refusals().next().is_some()
    }

    /// The refusing findings.
    pub fn refusals(&self) -> impl Iterator<Item = &Finding> {
        self.findings
            .iter()
            .filter(|f| f.verdict == Verdict::Refuse)
    }

    /// The finding of `check`, if it ran.
    pub fn finding(&self, check: &str) -> Option<&Finding> {
        self.findings.iter().find(|f| f.check == check)
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, finding) in self.findings.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{finding}")?;
        }
        Ok(())
    }
}

/// Runs every check of [`CHECKS`] on `input`.
pub fn run(input: &Input<'_>) -> Report {
    Report {
        findings: CHECKS.iter().filter_map(|check| check(input)).collect(),
    }
}

/// The identification file beside a rig file: `rig.toml` → `rig.identification.toml` (as
/// `riprs identify` writes it).
pub fn identification_path(rig: &Path) -> PathBuf {
    let stem = rig.file_stem().map(|s| s.to_string_lossy().into_owned());
    rig.with_file_name(format!("{}.identification.toml", stem.unwrap_or_default()))
}

/// Whether anything is at `path`, a dangling symbolic link included: a record that is there
/// but cannot be read is a refusal, not an absence.
fn present(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok()
}

/// Why the rig file is untrusted by its identification, if it is, or why the identification
/// file beside it cannot say (module docs).
pub fn untrusted_reason(rig: &Path) -> Option<String> {
    if let Ok(text) = crate::spec::read_text(rig) {
        let marked = text
            .lines()
            .take_while(|l| l.trim_start().starts_with('#') || l.trim().is_empty())
            .any(|l| {
                l.trim_start()
                    .trim_start_matches('#')
                    .trim_start()
                    .starts_with("UNTRUSTED")
            });
        if marked {
            return Some(format!(
                "{} is marked UNTRUSTED: riprs identify wrote it with --force despite failed \
                 checks (its header lists them)",
                rig.display()
            ));
        }
    }
    // A tuned file keeps its rig's verdict in its record: nothing lies beside it.
    let record = tune_record_path(rig);
    if let Some(reason) = recorded_untrusted(&record) {
        return Some(format!(
            "{reason} (recorded by riprs tune in {})",
            record.display()
        ));
    }
    let side = identification_path(rig);
    if !present(&side) {
        return None;
    }
    let unreadable = |e: crate::spec::SpecError| {
        Some(format!(
            "{e}: the identification beside the rig file cannot say whether it is trusted"
        ))
    };
    let table = match crate::spec::read_text(&side)
        .and_then(|text| crate::spec::parse_table(&text).map_err(|e| e.in_file(&side)))
    {
        Ok(table) => table,
        Err(e) => return unreadable(e),
    };
    let ident = table.get("identification").and_then(toml::Value::as_table);
    let trusted = ident.and_then(|i| i.get("trusted"));
    let Some(trusted) = trusted.and_then(toml::Value::as_bool) else {
        let got = trusted.map_or_else(|| "nothing".to_string(), ToString::to_string);
        let e = crate::spec::SpecError::new(
            "identification.trusted",
            format!("must be true or false, got {got}"),
        );
        return unreadable(e.in_file(&side));
    };
    if trusted {
        return None;
    }
    let ident = ident?;
    let problems: Vec<&str> = ident
        .get("problems")
        .and_then(|p| p.as_array())
        .map(|a| a.iter().filter_map(|v| v.as_str()).collect())
        .unwrap_or_default();
    Some(format!(
        "{} says the identification is not trusted{}",
        side.display(),
        if problems.is_empty() {
            String::new()
        } else {
            format!(": {}", problems.join("; "))
        }
    ))
}

/// The `[identification]` table `riprs tune` adds to its record ([`tune_record_path`]) when
/// the rig it tuned is untrusted ([`untrusted_reason`] of the rig file): the verdict then
/// travels with the tuned file, which has no identification file beside it.
pub fn untrusted_section(reason: &str) -> String {
    let mut table = toml::Table::new();
    table.insert("trusted".into(), toml::Value::Boolean(false));
    table.insert("reason".into(), toml::Value::String(reason.into()));
    let mut doc = toml::Table::new();
    doc.insert("identification".into(), toml::Value::Table(table));
    toml::to_string(&doc).expect("strings and booleans have a TOML form")
}

/// The reason of an [`untrusted_section`] in the record at `path`, if it holds one. A record
/// that cannot be read (not a regular file, too large, not TOML) holds none here: the tuning
/// check refuses it.
fn recorded_untrusted(path: &Path) -> Option<String> {
    let bytes = crate::files::read_regular(path).ok()?;
    let table: toml::Table = std::str::from_utf8(&bytes).ok()?.parse().ok()?;
    let ident = table.get("identification")?.as_table()?;
    if ident.get("trusted")?.as_bool()? {
        return None;
    }
    Some(ident.get("reason")?.as_str()?.to_string())
}

fn identification(input: &Input<'_>) -> Option<Finding> {
    let rig = input.rig_file?;
    Some(match untrusted_reason(rig) {
        Some(reason) => Finding::new(
            "identification",
            Verdict::Refuse,
            format!("{reason}; identify the rig again, or pass --force to run it as it is"),
        ),
        None => Finding::new(
            "identification",
            Verdict::Pass,
            format!("{} is not marked untrusted", rig.display()),
        ),
    })
}

/// The voltage the unstable mode needs at state `x` (module docs, "voltage"): `p |wᵀx| / |wᵀB|`
/// for the continuous model `(a, b)`, with `p` its unstable pole; `None` when the model has no
/// unstable real pole.
pub fn mode_voltage(a: &Mat, b: &Mat, x: &[f64; 4]) -> Option<(f64, f64)> {
    let at = a.transpose();
    let eig = crate::linalg::eigenvalues(a);
    let p = eig
        .iter()
        .filter(|l| l.im.abs() < 1e-9 * (1.0 + l.re.abs()) && l.re > 1e-9)
        .map(|l| l.re)
        .fold(f64::NAN, f64::max);
    if !p.is_finite() {
        return None;
    }
    // wᵀ spans the null space of (Aᵀ − p I): the right singular vector of its smallest
    // singular value.
    let m: DMatrix<f64> = &at - DMatrix::<f64>::identity(4, 4) * p;
    let svd = m.svd(false, true);
    let vt = svd.v_t?;
    let (i_min, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let w = vt.row(i_min).transpose();
    let wb = (w.transpose() * b)[(0, 0)];
    let wx: f64 = (0..4).map(|i| w[i] * x[i]).sum();
    if wb == 0.0 {
        return Some((f64::INFINITY, p));
    }
    Some(((p * wx / wb).abs(), p))
}

/// The voltage check (module docs): whether any controller can balance the rig of
/// `input.design` from its start state within its voltage bound; `None` when the model has no
/// unstable mode. `riprs tune` runs it before its search.
pub fn voltage(input: &Input<'_>) -> Option<Finding> {
    let spec = input.design.spec();
    let (ac, bc) = spec.continuous_design_model().ok()?;
    let p = spec.plant.params();
    let x0 = spec.plant.initial_state;
    let (v_mode, pole) = mode_voltage(&ac, &bc, &x0)?;
    let friction = if p.kt > 0.0 { p.cr * p.rm / p.kt } else { 0.0 };
    let need = v_mode + p.vd + friction;
    let (lo, hi) = spec.mpc.input_bounds[0];
    let bound = hi.min(-lo);
    let detail = format!(
        "from the start state (pendulum {:.3} rad) the unstable mode (pole {pole:.2} 1/s) needs \
         {v_mode:.2} V, the dead zone {:.2} V and the arm friction {friction:.2} V: {need:.2} V \
         of the ±{bound:.2} V bound",
        x0[2], p.vd
    );
    Some(if need >= bound {
        Finding::new(
            "voltage",
            Verdict::Refuse,
            format!(
                "no controller can balance this rig at ±{bound:.2} V: {detail}; it would need \
                 at least {need:.2} V"
            ),
        )
    } else {
        Finding::new("voltage", Verdict::Pass, detail)
    })
}

/// The tuning record beside a tuned file: `tuned.toml` → `tuned.tune.toml`.
pub fn tune_record_path(rig: &Path) -> PathBuf {
    let stem = rig.file_stem().map(|s| s.to_string_lossy().into_owned());
    rig.with_file_name(format!("{}.tune.toml", stem.unwrap_or_default()))
}

/// The checksum of everything a design's predicted behaviour depends on: the experiment
/// (its canonical TOML, presets resolved), the sample time and the planned input bounds.
/// 64-bit FNV-1a, written `fnv1a64:` and 16 hex digits; it detects edits, not tampering.
pub fn design_checksum(design: &Design) -> String {
    let spec = design.spec().resolved().to_toml();
    let (lo, hi) = design.bounds();
    let bits: Vec<u8> = [design.ts(), lo, hi]
        .iter()
        .flat_map(|v| v.to_bits().to_le_bytes())
        .collect();
    crate::checksum::fnv1a64(&[spec.as_bytes(), &bits])
}

/// What `riprs tune` predicted for one controller, as stored in its record.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredPrediction {
    /// Whether a predicted run fell or diverged.
    pub fell: bool,
    /// Largest `|θ|` over the predicted runs (rad).
    pub arm_max: f64,
    /// Steady-state arm peak-to-peak (rad).
    pub arm_peak_to_peak: f64,
    /// Steady-state largest `|α|` (rad).
    pub pendulum: f64,
    /// Balanced disk margin at the plant input.
    pub disk_margin: f64,
    /// Whether it met the whole bar of the tuning.
    pub works: bool,
    /// What of the rig's bar it misses, when it did not work.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub misses: Option<String>,
}

/// The record `riprs tune` writes beside the tuned file ([`tune_record_path`]): the checksum
/// of the inputs it was computed from and each controller's prediction. Other sections (a
/// swing-up verdict) may sit beside these; readers ignore what they do not know.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TuneRecord {
    /// [`design_checksum`] of the design the predictions were made on.
    pub inputs: String,
    /// Noise seeds and length of the predicted runs, for the message.
    pub runs: String,
    /// Per controller (`"LQR"`, `"LQG"`, `"MPC"`), its prediction.
    pub prediction: std::collections::BTreeMap<String, StoredPrediction>,
}

impl TuneRecord {
    /// The record as TOML, with a comment saying what it is.
    pub fn to_toml(&self) -> String {
        format!(
            "# Written by riprs tune beside the tuned file: what it predicted for each controller.\n\
             # rip-rt run's pre-flight reads it while `inputs` is the checksum of its design.\n{}",
            toml::to_string(self).expect("every record value has a TOML form")
        )
    }

    /// The record in the file at `path`, read as the experiment file is
    /// ([`crate::spec::read_text`]: regular files only, bounded); the error names the file and
    /// what is wrong.
    pub fn read(path: &Path) -> Result<Self, crate::spec::SpecError> {
        let text = crate::spec::read_text(path)?;
        let table = crate::spec::parse_table(&text).map_err(|e| e.in_file(path))?;
        crate::spec::from_value(toml::Value::Table(table), "").map_err(|e| e.in_file(path))
    }
}

/// The prediction finding from a stored record, when `input.rig_file` has one matching the
/// design, or a refusal when it has one that cannot be read; otherwise `Err` with a note to
/// add to a recomputed finding (empty when there is no record).
fn stored_prediction(input: &Input<'_>) -> Result<Finding, String> {
    let Some(rig) = input.rig_file else {
        return Err(String::new());
    };
    let path = tune_record_path(rig);
    if !present(&path) {
        return Err(String::new());
    }
    let record = match TuneRecord::read(&path) {
        Ok(record) => record,
        Err(e) => {
            return Ok(Finding::new(
                "prediction",
                Verdict::Refuse,
                format!(
                    "{e}: the tuning record beside the rig file cannot be read; remove it or \
                     tune the rig again (riprs tune), or pass --force"
                ),
            ))
        }
    };
    let kind = input.controller;
    let stored = record.prediction.get(kind.name());
    let Some(p) = stored.filter(|_| record.inputs == design_checksum(input.design)) else {
        return Err(format!(
            " ({} is stale, from other inputs: recomputed)",
            path.display()
        ));
    };
    let from = format!(
        "stored by riprs tune in {} ({})",
        path.display(),
        record.runs
    );
    if p.fell {
        return Ok(Finding::new(
            "prediction",
            Verdict::Refuse,
            format!(
                "{} is predicted to fall on this rig: {from}; tune the rig again or pass --force",
                kind.name()
            ),
        ));
    }
    if let Some(limit) = input.arm_limit {
        if p.arm_max > limit {
            return Ok(Finding::new(
                "prediction",
                Verdict::Refuse,
                format!(
                    "{} is predicted to carry the arm to {:.2} rad on this rig, past \
                     safety.arm_limit ({limit:.2} rad): {from}; tune the rig or pass --force",
                    kind.name(),
                    p.arm_max
                ),
            ));
        }
    }
    // A controller the tuning found short of the rig's bar is refused: it balances the model,
    // but not as well as the bar asks of every controller on this rig.
    Ok(Finding::new(
        "prediction",
        if p.works {
            Verdict::Pass
        } else {
            Verdict::Refuse
        },
        format!(
            "{} balances the rig's model: {from}: arm within {:.2} rad, steady-state arm \
             peak-to-peak {:.3} rad, pendulum within {:.3} rad, disk margin {:.2}{}",
            kind.name(),
            p.arm_max,
            p.arm_peak_to_peak,
            p.pendulum,
            p.disk_margin,
            match (&p.misses, p.works) {
                (_, true) => String::new(),
                (Some(why), false) =>
                    format!("; but {why}; choose another controller or pass --force"),
                (None, false) => {
                    "; but it misses the tuning's bar; choose another controller or pass --force"
                        .to_string()
                }
            }
        ),
    ))
}

fn prediction(input: &Input<'_>) -> Option<Finding> {
    let note = match stored_prediction(input) {
        Ok(finding) => return Some(finding),
        Err(note) => note,
    };
    let mut finding = simulated_prediction(input)?;
    finding.message.push_str(&note);
    Some(finding)
}

fn simulated_prediction(input: &Input<'_>) -> Option<Finding> {
    let design = input.design;
    let spec = design.spec();
    let kind = input.controller;
    let plant = match spec.plant() {
        Ok(p) => p,
        Err(e) => return Some(Finding::new("prediction", Verdict::Refuse, e.to_string())),
    };
    let mut controller = match design.controller(kind) {
        Ok(c) => c,
        Err(e) => return Some(Finding::new("prediction", Verdict::Refuse, e.to_string())),
    };
    // A controller too slow to simulate in the budget (a long MPC horizon) is left to the
    // loop's own timing probe: the pre-flight must not hold the run for long.
    let steps = (spec.reference.duration.min(PREDICTION_HORIZON) / design.ts()).ceil();
    let per_step = {
        let start = std::time::Instant::now();
        let mut u = [0.0];
        for _ in 0..10 {
            controller.step(&[0.0, 0.01], &[0.0, 0.0], &mut u);
        }
        start.elapsed().as_secs_f64() / 10.0
    };
    let estimate = per_step * steps * PREDICTION_SEEDS.len() as f64;
    if estimate > PREDICTION_BUDGET {
        return Some(Finding::new(
            "prediction",
            Verdict::Warn,
            format!(
                "not predicted: {} takes {:.2} ms a step, {estimate:.1} s to simulate, more \
                 than the pre-flight's {PREDICTION_BUDGET} s",
                kind.name(),
                per_step * 1e3
            ),
        ));
    }
    let mut worst_arm = 0.0f64;
    let mut worst_alpha = 0.0f64;
    let mut horizon = 0.0;
    for seed in PREDICTION_SEEDS {
        let mut cfg = spec.sim_config(design.ts(), seed);
        cfg.duration = cfg.duration.min(PREDICTION_HORIZON);
        horizon = cfg.duration;
        let out = match simulate(&plant, controller.as_mut(), &cfg) {
            Ok(out) => out,
            Err(e) => {
                return Some(Finding::new(
                    "prediction",
                    Verdict::Refuse,
                    format!("the simulation of {} on this rig fails: {e}", kind.name()),
                ))
            }
        };
        let arm = out.x.iter().map(|x| x[0].abs()).fold(0.0, f64::max);
        let alpha = out.x.iter().map(|x| x[2].abs()).fold(0.0, f64::max);
        worst_arm = worst_arm.max(arm);
        worst_alpha = worst_alpha.max(alpha);
        if out.fell || out.diverged {
            let when = out
                .fall_time
                .map_or_else(String::new, |t| format!(" at t = {t:.2} s"));
            return Some(Finding::new(
                "prediction",
                Verdict::Refuse,
                format!(
                    "{} is predicted to fall on this rig: in a simulation of its nonlinear \
                     model (seed {seed}) the pendulum left ±{:.2} rad{when}; tune the rig \
                     (riprs tune) or pass --force",
                    kind.name(),
                    spec.plant.fall_limit
                ),
            ));
        }
        if let Some(limit) = input.arm_limit {
            if arm > limit {
                return Some(Finding::new(
                    "prediction",
                    Verdict::Refuse,
                    format!(
                        "{} is predicted to carry the arm to {arm:.2} rad on this rig (seed \
                         {seed}), past safety.arm_limit ({limit:.2} rad); tune the rig \
                         (riprs tune) or pass --force",
                        kind.name()
                    ),
                ));
            }
        }
    }
    Some(Finding::new(
        "prediction",
        Verdict::Pass,
        format!(
            "{} balances the rig's model in {} simulated runs of {horizon:.1} s: pendulum within \
             {worst_alpha:.3} rad, arm within {worst_arm:.2} rad",
            kind.name(),
            PREDICTION_SEEDS.len()
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::Spec;

    #[test]
    fn the_paper_rig_passes_every_check() {
        let design = Spec::default().design(crate::paper::TS).unwrap();
        for kind in ControllerKind::ALL {
            let report = run(&Input {
                design: &design,
                controller: kind,
                rig_file: None,
                arm_limit: Some(2.0),
                swing_up: false,
            });
            assert!(!report.refused(), "{kind:?}: {report}");
            assert_eq!(report.findings.len(), 2);
        }
    }

    #[test]
    fn the_mode_voltage_is_the_unstable_modes_balance() {
        // A scalar unstable mode embedded in a 4-state model: ż = 3 z + 2 u on x[2], the rest
        // stable and uncoupled; V_mode = p |z| / |b| = 3 · 0.1 / 2.
        let a = Mat::from_diagonal(&nalgebra::DVector::from_vec(vec![-1.0, -2.0, 3.0, -4.0]));
        let b = Mat::from_column_slice(4, 1, &[1.0, 1.0, 2.0, 1.0]);
        let (v, p) = mode_voltage(&a, &b, &[0.5, 0.5, 0.1, 0.5]).unwrap();
        assert!((p - 3.0).abs() < 1e-12);
        assert!((v - 0.15).abs() < 1e-12, "{v}");
    }

    #[test]
    fn a_weak_motor_under_a_heavy_pendulum_is_refused_with_the_voltage_it_needs() {
        let text = "[plant]\npreset = \"qube_servo2\"\nmp = 0.08\nLp = 0.3\nRm = 20.0\n\
                    kt = 0.008\nkm = 0.008\ninitial_state = [0.0, 0.0, 0.1, 0.0]\n";
        let spec = Spec::parse(text).unwrap();
        let design = spec.design(0.01).unwrap();
        let report = run(&Input {
            design: &design,
            controller: ControllerKind::Lqr,
            rig_file: None,
            arm_limit: None,
            swing_up: false,
        });
        let v = report.finding("voltage").unwrap();
        assert_eq!(v.verdict, Verdict::Refuse, "{report}");
        assert!(v.message.contains("would need"), "{}", v.message);
        // Independently: the LQR of the file does fall on the rig's model.
        let p = report.finding("prediction").unwrap();
        assert_eq!(p.verdict, Verdict::Refuse, "{report}");
    }
}

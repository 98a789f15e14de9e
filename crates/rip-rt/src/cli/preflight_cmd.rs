//! `rip-rt run`'s pre-flight ([`rip_core::preflight`]) as the command line reports it: the
//! refusals, forced or not, or one line of verdicts and the warnings.

use rip_core::preflight::Verdict;
use rip_rt::config::Config;
use rip_rt::controllers;
use rip_rt::stop::SetupError;

use super::RunArgs;

/// Runs the pre-flight of the run `args` asks for on `cfg` and says what it found; the
/// refusal (exit 16) when a check refuses and `--force` is not given.
pub(super) fn check(args: &RunArgs, cfg: &Config) -> Result<(), SetupError> {
    let rig_file = args.config.as_deref();
    let report = controllers::preflight(args.controller, cfg, rig_file, args.swing_up)
        .map_err(SetupError::Design)?;
    // The verdict a swing-up will be judged against, and where it came from, even when it
    // passes: a stale record recomputed must not go unnoticed. A refusal says it itself.
    if let Some(f) = report
        .finding("swing_up")
        .filter(|f| f.verdict != Verdict::Refuse)
    {
        rip_rt::say!("rip-rt: swing-up feasibility: {}", f.message);
    }
    if report.refused() {
        if !args.force {
            return Err(SetupError::Preflight(report.to_string()));
        }
        for f in report.refusals() {
            rip_rt::say!("rip-rt: warning: --force: {f}");
        }
        return Ok(());
    }
    // Silence after a pass read as a check that never ran; its warnings were not shown.
    let verdicts: Vec<String> = report
        .findings
        .iter()
        .map(|f| format!("{} {}", f.check, f.verdict.name()))
        .collect();
    rip_rt::say!("rip-rt: pre-flight: passed ({})", verdicts.join(", "));
    for f in report
        .findings
        .iter()
        .filter(|f| f.verdict == Verdict::Warn)
    {
        rip_rt::say!("rip-rt: pre-flight: {f}");
    }
    Ok(())
}

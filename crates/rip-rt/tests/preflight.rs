//! The pre-flight check in `rip-rt run`: refused runs end with exit 16 before the port is
//! opened (so a missing port shows that nothing reached the device), `--force` goes past it.
//! The host loop and `--onboard` share it: a refusal leaves the motor of the lockstep
//! emulator untouched in both, judged on its record and its true state.

mod common;

use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rip-rt");

fn run(config: &Path, force: bool) -> (i32, String) {
    let mut cmd = Command::new(BIN);
    cmd.args([
        "run",
        "--port",
        "/nonexistent/rip-rt-preflight",
        "--controller",
        "lqr",
    ])
    .arg("--config")
    .arg(config);
    if force {
        cmd.arg("--force");
    }
    let out = cmd.output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A fresh directory under the system's temporary one, for this test's files.
fn tempdir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("rip-rt-preflight-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn an_untrusted_rig_file_is_refused_unless_forced() {
    let dir = tempdir("untrusted");
    let rig = write(
        &dir,
        "rig.toml",
        "# Identified by riprs identify.\n# UNTRUSTED: written by riprs identify --force \
         despite:\n#   - held-out fit 40 %\n[plant]\npreset = \"qube_servo2\"\n",
    );
    let (code, err) = run(&rig, false);
    assert_eq!(code, 16, "{err}");
    assert!(
        err.contains("UNTRUSTED") && err.contains("--force"),
        "{err}"
    );
    // Forced: past the pre-flight, the missing port stops it (exit 1).
    let (code, err) = run(&rig, true);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("warning: --force"), "{err}");

    // The marker of the identification file beside the rig file.
    let rig = write(&dir, "lab.toml", "[plant]\npreset = \"qube_servo2\"\n");
    write(
        &dir,
        "lab.identification.toml",
        "[identification]\ntrusted = false\nproblems = [\"condition number 1e9\"]\n",
    );
    let (code, err) = run(&rig, false);
    assert_eq!(code, 16, "{err}");
    assert!(err.contains("condition number 1e9"), "{err}");
}

#[test]
fn a_rig_no_controller_can_balance_is_refused_with_the_voltage_it_needs() {
    let dir = tempdir("weak");
    let rig = write(
        &dir,
        "weak.toml",
        "[plant]\npreset = \"qube_servo2\"\nmp = 0.08\nLp = 0.3\nRm = 20.0\nkt = 0.008\n\
         km = 0.008\ninitial_state = [0.0, 0.0, 0.1, 0.0]\n",
    );
    let (code, err) = run(&rig, false);
    assert_eq!(code, 16, "{err}");
    assert!(
        err.contains("no controller can balance") && err.contains("would need"),
        "{err}"
    );
    assert!(err.contains("predicted to fall"), "{err}");
}

#[test]
fn a_rig_that_balances_passes() {
    let dir = tempdir("good");
    let rig = write(&dir, "qube.toml", "[plant]\npreset = \"qube_servo2\"\n");
    let (code, err) = run(&rig, false);
    assert_eq!(
        code, 1,
        "past the pre-flight, stopped by the missing port: {err}"
    );
}

/// Writes beside `rig` (whose text is `text`) a tuning record of its design at rip-rt's
/// default 10 ms period and ±12 V, so that the record is current, which says LQR falls.
fn write_lqr_falls_record(rig: &Path, text: &str) {
    use rip_core::preflight::{design_checksum, tune_record_path, StoredPrediction, TuneRecord};
    let design = rip_core::spec::Spec::parse(text)
        .unwrap()
        .design(0.01)
        .unwrap();
    let falls = StoredPrediction {
        fell: true,
        arm_max: 3.0,
        arm_peak_to_peak: f64::NAN,
        pendulum: f64::NAN,
        disk_margin: 0.7,
        works: false,
    };
    let record = TuneRecord {
        inputs: design_checksum(&design),
        runs: "noise seeds [11, 12], 10 s each".into(),
        prediction: [("LQR".to_string(), falls)].into_iter().collect(),
    };
    std::fs::write(tune_record_path(rig), record.to_toml()).unwrap();
}

#[test]
fn the_preflight_reads_the_tuning_record_while_it_is_current() {
    let dir = tempdir("record");
    let text = "[plant]\npreset = \"qube_servo2\"\n";
    let rig = write(&dir, "tuned.toml", text);
    // A record of this design (at rip-rt's default 10 ms period and ±12 V) that says LQR
    // falls: the rig balances, so only a pre-flight that reads the record refuses it.
    write_lqr_falls_record(&rig, text);
    let (code, err) = run(&rig, false);
    assert_eq!(code, 16, "{err}");
    assert!(
        err.contains("predicted to fall") && err.contains("stored by riprs tune"),
        "{err}"
    );
    // The file edited after the tuning: the record is stale, the check simulates again and
    // passes the run (stopped by the missing port), saying so.
    write(&dir, "tuned.toml", &format!("{text}[lqr]\nR = 2.0\n"));
    let (code, err) = run(&rig, false);
    assert_eq!(code, 1, "{err}");
    assert!(!err.contains("stored by riprs tune"), "{err}");
}

/// The two ways `rip-rt run` drives the motor: its own loop, or the design uploaded to the
/// device (`--onboard`).
#[derive(Debug, Clone, Copy)]
enum Mode {
    Host,
    Onboard,
}

impl Mode {
    fn name(self) -> &'static str {
        match self {
            Mode::Host => "host",
            Mode::Onboard => "onboard",
        }
    }
}

/// A rig file of the `qube_servo2` preset, which LQR balances, refused by the pre-flight all
/// the same, with the words its refusal must name: `falls` — a tuning record of this very
/// design that says LQR falls; else an identification beside it that is not trusted. A
/// refusal is then the pre-flight's doing, and a forced run balances.
fn refused_rig(dir: &Path, falls: bool) -> (std::path::PathBuf, &'static str) {
    let text = "[plant]\npreset = \"qube_servo2\"\n";
    if !falls {
        let rig = write(dir, "lab.toml", text);
        write(
            dir,
            "lab.identification.toml",
            "[identification]\ntrusted = false\nproblems = [\"condition number 1e9\"]\n",
        );
        return (rig, "condition number 1e9");
    }
    let rig = write(dir, "tuned.toml", text);
    write_lqr_falls_record(&rig, text);
    (rig, "stored by riprs tune")
}

/// `rip-rt run` in `mode` and lockstep against `emu`, on the rig file `rig`.
fn run_on(emu: &common::Emulator, mode: Mode, rig: &Path, extra: &[&str]) -> common::RunResult {
    let mut args = vec!["--config", rig.to_str().unwrap()];
    if let Mode::Onboard = mode {
        args.push("--onboard");
    }
    args.extend_from_slice(extra);
    common::run_lockstep(&emu.device, "lqr", &args)
}

/// The emulator simulating `rig` (its `[plant]`), held upright until enabled, in lockstep.
fn emulator(name: &str, rig: &Path) -> common::Emulator {
    common::Emulator::lockstep(name, &["--config", rig.to_str().unwrap()])
}

/// Both refused rigs in `mode`: exit 16 naming the reason and `--force`; nothing enabling
/// reached the device, and the simulated motor was never driven (no upload and onboard
/// start either: those would drive it).
fn refused_runs_never_enable_the_motor(mode: Mode) {
    let _one = common::one_at_a_time();
    for falls in [true, false] {
        let what = format!(
            "{} {}",
            mode.name(),
            if falls { "falls" } else { "untrusted" }
        );
        let dir = tempdir(&what.replace(' ', "-"));
        let (rig, reason) = refused_rig(&dir, falls);
        let mut emu = emulator(&what.replace(' ', "-"), &rig);
        let r = run_on(&emu, mode, &rig, &["--duration", "3"]);
        assert_eq!(r.status.code(), Some(16), "{what}: {}", r.stderr);
        assert!(
            r.stderr.contains("pre-flight check refuses")
                && r.stderr.contains(reason)
                && r.stderr.contains("--force"),
            "{what}: {}",
            r.stderr
        );
        let enabling: Vec<(i32, u8)> = emu
            .commands()
            .into_iter()
            .filter(|&(_, flags)| flags & rip_rt::protocol::COMMAND_ENABLE != 0)
            .collect();
        assert!(
            enabling.is_empty(),
            "{what}: enabling commands {enabling:?}"
        );
        let truth = emu.finish();
        let driven = truth.iter().filter(|t| t.driver == "drive").count();
        assert_eq!(driven, 0, "{what}: the motor was driven for {driven} rows");
    }
}

/// The rig whose record says LQR falls, forced in `mode`: the refusal is printed as a warning
/// and the run goes ahead as an unrefused one does (it balances for `--duration`, exit 0).
fn forced_runs_warn_and_go_ahead(mode: Mode) {
    let _one = common::one_at_a_time();
    let what = format!("{} forced", mode.name());
    let dir = tempdir(&what.replace(' ', "-"));
    let (rig, reason) = refused_rig(&dir, true);
    let mut emu = emulator(&what.replace(' ', "-"), &rig);
    let r = run_on(&emu, mode, &rig, &["--duration", "3", "--force"]);
    assert_eq!(r.status.code(), Some(0), "{what}: {}", r.stderr);
    assert!(
        r.stderr.contains("warning: --force") && r.stderr.contains(reason),
        "{what}: {}",
        r.stderr
    );
    let truth = emu.finish();
    // Over the run's 3 s only: after them the host loop's stop brakes the arm to rest with the
    // motor driven, the pendulum falling meanwhile.
    let driven: Vec<&common::Truth> = truth
        .iter()
        .filter(|t| t.t < 3.0 && t.driver == "drive")
        .collect();
    assert!(
        driven.len() > 250,
        "{what}: driven for {} rows",
        driven.len()
    );
    // Balanced through the reference step (1 rad of arm at 1 s), which tips the pendulum by
    // about 0.22 rad on this rig: well inside safety.pendulum_limit (0.6 rad).
    let worst = driven.iter().fold(0.0f64, |m, t| m.max(t.alpha.abs()));
    assert!(worst < 0.4, "{what}: the pendulum reached {worst} rad");
}

#[test]
fn a_refused_host_run_never_enables_the_motor() {
    refused_runs_never_enable_the_motor(Mode::Host);
}

#[test]
fn a_refused_onboard_run_never_uploads_or_enables_the_motor() {
    refused_runs_never_enable_the_motor(Mode::Onboard);
}

#[test]
fn a_forced_host_run_warns_and_goes_ahead() {
    forced_runs_warn_and_go_ahead(Mode::Host);
}

#[test]
fn a_forced_onboard_run_warns_and_goes_ahead() {
    forced_runs_warn_and_go_ahead(Mode::Onboard);
}

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

/// `rip-rt run` of `config` with `extra`, against a missing port, which must end within a
/// bound (a pre-flight that blocks on a file fails the test instead of hanging it).
fn run_promptly(config: &Path, extra: &[&str]) -> (i32, String) {
    let mut args = vec!["--config", config.to_str().unwrap()];
    args.extend_from_slice(extra);
    let child = common::spawn_run(Path::new("/nonexistent/rip-rt-preflight"), "lqr", &args);
    let r = common::wait_with_timeout(child, std::time::Duration::from_secs(60));
    (r.status.code().unwrap_or(-1), r.stderr)
}

#[test]
fn a_garbage_identification_beside_the_rig_file_is_refused_unless_forced() {
    let dir = tempdir("garbage-ident");
    let rig = write(&dir, "lab.toml", "[plant]\npreset = \"qube_servo2\"\n");
    let side = dir.join("lab.identification.toml");
    for (garbage, what) in [
        (&b"\x00\xff{{ not toml"[..], "not UTF-8"),
        (&b"[identification\ntrusted = "[..], "invalid TOML"),
        (
            &b"[identification]\ntrusted = \"yes\"\n"[..],
            "identification.trusted",
        ),
        (&b"[fit]\nrmse = 0.1\n"[..], "identification.trusted"),
    ] {
        std::fs::write(&side, garbage).unwrap();
        let (code, err) = run_promptly(&rig, &[]);
        assert_eq!(code, 16, "{what}: {err}");
        assert!(
            err.contains(&side.display().to_string())
                && err.contains(what)
                && err.contains("--force"),
            "{what}: {err}"
        );
        let (code, err) = run_promptly(&rig, &["--force"]);
        assert_eq!(
            code, 1,
            "{what}: past the pre-flight, stopped by the missing port: {err}"
        );
        assert!(err.contains("warning: --force"), "{what}: {err}");
    }
}

#[test]
fn a_tuning_record_that_does_not_parse_is_refused() {
    let dir = tempdir("garbage-record");
    let rig = write(&dir, "tuned.toml", "[plant]\npreset = \"qube_servo2\"\n");
    let record = write(
        &dir,
        "tuned.tune.toml",
        "inputs = 3\n[prediction.LQR]\nfell = \"no\"\n",
    );
    let (code, err) = run_promptly(&rig, &[]);
    assert_eq!(code, 16, "{err}");
    assert!(
        err.contains(&record.display().to_string()) && err.contains("--force"),
        "{err}"
    );
}

/// Something that is not a regular file at `path`: a FIFO no one writes (opening it blocks)
/// or a symbolic link to `/dev/zero` (reading it never ends).
fn plant_non_file(path: &Path, fifo: bool) {
    let _ = std::fs::remove_file(path);
    if fifo {
        let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
        assert_eq!(
            unsafe { libc::mkfifo(c.as_ptr(), 0o644) },
            0,
            "mkfifo {}",
            path.display()
        );
    } else {
        std::os::unix::fs::symlink("/dev/zero", path).unwrap();
    }
}

#[test]
fn a_fifo_or_dev_zero_beside_the_rig_file_is_refused_at_once() {
    let dir = tempdir("non-file");
    let rig = write(&dir, "rig.toml", "[plant]\npreset = \"qube_servo2\"\n");
    let sides = [
        dir.join("rig.tune.toml"),
        dir.join("rig.identification.toml"),
    ];
    for side in &sides {
        for fifo in [true, false] {
            plant_non_file(side, fifo);
            for extra in [&[][..], &["--swing-up"][..], &["--onboard"][..]] {
                let what = format!("{} fifo={fifo} {extra:?}", side.display());
                let (code, err) = run_promptly(&rig, extra);
                assert_eq!(code, rip_rt::stop::exit_code::PREFLIGHT, "{what}: {err}");
                assert!(
                    err.contains(&side.display().to_string())
                        && err.contains("not a regular file")
                        && err.contains("--force"),
                    "{what}: {err}"
                );
            }
            std::fs::remove_file(side).unwrap();
        }
    }
    // The experiment file itself: refused as a bad configuration (exit 2), at once.
    let fifo = dir.join("fifo.toml");
    plant_non_file(&fifo, true);
    let (code, err) = run_promptly(&fifo, &[]);
    assert_eq!(code, rip_rt::stop::exit_code::USAGE, "{err}");
    assert!(err.contains("not a regular file"), "{err}");
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
        misses: None,
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

/// Why [`refused_rig`]'s rig file is refused.
#[derive(Debug, Clone, Copy)]
enum Refusal {
    /// A tuning record of this very design says LQR falls.
    Falls,
    /// The identification beside it is not trusted.
    Untrusted,
    /// The identification beside it is garbage: nothing can vouch for the rig file.
    Garbage,
}

impl Refusal {
    const ALL: [Refusal; 3] = [Refusal::Falls, Refusal::Untrusted, Refusal::Garbage];
}

/// A rig file of the `qube_servo2` preset, which LQR balances, refused by the pre-flight all
/// the same for `why`, with the words its refusal must name. A refusal is then the
/// pre-flight's doing, and a forced run balances.
fn refused_rig(dir: &Path, why: Refusal) -> (std::path::PathBuf, &'static str) {
    let text = "[plant]\npreset = \"qube_servo2\"\n";
    match why {
        Refusal::Untrusted => {
            let rig = write(dir, "lab.toml", text);
            write(
                dir,
                "lab.identification.toml",
                "[identification]\ntrusted = false\nproblems = [\"condition number 1e9\"]\n",
            );
            (rig, "condition number 1e9")
        }
        Refusal::Garbage => {
            let rig = write(dir, "lab.toml", text);
            std::fs::write(dir.join("lab.identification.toml"), b"\x00\xff{{ not toml").unwrap();
            (rig, "lab.identification.toml")
        }
        Refusal::Falls => {
            let rig = write(dir, "tuned.toml", text);
            write_lqr_falls_record(&rig, text);
            (rig, "stored by riprs tune")
        }
    }
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

/// The emulator simulating `rig` (its `[plant]`), held upright until enabled, in lockstep,
/// once its record of commands exists: it creates it just after printing its device, and a
/// run the pre-flight refuses at once can end before that.
fn emulator(name: &str, rig: &Path) -> common::Emulator {
    let emu = common::Emulator::lockstep(name, &["--config", rig.to_str().unwrap()]);
    let start = std::time::Instant::now();
    while !emu.record.exists() {
        assert!(
            start.elapsed() < std::time::Duration::from_secs(30),
            "{name}: no record {:?}",
            emu.record
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    emu
}

/// Every refused rig in `mode`: exit 16 naming the reason and `--force`; nothing enabling
/// reached the device, and the simulated motor was never driven (no upload and onboard
/// start either: those would drive it).
fn refused_runs_never_enable_the_motor(mode: Mode) {
    let _one = common::one_at_a_time();
    for why in Refusal::ALL {
        let what = format!("{} {why:?}", mode.name());
        let dir = tempdir(&what.replace(' ', "-"));
        let (rig, reason) = refused_rig(&dir, why);
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
    let (rig, reason) = refused_rig(&dir, Refusal::Falls);
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

/// `rip-rt run --swing-up`'s stopping-distance check of a file that narrows only
/// `safety.arm_limit`: a refusal names that key (not the default `swing_up.arm_limit` it is
/// checked against) and the least value that passes, which does.
#[test]
fn a_narrow_arm_limit_for_a_swing_up_is_refused_through_the_key_written() {
    use rip_rt::config::Config;
    use rip_rt::envelope::check_swing_up;
    for preset in ["paper", "qube_servo2"] {
        let mut refused = 0;
        for i in 0..=60 {
            let limit = 1.55 + 0.05 * f64::from(i);
            let text = format!("[plant]\npreset = \"{preset}\"\n[safety]\narm_limit = {limit}\n");
            let cfg = Config::from_toml(&text).unwrap_or_else(|e| panic!("{text}: {e}"));
            let Err(e) = check_swing_up(&cfg) else {
                continue;
            };
            refused += 1;
            assert_eq!(e.key, "safety.arm_limit", "{text}: {e}");
            let least: f64 = e
                .reason
                .split("must be at least ")
                .nth(1)
                .and_then(|r| r.split(' ').next())
                .and_then(|n| n.parse().ok())
                .unwrap_or_else(|| panic!("no least value in {e}"));
            assert!(least > limit, "{text}: {e}");
            let fixed = format!("[plant]\npreset = \"{preset}\"\n[safety]\narm_limit = {least}\n");
            if least <= std::f64::consts::TAU {
                check_swing_up(&Config::from_toml(&fixed).unwrap())
                    .unwrap_or_else(|e| panic!("{fixed}: {e}"));
            }
        }
        assert!(refused > 0, "{preset}: the sweep reaches no refusal");
    }
}

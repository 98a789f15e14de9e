//! The pre-flight check in `rip-rt run`: refused runs end with exit 16 before the port is
//! opened (so a missing port shows that nothing reached the device), `--force` goes past it.

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

#[test]
fn the_preflight_reads_the_tuning_record_while_it_is_current() {
    use rip_core::preflight::{design_checksum, tune_record_path, StoredPrediction, TuneRecord};
    let dir = tempdir("record");
    let text = "[plant]\npreset = \"qube_servo2\"\n";
    let rig = write(&dir, "tuned.toml", text);
    // A record of this design (at rip-rt's default 10 ms period and ±12 V) that says LQR
    // falls: the rig balances, so only a pre-flight that reads the record refuses it.
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
    std::fs::write(tune_record_path(&rig), record.to_toml()).unwrap();
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

//! End to end, against the emulator: `rip-rt excite` (rest check, sign check, excitation) and
//! `rip-rt emulate --config` with a plant riprs has no preset for. Each test holds
//! `common::one_at_a_time` (the reason is there).

mod common;

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::*;
use rip_core::excitation::{ArmCentering, ExcitationSettings, Signal, STEP_LEVELS};

const COLUMNS: &str = "t,seq,theta,alpha,theta_ref,u,compute_us,jitter_us,status,phase";

/// The emulator with the pendulum hanging at rest, in lockstep: these tests are about the
/// excitation's signals, logs and stops, not timing; pair it with [`spawn_excite`].
fn hanging(name: &str, extra: &[&str]) -> Emulator {
    let pi = PI.to_string();
    let mut args = vec!["--initial-pendulum", pi.as_str()];
    args.extend_from_slice(extra);
    Emulator::lockstep(name, &args)
}

/// `rip-rt excite` in lockstep.
fn spawn_excite(device: &Path, signal: &str, log: &Path, extra: &[&str]) -> Child {
    Command::new(BIN)
        .arg("excite")
        .arg("--port")
        .arg(device)
        .args(["--signal", signal, "--quiet", "--log"])
        .arg(log)
        .args(extra)
        .args((!extra.contains(&LOCKSTEP)).then_some(LOCKSTEP))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn excite")
}

fn excite(device: &Path, signal: &str, log: &Path, extra: &[&str]) -> RunResult {
    wait_with_timeout(
        spawn_excite(device, signal, log, extra),
        Duration::from_secs(60),
    )
}

fn assert_stopped_at_zero(commands: &[(i32, u8)]) {
    assert_eq!(
        commands.last(),
        Some(&(0, 0)),
        "the last command is not 0 V disabled"
    );
}

/// Checks what every excitation log holds: the columns, the sign check before the signal,
/// the arm inside its limit; returns the log.
fn check_log(path: &Path, signal: &str, arm_limit: f64) -> Log {
    let log = Log::read(path);
    assert_eq!(log.columns.join(","), COLUMNS);
    assert_eq!(log.meta("mode"), Some("excite"));
    assert_eq!(log.meta("signal"), Some(signal));
    let phases = log.text("phase");
    let first_signal = phases
        .iter()
        .position(|p| p != "sign_check")
        .expect("rows after the sign check");
    assert!(first_signal >= 50, "a sign check of 0.6 s comes first");
    assert!(phases[first_signal..].iter().all(|p| p != "sign_check"));
    let theta = log.col("theta");
    let max_arm = theta.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(max_arm < arm_limit, "|theta| reached {max_arm}");
    assert!(max_arm > 0.05, "the arm hardly moved: {max_arm}");
    // Hanging: alpha stays near pi, continuous (no wrap at ±pi).
    assert!(log.col("alpha").iter().all(|a| (a - PI).abs() < 1.0));
    log
}

/// In lockstep: what is tested is each signal's shape, its log and its stop, not timing,
/// which a real-time emulator on a loaded machine can break (5 replies missed at the start
/// of one run in CI stopped it on the watchdog before the rest check).
#[test]
fn each_signal_runs_logs_its_columns_and_ends_at_zero_volts() {
    let _serial = one_at_a_time();
    let pi = PI.to_string();
    for signal in ["chirp", "prbs", "steps", "free-swing"] {
        let emu = Emulator::lockstep(
            &format!("excite-{signal}"),
            &["--initial-pendulum", pi.as_str(), "--noise", "0.3"],
        );
        let path = scratch(&format!("excite-{signal}.csv"));
        let r = excite(
            &emu.device,
            signal,
            &path,
            &["--duration", "2.5", "--lockstep"],
        );
        assert_eq!(r.status.code(), Some(0), "{signal}: {}", r.stderr);
        let log = check_log(&path, signal, 3.0);
        assert_eq!(log.meta("stop"), Some("finished"), "{signal}");
        assert!(log
            .meta("calibration")
            .is_some_and(|c| c.contains("arm_zero_counts")));
        assert!(log
            .meta("sign_check")
            .is_some_and(|c| c.starts_with("passed")));
        assert_stopped_at_zero(&emu.commands());
        let phases = log.text("phase");
        let u = log.col("u");
        let theta = log.col("theta");
        let defaults = ExcitationSettings::new(Signal::from_name(signal).unwrap());
        let a = defaults.amplitude;
        let rows = || (0..u.len()).filter(|&k| phases[k] != "sign_check");
        let seconds = rows().count() as f64 * 0.01;
        assert!((seconds - 2.5).abs() < 0.05, "{signal}: {seconds} s logged");
        match signal {
            "free-swing" => {
                // The kick, +A then −A at full amplitude, then coasting at exactly 0 V (rows
                // that repeat a command for a lost measurement aside).
                let status = log.col("status");
                let t = log.col("t");
                let t0 = t[rows().next().unwrap()];
                for k in rows().filter(|&k| status[k] as u32 & 256 == 0) {
                    let (phase, expected) = match t[k] - t0 {
                        s if s < 0.145 => ("kick", a),
                        s if s > 0.155 && s < 0.295 => ("kick", -a),
                        s if s > 0.305 => ("coast", 0.0),
                        _ => continue,
                    };
                    assert_eq!((phases[k].as_str(), u[k]), (phase, expected), "row {k}");
                }
            }
            "steps" => {
                // u is one of the levels through the documented centring law, the arm rate
                // taken over the time since the previous measurement, as the loop does.
                let law = ArmCentering {
                    gain: defaults.centering,
                    damping: defaults.damping,
                };
                let (t, status) = (log.col("t"), log.col("status"));
                let measured: Vec<usize> = (0..u.len())
                    .filter(|&k| status[k] as u32 & 256 == 0)
                    .collect();
                for w in measured.windows(2) {
                    let (j, k) = (w[0], w[1]);
                    if phases[k] == "sign_check" {
                        continue;
                    }
                    assert_eq!(phases[k], "steps");
                    let rate = (theta[k] - theta[j]) / (t[k] - t[j]);
                    assert!(
                        STEP_LEVELS.iter().any(|l| {
                            (law.command(l * a, theta[k], rate, 3.0) - u[k]).abs() < 2e-3
                        }),
                        "row {k}: u = {} at theta = {}, rate {rate}",
                        u[k],
                        theta[k]
                    );
                }
            }
            _ => {
                // The centring law's share bounded by the arm's own excursion and rate, the rate
                // over the time since the previous measurement as the loop takes it (a row that
                // repeats a command for a lost measurement has none of its own).
                let (t, status) = (log.col("t"), log.col("status"));
                let measured: Vec<usize> =
                    rows().filter(|&k| status[k] as u32 & 256 == 0).collect();
                for w in measured.windows(2) {
                    let (j, k) = (w[0], w[1]);
                    assert_eq!(phases[k], signal);
                    let rate = (theta[k] - theta[j]) / (t[k] - t[j]);
                    let e = u[k] + defaults.centering * theta[k] + defaults.damping * rate;
                    assert!(e.abs() <= a + 0.05, "row {k}: e = {e}");
                }
            }
        }
    }
}

#[test]
fn sign_check_failures_are_refused_before_the_excitation() {
    let _serial = one_at_a_time();
    for (fault, expected) in [
        ("--reverse-motor", "swap the motor leads"),
        ("--reverse-arm-encoder", "device.arm_sign = -1"),
        ("--reverse-pendulum-encoder", "device.pendulum_sign = -1"),
        ("--freeze-arm-encoder", "the arm encoder did not count"),
        (
            "--freeze-pendulum-encoder",
            "the pendulum encoder did not count",
        ),
    ] {
        let emu = hanging(&format!("sign{fault}"), &[fault]);
        let path = scratch(&format!("sign{fault}.csv"));
        let r = excite(&emu.device, "chirp", &path, &["--duration", "5"]);
        assert_eq!(r.status.code(), Some(14), "{fault}: {}", r.stderr);
        assert!(r.stderr.contains(expected), "{fault}: {}", r.stderr);
        let log = Log::read(&path);
        assert_eq!(log.meta("stop"), Some("sign_check"), "{fault}");
        assert!(
            log.text("phase").iter().all(|p| p == "sign_check"),
            "{fault}: excitation rows after a failed check"
        );
        // The pulse, +2 V then −2 V, and otherwise nothing but 0 V.
        let commands = emu.commands();
        assert_stopped_at_zero(&commands);
        let pulse = commands.iter().filter(|c| c.1 != 0 && c.0 != 0).count();
        assert!(
            (28..=32).contains(&pulse),
            "{fault}: {pulse} pulse commands"
        );
        assert!(commands.iter().all(|c| [0, 2000, -2000].contains(&c.0)));
    }
}

#[test]
fn sigint_mid_excitation_leaves_zero_volts() {
    let _serial = one_at_a_time();
    let emu = hanging("excite-sigint", &[]);
    let path = scratch("excite-sigint.csv");
    let child = spawn_excite(&emu.device, "prbs", &path, &["--duration", "30"]);
    // Rest check (1 s), sign check (0.6 s), then well into the PRBS: 2 s of it driven.
    emu.wait_for("the PRBS under way", Duration::from_secs(60), |rows| {
        rows.iter().filter(|r| r.driver == "drive").count() > 200
    });
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    let r = wait_with_timeout(child, Duration::from_secs(20));
    assert_eq!(r.status.code(), Some(130), "{}", r.stderr);
    let log = Log::read(&path);
    assert_eq!(log.meta("stop"), Some("signal"));
    assert!(log.text("phase").iter().any(|p| p == "prbs"));
    let commands = emu.commands();
    assert_stopped_at_zero(&commands);
    // The PRBS was running: enabling commands of both signs before the stop.
    assert!(commands.iter().any(|c| c.1 != 0 && c.0 > 500));
    assert!(commands.iter().any(|c| c.1 != 0 && c.0 < -500));
}

#[test]
fn the_arm_stays_inside_a_tight_limit_under_a_low_inertia_arm() {
    let _serial = one_at_a_time();
    // The QUBE-Servo 2's light arm at 2 V of steps: left alone it would turn at about
    // 8 rad/s, past a 1.2 rad limit within a quarter of a second.
    let cfg = scratch("tight-arm.toml");
    // The file describes the rig (its [plant]): the braking envelope's model.
    std::fs::write(
        &cfg,
        "[plant]\npreset = \"qube_servo2\"\n[safety]\narm_limit = 1.2\n",
    )
    .unwrap();
    let emu = hanging("excite-tight", &["--model", "qube_servo2"]);
    let path = scratch("excite-tight.csv");
    let cfg_arg = cfg.display().to_string();
    let r = excite(
        &emu.device,
        "steps",
        &path,
        &["--duration", "6", "--amplitude", "2", "--config", &cfg_arg],
    );
    assert_eq!(r.status.code(), Some(0), "{}", r.stderr);
    let log = check_log(&path, "steps", 1.2);
    let theta = log.col("theta");
    let max_arm = theta.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(max_arm > 0.4, "{max_arm}");
    assert_stopped_at_zero(&emu.commands());
}

/// Frequency (Hz) of `x` from its crossings of `centre` (with a hysteresis of `band`).
fn crossing_frequency(t: &[f64], x: &[f64], centre: f64, band: f64) -> f64 {
    let mut side = 0.0;
    let mut times = Vec::new();
    for (&tk, &xk) in t.iter().zip(x) {
        let d = xk - centre;
        if d.abs() > band && d.signum() != side {
            if side != 0.0 {
                times.push(tk);
            }
            side = d.signum();
        }
    }
    assert!(times.len() >= 6, "only {} crossings", times.len());
    (times.len() - 1) as f64 / 2.0 / (times[times.len() - 1] - times[0])
}

#[test]
fn emulate_config_simulates_a_plant_without_a_preset() {
    let _serial = one_at_a_time();
    // A rig riprs has no preset for: a longer, heavier pendulum on a lighter arm, Coulomb
    // friction on both joints, a dead zone, a finer arm encoder whose zero is not the arm's
    // start, a pendulum encoder reset 0.04 rad from hanging (inside the rest check's default
    // calibration.max_pendulum_offset, 0.05 rad), encoder noise.
    let text = "[plant]\npreset = \"qube_servo2\"\nmp = 0.04\nLp = 0.2\nJp = 0.00013\n\
                mr = 0.08\nLr = 0.1\nJr = 0.00007\nDr = 0.001\nDp = 0.00004\nRm = 6.5\n\
                kt = 0.036\nkm = 0.036\nCr = 0.0008\nCp = 0.00001\nVd = 0.4\n\
                [sensor]\nencoder_counts = [4096, 2048]\nencoder_offsets = [0.4, 0.04]\n";
    let cfg: PathBuf = scratch("hidden-plant.toml");
    std::fs::write(&cfg, text).unwrap();
    let cfg_arg = cfg.display().to_string();
    let emu = hanging("hidden", &["--config", &cfg_arg, "--noise", "0.3"]);
    let path = scratch("hidden-free-swing.csv");
    let r = excite(
        &emu.device,
        "free-swing",
        &path,
        &["--duration", "5", "--config", &cfg_arg],
    );
    assert_eq!(r.status.code(), Some(0), "{}", r.stderr);
    let log = check_log(&path, "free-swing", 3.0);
    assert_stopped_at_zero(&emu.commands());
    // The calibration took both zeros from the rest: the first row reads θ = 0, α = π.
    let (theta, alpha_all, t_all) = (log.col("theta"), log.col("alpha"), log.col("t"));
    assert!(theta[0].abs() < 0.005, "theta starts at {}", theta[0]);
    assert!(
        (alpha_all[0] - PI).abs() < 0.01,
        "alpha starts at {}",
        alpha_all[0]
    );
    // The coast's frequency is the file's plant's: between that of the pendulum on an arm held
    // still, √(G/J_α), and that of the pair with the arm free, √(G J₀/(J₀ J_α − m₁₂²)) (the
    // arm's Coulomb friction holds it nearly still as it coasts).
    let band = |p: rip_core::FurutaParams| {
        let j_alpha = p.jp + p.mp * p.lp * p.lp / 4.0;
        let j0 = p.jr + p.mr * p.lr * p.lr / 4.0 + p.mp * p.lr * p.lr;
        let m12 = p.mp * p.lr * p.lp / 2.0;
        let g = p.mp * p.g * p.lp / 2.0;
        let hz = |w2: f64| w2.sqrt() / std::f64::consts::TAU;
        (hz(g / j_alpha), hz(g * j0 / (j0 * j_alpha - m12 * m12)))
    };
    let (lo, hi) = band(rip_core::spec::Spec::parse(text).unwrap().plant.params());
    let phases = log.text("phase");
    let coast: Vec<usize> = (0..phases.len())
        .filter(|&k| phases[k] == "coast")
        .collect();
    let t: Vec<f64> = coast.iter().map(|&k| t_all[k]).collect();
    let alpha: Vec<f64> = coast.iter().map(|&k| alpha_all[k]).collect();
    let got = crossing_frequency(&t, &alpha, PI, 0.005);
    assert!(
        got > 0.97 * lo && got < 1.03 * hi,
        "pendulum swings at {got:.3} Hz, the file's plant between {lo:.3} and {hi:.3} Hz"
    );
    // ... which is not the paper preset's.
    let (paper_lo, paper_hi) = band(rip_core::FurutaParams::paper());
    assert!(
        paper_hi < 0.9 * lo || paper_lo > 1.1 * hi,
        "{paper_lo}..{paper_hi}"
    );
}

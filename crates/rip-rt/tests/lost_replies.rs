//! Lost replies are not a fault of the rig: a run on a link that drops a quarter of the
//! device's replies balances to its end, with no witness stop (exit 15) and no other stop.
//!
//! The runs set `loop.watchdog_periods = 10` (100 ms, the most the watchdog allows): with a
//! quarter of the replies lost independently, the default 5 periods without a measurement
//! come once in about 1 300 periods (0.25⁵ · 0.75), and the watchdog's stop there is its rule
//! (exit 4: the device silent for 50 ms), not a false stop; 10 periods come once in about
//! 1.4 million.

mod common;

use std::time::Duration;

use common::*;

const DROP_RATE: &str = "0.25";

fn lossy_config() -> std::path::PathBuf {
    let cfg = scratch("lost-replies.toml");
    std::fs::write(&cfg, "[loop]\nwatchdog_periods = 10\n").unwrap();
    cfg
}

/// One balancing run of `controller` for `seconds` on an emulator dropping [`DROP_RATE`] of
/// its replies (noise seed `seed`); its exit code and stderr, and how many periods went
/// without a reply.
fn lossy_run(name: &str, controller: &str, seed: u64, seconds: f64, lockstep: bool) -> RunResult {
    let cfg = lossy_config();
    let seed = seed.to_string();
    let args = [
        "--noise",
        "0.3",
        "--drop-rate",
        DROP_RATE,
        "--seed",
        seed.as_str(),
    ];
    let emu = if lockstep {
        Emulator::lockstep(name, &args)
    } else {
        Emulator::start(name, &args)
    };
    let duration = seconds.to_string();
    let mut run_args = vec![
        "--config",
        cfg.to_str().unwrap(),
        "--duration",
        duration.as_str(),
        "--quiet",
    ];
    if lockstep {
        run_args.push(LOCKSTEP);
    }
    wait_with_timeout(
        spawn_run(&emu.device, controller, &run_args),
        Duration::from_secs(60),
    )
}

fn missing_replies(stderr: &str) -> u64 {
    stderr
        .split("missing_replies=")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0)
}

/// 100 runs of 5 s in lockstep (20 at the small scale), the three controllers in turn, each
/// with its own drop sequence.
#[test]
fn a_quarter_of_the_replies_lost_stops_no_lockstep_run() {
    let runs = rip_test_scale::size(20, 100);
    let mut lost = 0;
    for i in 0..runs {
        let controller = ["lqr", "lqg", "mpc"][i % 3];
        let r = lossy_run(
            &format!("lost-replies-{i}"),
            controller,
            1000 + i as u64,
            5.0,
            true,
        );
        assert_eq!(
            r.status.code(),
            Some(0),
            "run {i} ({controller}): {}",
            r.stderr
        );
        lost += missing_replies(&r.stderr);
    }
    // About a quarter of 500 periods per run went without a reply.
    assert!(lost as f64 > 0.2 * 500.0 * runs as f64, "{lost}");
}

/// 20 runs of 1 s in real time (the real-time stage, one at a time).
#[test]
fn a_quarter_of_the_replies_lost_stops_no_real_time_run() {
    let _serial = one_at_a_time();
    for i in 0..20 {
        let controller = ["lqr", "lqg", "mpc"][i % 3];
        let r = lossy_run(
            &format!("lost-replies-rt-{i}"),
            controller,
            2000 + i as u64,
            1.0,
            false,
        );
        assert_eq!(
            r.status.code(),
            Some(0),
            "run {i} ({controller}): {}",
            r.stderr
        );
        assert!(missing_replies(&r.stderr) > 5, "{}", r.stderr);
    }
}

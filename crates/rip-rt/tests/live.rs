//! The live stream (`--live PORT`) of `rip-rt run` on the host and onboard, read as a viewer
//! reads it: every logged period arrives as a frame with the log's values, then the stop frame.
//! In lockstep: what is sent is the subject, not the loop's timing.

mod common;

use std::net::UdpSocket;
use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

use common::*;
use rip_rt::live::{Frame, Kind, SIZE};

/// A reader on a free loopback port: its port, and the frames it received up to the first stop
/// frame (or 10 s of silence).
fn reader() -> (u16, mpsc::Receiver<Vec<Frame>>) {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    let port = socket.local_addr().unwrap().port();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut frames = Vec::new();
        let mut buf = [0u8; 2 * SIZE];
        while let Ok(n) = socket.recv(&mut buf) {
            let frame = Frame::decode(&buf[..n]).expect("a frame of this layout");
            let stop = frame.kind == Kind::Stop as u16;
            frames.push(frame);
            if stop {
                break;
            }
        }
        let _ = tx.send(frames);
    });
    (port, rx)
}

/// Runs `controller` in lockstep on a fresh emulator with `extra` flags, `--live` and a log;
/// returns the log and the frames received.
fn watched(name: &str, controller: &str, extra: &[&str]) -> (Log, Vec<Frame>) {
    let emu = Emulator::lockstep(name, &[]);
    let (port, frames) = reader();
    let port = port.to_string();
    let log = scratch(&format!("{name}.csv"));
    let mut args = vec!["--lockstep", "--duration", "2", "--live", &port];
    args.extend_from_slice(&["--log", log.to_str().unwrap()]);
    args.extend_from_slice(extra);
    let r = run(&emu.device, controller, &args);
    assert_eq!(r.status.code(), Some(0), "{}", r.stderr);
    let frames = frames.recv_timeout(Duration::from_secs(30)).unwrap();
    (Log::read(Path::new(&log)), frames)
}

fn periods(frames: &[Frame]) -> Vec<&Frame> {
    frames
        .iter()
        .filter(|f| f.kind == Kind::Period as u16)
        .collect()
}

#[test]
fn every_period_of_a_host_run_is_sent_with_the_logs_values_then_its_stop() {
    let (log, frames) = watched("live-host", "lqg", &[]);
    let sent = periods(&frames);
    assert_eq!(sent.len(), log.rows.len());
    let (theta, u) = (log.col("theta"), log.col("u"));
    for (i, f) in sent.iter().enumerate() {
        assert_eq!(f.counter as usize, i);
        assert!(
            (f.theta - theta[i]).abs() < 1e-5,
            "{i}: {} {}",
            f.theta,
            theta[i]
        );
        assert!(
            (f.u_written - u[i]).abs() < 1e-3,
            "{i}: {} {}",
            f.u_written,
            u[i]
        );
        // LQG's estimate, and the planned voltage, which the clamp leaves alone here.
        assert!(
            f.estimate.iter().all(|x| x.is_finite()),
            "{i}: {:?}",
            f.estimate
        );
        assert!((f.u_planned - f.u_written).abs() < 1e-3 || f.u_written.abs() >= 11.99);
        assert_eq!(f.voltage_limit, 12.0);
    }
    let stop = frames.last().unwrap();
    assert_eq!(stop.kind, Kind::Stop as u16);
    assert_eq!(stop.exit_code, 0);
    assert_eq!(&stop.phase[..8], b"finished");
}

#[test]
fn an_onboard_run_sends_its_telemetry_records_then_its_stop() {
    let _one = one_at_a_time();
    let (log, frames) = watched("live-onboard", "lqr", &["--onboard"]);
    let sent = periods(&frames);
    assert!(!sent.is_empty());
    assert_eq!(sent.len(), log.rows.len());
    assert!(sent.iter().all(|f| &f.phase[..7] == b"onboard"));
    let stop = frames.last().unwrap();
    assert_eq!((stop.kind, stop.exit_code), (Kind::Stop as u16, 0));
}

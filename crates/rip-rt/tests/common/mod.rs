//! Helpers of the end-to-end tests: `rip-rt emulate` on a pseudo-terminal, `rip-rt run`
//! against it, and readers of their records and logs.
//!
//! Each test holds [`one_at_a_time`]: every run is a 100 Hz loop against a 1 kHz emulator, and
//! the default test threads would otherwise run several such pairs on two cores at once, so
//! that scheduling delays (skipped periods, watchdog stops) rather than the code decide the
//! outcome.
//!
//! Tests of control and safety logic, where timing is not what they test, run in lockstep
//! ([`Emulator::lockstep`], [`run_lockstep`]): the emulator advances its plant one period per
//! exchange and `rip-rt` waits for no deadline, so they run faster than real time and the
//! machine's load cannot change their outcome. Timing, the watchdog and the stall rules keep
//! their real-time runs.

// Each test binary uses its own share of these.
#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

pub const BIN: &str = env!("CARGO_BIN_EXE_rip-rt");

static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Serialises the tests of this file (module docs); a failed test does not block the others.
pub fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("rip-rt-e2e-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A running emulator; killed (SIGTERM) on drop.
pub struct Emulator {
    pub child: Child,
    pub device: PathBuf,
    pub record: PathBuf,
    /// The emulator's `--true-state` record: the simulated plant, not its encoders.
    pub truth: PathBuf,
    /// In lockstep ([`Emulator::lockstep`]).
    pub lockstep: bool,
}

/// The flag that puts `rip-rt emulate`, `rip-rt run` and `rip-rt excite` in lockstep.
pub const LOCKSTEP: &str = "--lockstep";

/// `args` with [`LOCKSTEP`] appended.
pub fn with_lockstep<'a>(args: &[&'a str]) -> Vec<&'a str> {
    let mut v = args.to_vec();
    v.push(LOCKSTEP);
    v
}

impl Emulator {
    /// An emulator in lockstep (module docs): pair it with [`run_lockstep`] or a run given
    /// [`LOCKSTEP`].
    pub fn lockstep(name: &str, extra: &[&str]) -> Self {
        Self::start(name, &with_lockstep(extra))
    }

    pub fn start(name: &str, extra: &[&str]) -> Self {
        let record = scratch(&format!("{name}-record.csv"));
        let truth = scratch(&format!("{name}-truth.csv"));
        let mut child = Command::new(BIN)
            .arg("emulate")
            .arg("--record")
            .arg(&record)
            .arg("--true-state")
            .arg(&truth)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn emulator");
        let mut line = String::new();
        BufReader::new(child.stdout.as_mut().unwrap())
            .read_line(&mut line)
            .unwrap();
        let device = PathBuf::from(
            line.trim()
                .strip_prefix("device: ")
                .unwrap_or_else(|| panic!("unexpected emulator output {line:?}")),
        );
        assert!(device.exists(), "{device:?}");
        Emulator {
            child,
            device,
            record,
            truth,
            lockstep: extra.contains(&LOCKSTEP),
        }
    }

    /// Waits until the emulator has stopped itself at its breakpoint (`--pause-at-arm`) and
    /// returns the true-state rows, which end on the state it paused at; fails the test,
    /// naming `what`, if the run `child` ended first or after `timeout` of wall time.
    pub fn wait_for_breakpoint(
        &self,
        child: &mut Child,
        what: &str,
        timeout: Duration,
    ) -> Vec<Truth> {
        let start = Instant::now();
        let stat = format!("/proc/{}/stat", self.child.id());
        loop {
            // The state follows the command's name in parentheses: `T` is stopped.
            let text = std::fs::read_to_string(&stat).unwrap_or_default();
            if text
                .rsplit_once(") ")
                .is_some_and(|(_, rest)| rest.starts_with('T'))
            {
                return self.truth_so_far();
            }
            if let Some(status) = child.try_wait().unwrap() {
                panic!("{what}: the run ended ({status}) first");
            }
            assert!(
                start.elapsed() < timeout,
                "{what}: not seen within {timeout:?}"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Resumes an emulator stopped at its breakpoint.
    pub fn resume(&self) {
        unsafe { libc::kill(self.child.id() as i32, libc::SIGCONT) };
    }

    /// The true-state rows written so far.
    pub fn truth_so_far(&self) -> Vec<Truth> {
        parse_truth(&std::fs::read_to_string(&self.truth).unwrap_or_default())
    }

    /// Stops the emulator (SIGTERM) and returns its whole true-state record, which ends with
    /// the state at exit.
    pub fn finish(&mut self) -> Vec<Truth> {
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        unsafe { libc::kill(self.child.id() as i32, libc::SIGCONT) };
        let _ = self.child.wait();
        parse_truth(&std::fs::read_to_string(&self.truth).unwrap())
    }

    /// Polls the true-state record until `done` holds for the rows so far (every 5 ms) and
    /// returns them; fails the test after `timeout` of wall time, naming `what`. A test
    /// waits for a state this way, never for a fixed time.
    pub fn wait_for(
        &self,
        what: &str,
        timeout: Duration,
        mut done: impl FnMut(&[Truth]) -> bool,
    ) -> Vec<Truth> {
        let start = Instant::now();
        loop {
            let rows = self.truth_so_far();
            if done(&rows) {
                return rows;
            }
            assert!(
                start.elapsed() < timeout,
                "{what}: not seen within {timeout:?}; last row {:?}",
                rows.last()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The true-state rows once the record has stopped growing (two reads 2 ms apart agree,
    /// within 10 s), for a plant that stands still because its lockstep host is suspended.
    pub fn truth_when_still(&self) -> Vec<Truth> {
        parse_truth(&settled_text(
            &self.truth,
            Duration::from_millis(2),
            Duration::from_secs(10),
        ))
    }

    /// Lets the lockstep run `child` go on in short bursts until `done` holds for the true
    /// state, and leaves it suspended (SIGSTOP) there: the plant, paced by the run, then
    /// stands still at that state, so a signal sent now lands close to it however fast
    /// lockstep runs. `near` says when the state is close to `done`: from then on each burst
    /// is as short as two signals in a row. Send SIGCONT after the signal. Fails the test if
    /// the run ends first or after `timeout` of wall time, naming `what`.
    pub fn suspend_run_when(
        &self,
        child: &mut Child,
        what: &str,
        timeout: Duration,
        near: impl Fn(&[Truth]) -> bool,
        mut done: impl FnMut(&[Truth]) -> bool,
    ) -> Vec<Truth> {
        let pid = child.id() as i32;
        let start = Instant::now();
        loop {
            unsafe { libc::kill(pid, libc::SIGSTOP) };
            let rows = self.truth_when_still();
            if done(&rows) {
                return rows;
            }
            if let Some(status) = child.try_wait().unwrap() {
                panic!("{what}: the run ended ({status}) first");
            }
            assert!(
                start.elapsed() < timeout,
                "{what}: not seen within {timeout:?}; last row {:?}",
                rows.last()
            );
            let close = near(&rows);
            unsafe { libc::kill(pid, libc::SIGCONT) };
            if !close {
                std::thread::sleep(Duration::from_micros(200));
            }
        }
    }

    /// Waits until the simulated arm has come to rest (|θ̇| below `rate` for `hold` seconds
    /// of simulated time) or `timeout` of wall time passed; returns the rows so far.
    ///
    /// In lockstep, once the run has ended: until the record stops growing. The emulator then
    /// runs its plant on to rest as soon as the run hangs up and stands still after it
    /// (`rip_rt::emulator::RUN_ON_REST_S`), or, if no run ever connected, holds the plant
    /// where it was.
    pub fn wait_for_rest(&self, rate: f64, hold: f64, timeout: Duration) -> Vec<Truth> {
        let start = Instant::now();
        if self.lockstep {
            let text = settled_text(&self.truth, Duration::from_millis(100), timeout);
            return parse_truth(&text);
        }
        loop {
            let rows = self.truth_so_far();
            if let Some(last) = rows.last() {
                let still = rows
                    .iter()
                    .rev()
                    .take_while(|r| r.theta_dot.abs() < rate && r.alpha_dot.abs() < 10.0 * rate)
                    .last();
                if still.is_some_and(|s| last.t - s.t >= hold) {
                    return rows;
                }
            }
            if start.elapsed() > timeout {
                return rows;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The commands the device has received so far: (voltage_mv, flags).
    pub fn commands_so_far(&self) -> Vec<(i32, u8)> {
        // The emulator creates the file once it runs, right after printing its device.
        let text = std::fs::read_to_string(&self.record).unwrap_or_default();
        parse_record(&text)
    }

    /// The commands the device received: (voltage_mv, flags). The last frames a run wrote
    /// before exiting may still be in the emulator's input, so this waits until the record
    /// stops growing.
    pub fn commands(&self) -> Vec<(i32, u8)> {
        assert!(self.record.exists(), "no record {:?}", self.record);
        parse_record(&settled_text(
            &self.record,
            Duration::from_millis(50),
            Duration::from_secs(2),
        ))
    }
}

/// The text of `path` once it has stopped growing (two reads `interval` apart agree), or the
/// last read after `timeout`: a record the emulator writes row by row, read when it is done.
fn settled_text(path: &Path, interval: Duration, timeout: Duration) -> String {
    let start = Instant::now();
    let mut text = std::fs::read_to_string(path).unwrap_or_default();
    loop {
        std::thread::sleep(interval);
        let again = std::fs::read_to_string(path).unwrap_or_default();
        if again == text || start.elapsed() > timeout {
            return again;
        }
        text = again;
    }
}

/// The rows of an emulator's `--record` (`t_s,seq,voltage_mv,flags`) that are complete.
fn parse_record(text: &str) -> Vec<(i32, u8)> {
    text.lines()
        .skip(1)
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            Some((f.get(2)?.parse().ok()?, f.get(3)?.parse().ok()?))
        })
        .collect()
}

impl Drop for Emulator {
    fn drop(&mut self) {
        // SIGCONT too: an emulator a failing test left stopped at its breakpoint would hold
        // the SIGTERM pending, and the wait would never return.
        unsafe { libc::kill(self.child.id() as i32, libc::SIGTERM) };
        unsafe { libc::kill(self.child.id() as i32, libc::SIGCONT) };
        let _ = self.child.wait();
    }
}

pub struct RunResult {
    pub status: ExitStatus,
    pub stderr: String,
}

pub fn wait_with_timeout(mut child: Child, timeout: Duration) -> RunResult {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut stderr = String::new();
            child
                .stderr
                .take()
                .unwrap()
                .read_to_string(&mut stderr)
                .unwrap();
            return RunResult { status, stderr };
        }
        if start.elapsed() > timeout {
            let _ = child.kill();
            panic!("rip-rt run did not finish within {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub fn spawn_run(device: &Path, controller: &str, extra: &[&str]) -> Child {
    Command::new(BIN)
        .arg("run")
        .arg("--port")
        .arg(device)
        .args(["--controller", controller])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn run")
}

/// `rip-rt run` with the resource limit `resource` set to `value` (e.g. `ulimit -f`: the
/// kernel sends SIGXFSZ on the write that crosses it).
pub fn spawn_run_with_limit(
    device: &Path,
    controller: &str,
    extra: &[&str],
    resource: libc::__rlimit_resource_t,
    value: u64,
) -> Child {
    let mut cmd = Command::new(BIN);
    cmd.arg("run")
        .arg("--port")
        .arg(device)
        .args(["--controller", controller])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    // SAFETY: setrlimit is async-signal-safe and touches only the child.
    unsafe {
        cmd.pre_exec(move || {
            let lim = libc::rlimit {
                rlim_cur: value,
                rlim_max: value,
            };
            if libc::setrlimit(resource, &lim) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.spawn().expect("spawn run")
}

pub fn run(device: &Path, controller: &str, extra: &[&str]) -> RunResult {
    wait_with_timeout(
        spawn_run(device, controller, extra),
        Duration::from_secs(30),
    )
}

/// A configuration for runs that start hanging at rest (`--swing-up`, `excite`): a quick rest
/// check (a 0.5 s window, refused after `rest_timeout_s`) and `extra` (more TOML). The
/// emulator reads the same file, so its `[plant]` is the run's.
pub fn swing_config(name: &str, rest_timeout_s: f64, extra: &str) -> PathBuf {
    let path = scratch(&format!("{name}.toml"));
    std::fs::write(
        &path,
        format!("[calibration]\nrest_window_s = 0.5\nrest_timeout_s = {rest_timeout_s}\n{extra}"),
    )
    .unwrap();
    path
}

/// The hanging rig of the swing-up tests: `rip-rt emulate --start down --noise 0.3` with the
/// configuration `cfg` ([`swing_config`]) and `extra` flags; in lockstep when `lockstep` (then
/// give the run [`LOCKSTEP`] too).
pub fn hanging_rig(name: &str, cfg: &Path, extra: &[&str], lockstep: bool) -> Emulator {
    let mut args = vec!["--start", "down", "--noise", "0.3", "--config"];
    args.push(cfg.to_str().unwrap());
    args.extend_from_slice(extra);
    if lockstep {
        Emulator::lockstep(name, &args)
    } else {
        Emulator::start(name, &args)
    }
}

/// `rip-rt run --swing-up` of `controller` for `duration` (s, of the experiment after the
/// catch) with the configuration `cfg` and a log, from hanging at rest on a [`hanging_rig`]
/// in lockstep with noise seed `seed`: the emulator, the log's path and the run.
pub fn swing_up_lockstep(
    name: &str,
    cfg: &Path,
    controller: &str,
    seed: &str,
    duration: &str,
) -> (Emulator, PathBuf, RunResult) {
    let emu = hanging_rig(name, cfg, &["--seed", seed], true);
    let log_path = scratch(&format!("{name}.csv"));
    let r = run_lockstep(
        &emu.device,
        controller,
        &[
            "--swing-up",
            "--duration",
            duration,
            "--config",
            cfg.to_str().unwrap(),
            "--log",
            log_path.to_str().unwrap(),
        ],
    );
    (emu, log_path, r)
}

/// `rip-rt run` in lockstep with an [`Emulator::lockstep`].
pub fn run_lockstep(device: &Path, controller: &str, extra: &[&str]) -> RunResult {
    run(device, controller, &with_lockstep(extra))
}

/// A `rip-rt run` log: its columns, its rows as text cells, and its comment lines.
pub struct Log {
    pub columns: Vec<String>,
    pub rows: Vec<Vec<String>>,
    pub comments: Vec<String>,
}

impl Log {
    pub fn read(path: &Path) -> Log {
        let text = std::fs::read_to_string(path).unwrap();
        let mut columns = Vec::new();
        let mut rows = Vec::new();
        let mut comments = Vec::new();
        for line in text.lines() {
            if let Some(c) = line.strip_prefix("# ") {
                comments.push(c.to_string());
            } else if columns.is_empty() {
                columns = line.split(',').map(str::to_string).collect();
            } else {
                rows.push(line.split(',').map(str::to_string).collect());
            }
        }
        Log {
            columns,
            rows,
            comments,
        }
    }

    fn index(&self, name: &str) -> usize {
        self.columns
            .iter()
            .position(|c| c == name)
            .unwrap_or_else(|| panic!("no column {name:?} in {:?}", self.columns))
    }

    /// A numeric column; empty cells are NaN.
    pub fn col(&self, name: &str) -> Vec<f64> {
        let i = self.index(name);
        self.rows
            .iter()
            .map(|r| {
                if r[i].is_empty() {
                    f64::NAN
                } else {
                    r[i].parse()
                        .unwrap_or_else(|_| panic!("{name}: not a number: {:?}", r[i]))
                }
            })
            .collect()
    }

    /// A text column.
    pub fn text(&self, name: &str) -> Vec<String> {
        let i = self.index(name);
        self.rows.iter().map(|r| r[i].clone()).collect()
    }

    /// The value of the comment line `key: value`.
    pub fn meta(&self, key: &str) -> Option<&str> {
        let prefix = format!("{key}: ");
        self.comments.iter().find_map(|c| c.strip_prefix(&prefix))
    }
}

/// A row of the emulator's true-state record.
#[derive(Debug, Clone, PartialEq)]
pub struct Truth {
    pub t: f64,
    pub theta: f64,
    pub theta_dot: f64,
    pub alpha: f64,
    pub alpha_dot: f64,
    pub voltage: f64,
    pub current: f64,
    pub driver: String,
}

/// The simulated time (s) of the swing's first command, on the emulator's true state: the
/// first driven row above the sign check's pulse by 0.5 V, which the pulse itself never
/// reaches. The first enabling command is the pulse, and the swing starts only after the rig
/// has come to rest from it (seconds later), so a fault or a stop timed from the first
/// enabling command would land while the arm still rests.
pub fn swing_start(rows: &[Truth]) -> Option<f64> {
    let pulse = rip_rt::sign_check::PULSE_VOLTAGE;
    rows.iter()
        .find(|r| r.driver == "drive" && r.voltage.abs() > pulse + 0.5)
        .map(|r| r.t)
}

/// The swing's first arrival near upright, the catch: the first driven row after
/// [`swing_start`] with the pendulum within 0.2 rad of upright.
pub fn first_upright(rows: &[Truth]) -> Option<f64> {
    let swing = swing_start(rows)?;
    rows.iter()
        .find(|r| {
            r.t > swing && r.driver == "drive" && rip_core::swingup::wrap_angle(r.alpha).abs() < 0.2
        })
        .map(|r| r.t)
}

/// The complete rows of a true-state record (a row being written is skipped).
pub fn parse_truth(text: &str) -> Vec<Truth> {
    let mut lines = text.lines();
    assert_eq!(
        lines
            .next()
            .unwrap_or("t_s,theta,theta_dot,alpha,alpha_dot,voltage,current,driver"),
        "t_s,theta,theta_dot,alpha,alpha_dot,voltage,current,driver"
    );
    lines
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            if f.len() != 8 {
                return None;
            }
            let n = |i: usize| f[i].parse::<f64>().ok();
            Some(Truth {
                t: n(0)?,
                theta: n(1)?,
                theta_dot: n(2)?,
                alpha: n(3)?,
                alpha_dot: n(4)?,
                voltage: n(5)?,
                current: n(6)?,
                driver: match f[7] {
                    d @ ("drive" | "open" | "brake") => d.to_string(),
                    _ => return None,
                },
            })
        })
        .collect()
}

/// The largest |θ| (rad) the simulated arm reached.
pub fn max_excursion(rows: &[Truth]) -> f64 {
    rows.iter().fold(0.0, |m, r| m.max(r.theta.abs()))
}

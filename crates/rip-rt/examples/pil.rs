//! Processor-in-the-loop checks of the firmware image in QEMU (`firmware/pil.sh` runs it):
//!
//! For each controller, the design `rip-rt run --onboard` would upload is uploaded to the USART
//! build of the firmware on QEMU's `netduinoplus2` (an STM32F405) over the emulated USART and
//! committed with its CRC-32; then, in lockstep, the host simulates the paper's plant (the
//! emulator's, 1 ms RK4 steps) and each period sends the encoder counts in a `PilStep`, the
//! firmware steps its controller (rip-control in `f32`) on them and returns the move, which
//! drives the plant for the next period. On the host the same image runs in rip-control's
//! `f32` controller on the same counts: the **agreement** is the largest difference of the
//! two moves over every step (≥ 10 000 per controller, the bar 1 mV). The **cost** is the
//! firmware's SysTick count of each step: QEMU runs with `-icount shift=0` (one instruction
//! per nanosecond of virtual time) and its `netduinoplus2` clocks SysTick from the 168 MHz
//! system clock, so a step of `n` ticks executed `n · 1000 / 168` instructions. On the chip
//! at 168 MHz a step of `N` instructions takes at most `2 N / 168` µs under the stated margin
//! (CPI ≤ 2: flash wait states behind the ART accelerator, multi-cycle FPU divisions and
//! square roots). **Balanced**: the pendulum within 0.2 rad of upright after the first 0.5 s
//! and the arm within 0.05 rad of the 1 rad reference step over the last second, and the
//! pendulum's RMS angle within 5 % of the same closed loop with the host's `f64` controller.
//!
//! **Timer**: then, for a 1 kHz and a 100 Hz design, onboard mode itself runs: the design is
//! uploaded and started, and the SysTick exception steps it on the image's own (meaningless,
//! in QEMU) encoder readings, with limits wide enough that they never stop it; the host only
//! keeps the link alive and collects the telemetry, one record per step. Each record carries
//! the device's microsecond clock (TIM5, which the `qemu` build prescales to QEMU's virtual
//! time: a timer model independent of SysTick's), so the interval between consecutive steps
//! is the interrupt's period as QEMU's clock saw it. Passing: every step reported in order,
//! every interval within [`PERIOD_TOLERANCE`] of the period, their mean within 1 µs of it,
//! no overrun, and each step's own time (SysTick's countdown) inside the period. The line is
//! `pil: timer-<rate> periods=N mean_us=X min_us=Y max_us=Z max_step_instr=W overruns=0`.
//!
//! **Budget**: the device refuses, at the commit, a design whose modelled worst step does not
//! fit half its period (rip-control's `Design::check_step_budget`, called by the image's
//! load on the chip): the 1 kHz MPC is accepted with the iteration bound the host caps it to
//! and refused with one more, and with the file's 200, after which onboard mode does not
//! start. The line is `pil: budget accepted=max_iterations:5 refused=max_iterations:6,200`.
//!
//! **Overrun**: then the same image boots in a second QEMU whose core takes 64 ns of virtual
//! time per instruction (`-icount shift=6`, ten times slower than the chip at CPI 2), and runs
//! the 1 kHz MPC onboard. The budget accepts it (it counts instructions, not this core's
//! time), and its step takes longer than the 1 ms period: SysTick wraps during the step, and
//! the first step must end onboard mode as an overrun, the final record showing the driver
//! disabled at 0 V. The line is `pil: overrun step=0 step_us=X step_instr=Y state=overrun
//! overruns=1 applied_mv=0 enabled=no`.
//!
//! **Stop**: the device's own stop (`rip_control::stop`, which the device runs when its host
//! dies with the wiring verified), stepped by `PilStep`s with the `PIL_STOP` flag on the
//! paper's plant from a falling pendulum with the arm moving (0.2 rad, 3 rad/s; the pendulum
//! 0.3 rad from upright, falling at 1.5 rad/s), the image's move driving the plant (the short
//! as shorted windings), against the host's `f32` copy of the same image on the same counts:
//! the agreement (the same command each period, voltages within 1 mV), the stop's cost (the
//! whole step's SysTick count, as the controllers'), and the arm inside 3 rad. The line is
//! `pil: stop steps=N max_du=X max_instr=Y max_arm=Z`.
//!
//! **Watchdog**: host mode's stop on the command watchdog (protocol v3's watchdog stop): the
//! image with the stop's design is uploaded, the stop armed with the wiring verified (the
//! `qemu` build's encoders read 0: the zeros there, the pendulum hanging still), then one
//! enabling command and silence. The device's watchdog must trip about 50 ms later and the
//! main loop start the SysTick on the stop: telemetry with the host-silent state at the stop's
//! period, then the stop's end, the driver disabled at 0 V within the stop's longest time.
//! The line is `pil: watchdog records=N first_ms=X period_us=Y end_s=Z applied_mv=0`.
//!
//! **Command line**: last, `rip-rt run --onboard` itself (the `rip-rt` binary beside this
//! example) runs LQR, LQG and MPC against a freshly booted image for a few seconds: it must
//! upload, verify and start the design, log the telemetry, stop on its duration with exit 0,
//! and leave the device, asked afterwards, disabled at 0 V. The `qemu` build reads its
//! encoders as 0 and the run's configuration sets `device.pendulum_zero = "up"`, so the image
//! sees an upright pendulum at rest. The lines are `pil: cli-<controller> exit=0 rows=N
//! max_step_cycles=C`.
//!
//! Usage: `cargo run --release -p rip-rt --example pil -- IMAGE [STEPS [CONTROLLER]]`, IMAGE
//! the `qemu` build; the last lines are
//! `pil: <controller> steps=N max_du=X max_instr=Y balanced=yes|no` and the timer lines. Exit 1
//! if any check fails.
//!
//! With `PIL_PHASES=1` each step's count covers one part of the step instead (`PIL_PHASE_*`,
//! in turn; `PIL_PHASES=qp`, or another part's name, that part on every step), and a `pil: <controller> phases:` line gives the worst count of each part over
//! the steps that measured it, and the QP's worst count per number of its iterations (the
//! iterations from the host's `f32` copy, which computes the same).

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use rip_device::law::ControlLaw;
use rip_device::Onboard;
use rip_protocol::{
    Message, OnboardStart, PilStep, Telemetry, WatchdogStop, ACK_OK, COMMAND_ENABLE,
    ONBOARD_HOST_SILENT, ONBOARD_OVERRUN, ONBOARD_RUNNING, ONBOARD_WIRING_VERIFIED, PIL_PHASES,
    PIL_PHASE_QP, PIL_PHASE_SHIFT, PIL_RESET, PIL_STOP, STATUS_ENABLED, STATUS_ONBOARD,
};
use rip_rt::config::Config;
use rip_rt::controllers::ControllerKind;
use rip_rt::emulator::EmulatorConfig;
use rip_rt::onboard::{self, Link};
use rip_rt::plant::PlantSim;
use rip_rt::serial::SerialPort;

/// Instructions per SysTick tick: 1 ns per instruction, 168 MHz ticks (module docs).
const INSTR_PER_TICK: f64 = 1000.0 / 168.0;
/// Cycles per instruction assumed for the time on the chip (module docs).
const CPI_MARGIN: f64 = 2.0;
/// Largest departure of one step interval from the period, as a fraction of it: the step's
/// interrupt waits while the main loop holds a critical section (parsing a frame, queueing a
/// reply), a few thousand instructions, a few µs in QEMU's clock.
const PERIOD_TOLERANCE: f64 = 0.05;
/// Steps of each timer check.
const TIMER_PERIODS: usize = 1000;

struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// QEMU on `image` with `-icount icount`; its USART's pty.
fn boot(image: &str, icount: &str) -> (Qemu, String) {
    let mut child = Command::new("qemu-system-arm")
        .args(["-M", "netduinoplus2", "-nographic", "-monitor", "none"])
        .args(["-icount", icount])
        .args(["-serial", "pty", "-kernel", image])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("qemu-system-arm");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let pty = line
        .split_whitespace()
        .find(|w| w.starts_with("/dev/pts/"))
        .unwrap_or_else(|| panic!("qemu offered no pty: {line:?}"))
        .to_string();
    (Qemu(child), pty)
}

/// The default configuration at `period_ms`. A faster loop than the paper's 10 ms keeps the
/// MPC's horizon in seconds and its QP's size: the prediction steps stay 10 ms
/// (`mpc.prediction_step`), `P = 50` of them, 0.5 s, while the estimator and the move run at
/// the loop's period.
fn config(period_ms: f64) -> Config {
    let mut cfg = Config::default();
    cfg.loop_.period_ms = period_ms;
    let paper_ms = 1e3 * rip_core::paper::TS;
    cfg.spec.mpc.prediction_step = (paper_ms / period_ms).round().max(1.0) as usize;
    cfg
}

/// Counts of the plant state with the default `[device]` (2048 counts per revolution, the
/// pendulum's zero hanging down).
fn counts(x: [f64; 4]) -> [i32; 2] {
    let per_rad = 2048.0 / std::f64::consts::TAU;
    [
        (x[0] * per_rad).round() as i32,
        ((x[2] + std::f64::consts::PI) * per_rad).round() as i32,
    ]
}

/// One closed loop of `steps` periods of `ts` on the paper's plant, the move from `law`.
fn closed_loop(
    steps: usize,
    ts: f64,
    mut law: impl FnMut(usize, [i32; 2]) -> f64,
) -> Vec<[f64; 4]> {
    let mut plant = PlantSim::new(EmulatorConfig::default().model, 0.0, 0.05);
    let sub = (ts / 1e-3).round().max(1.0) as usize;
    let mut xs = Vec::with_capacity(steps);
    for k in 0..steps {
        let u = law(k, counts(plant.state())).clamp(-12.0, 12.0);
        for _ in 0..sub {
            plant.step(u, ts / sub as f64);
        }
        xs.push(plant.state());
    }
    xs
}

fn judge(xs: &[[f64; 4]], ts: f64) -> (bool, f64) {
    let settle = (0.5 / ts) as usize;
    let last = (1.0 / ts) as usize;
    let upright = xs[settle..].iter().all(|x| x[2].abs() < 0.2);
    let tail = &xs[xs.len() - last..];
    let on_ref = tail.iter().all(|x| (x[0] - 1.0).abs() < 0.05);
    let rms =
        (xs[settle..].iter().map(|x| x[2] * x[2]).sum::<f64>() / (xs.len() - settle) as f64).sqrt();
    (upright && on_ref, rms)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let image = args.next().expect("usage: pil IMAGE [STEPS [CONTROLLER]]");
    let min_steps: usize = args.next().map_or(10_000, |s| s.parse().expect("STEPS"));
    let only = args.next();
    const PARTS: [&str; PIL_PHASES] = ["convert", "estimate", "linear", "qp", "rest"];
    // 0: the whole step; PIL_PHASES + 1: each part in turn; else that part on every step.
    let phases = match std::env::var("PIL_PHASES").as_deref() {
        Ok("1") => PIL_PHASES + 1,
        Ok(part) => PARTS.iter().position(|p| *p == part).map_or(0, |i| i + 1),
        Err(_) => 0,
    };
    let icount = std::env::var("PIL_ICOUNT").unwrap_or("shift=0".into());
    let (qemu, pty) = boot(&image, &icount);
    let port = SerialPort::open(std::path::Path::new(&pty), 115_200).expect("pty");
    let mut link = Link::new(port.io());
    assert!(answers(&mut link), "the firmware did not answer");

    let mut ok = true;
    let mut lines = Vec::new();
    for (name, kind, period_ms) in [
        ("lqr", ControllerKind::Lqr, 10.0),
        ("lqg", ControllerKind::Lqg, 10.0),
        ("mpc", ControllerKind::Mpc, 10.0),
        ("lqr-1khz", ControllerKind::Lqr, 1.0),
        ("lqg-1khz", ControllerKind::Lqg, 1.0),
        ("mpc-1khz", ControllerKind::Mpc, 1.0),
    ] {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let cfg = config(period_ms);
        let ts = cfg.period_s();
        let design = onboard::design(kind, &cfg).expect("design");
        let img = onboard::image(&design, &cfg).expect("image");
        if let Err(e) = link.upload(&img) {
            println!("pil: {name} upload of {} bytes failed: {e}", img.len());
            ok = false;
            continue;
        }
        // The host's copies of the same image: f32 as on the chip, f64 for the reference.
        let mut host32 = host_copy::<f32>(&img).expect("host f32 load");
        let mut host64 = host_copy::<f64>(&img).expect("host f64 load");

        // At least `min_steps` and at least 10 s, so that the reference step is inside.
        let steps = min_steps.max((10.0 / ts) as usize);
        let mut max_du = 0.0f64;
        let mut max_ticks = 0u32;
        let mut phase_max = [0u32; PIL_PHASES];
        let mut qp_by_iter = std::collections::BTreeMap::<u32, u32>::new();
        let mut failed = None;
        let xs = closed_loop(steps, ts, |k, c| {
            if failed.is_some() {
                return 0.0;
            }
            if k == 0 {
                host32.reset(c);
            }
            let want = host32.step(c);
            let phase = match phases {
                0 => 0,
                p if p > PIL_PHASES => (k % PIL_PHASES) as u8 + 1,
                p => p as u8,
            };
            let step = PilStep {
                arm_counts: c[0],
                pendulum_counts: c[1],
                flags: (if k == 0 { PIL_RESET } else { 0 }) | phase << PIL_PHASE_SHIFT,
            };
            let got = link.send(Message::PilStep(step)).and_then(|seq| {
                link.wait(
                    Duration::from_secs(5),
                    |m| matches!(m, Message::PilMove(p) if p.ack_seq == seq),
                )
            });
            match got {
                Ok(Some(Message::PilMove(m))) if m.code == 0 => {
                    max_du = max_du.max((m.voltage() - want).abs());
                    if phase == 0 {
                        max_ticks = max_ticks.max(m.cycles);
                    } else {
                        let w = &mut phase_max[usize::from(phase) - 1];
                        *w = (*w).max(m.cycles);
                        if phase == PIL_PHASE_QP {
                            let it = host32.last_move().map_or(0, |mv| mv.iterations);
                            let w = qp_by_iter.entry(it).or_default();
                            *w = (*w).max(m.cycles);
                        }
                    }
                    m.voltage()
                }
                other => {
                    failed = Some(format!("step {k}: {other:?}"));
                    0.0
                }
            }
        });
        if let Some(f) = failed {
            println!("pil: {name} failed at {f}");
            ok = false;
            continue;
        }
        let mut k64 = 0;
        let reference = closed_loop(steps, ts, |k, c| {
            if k == 0 {
                host64.reset(c);
            }
            k64 += 1;
            host64.step(c)
        });
        let (balanced, rms) = judge(&xs, ts);
        let (ref_balanced, ref_rms) = judge(&reference, ts);
        let same = (rms / ref_rms - 1.0).abs() < 0.05;
        if phases != 0 {
            let instr = |t: u32| (t as f64 * INSTR_PER_TICK).round();
            let mut line = format!("pil: {name} phases (worst instructions):");
            for (p, t) in PARTS.iter().zip(phase_max) {
                line += &format!(" {p}={}", instr(t));
            }
            line += " | qp by iterations:";
            for (it, t) in &qp_by_iter {
                line += &format!(" {it}:{}", instr(*t));
            }
            println!("{line}");
        }
        let max_instr = (max_ticks as f64 * INSTR_PER_TICK).round();
        let est_us = max_instr * CPI_MARGIN / 168.0;
        let pass = balanced && ref_balanced && same && max_du <= 1e-3;
        ok &= pass;
        println!(
            "pil: {name} detail: image={} bytes ts={ts} s pendulum_rms={rms:.5} host_f64_rms={ref_rms:.5} \
             est_step_us_at_168MHz={est_us:.1} (CPI {CPI_MARGIN}) period_us={} \
             qp_max_iterations={}",
            img.len(),
            (ts * 1e6).round(),
            host32
                .controller()
                .map_or(0, |c| c.stats().max_iterations)
        );
        lines.push(format!(
            "pil: {name} steps={steps} max_du={max_du:.3e} max_instr={max_instr} balanced={}",
            if balanced && same { "yes" } else { "no" }
        ));
    }
    // Each named check: its line, or what failed (and the run fails).
    let mut check = |name: &str, result: &mut dyn FnMut() -> Result<String, String>| {
        if only.as_deref().is_some_and(|o| o != name) {
            return;
        }
        match result() {
            Ok(line) => lines.push(format!("pil: {name} {line}")),
            Err(e) => {
                println!("pil: {name} failed: {e}");
                ok = false;
            }
        }
    };
    check("stop", &mut || stop_check(&mut link));
    check("watchdog", &mut || watchdog_check(&mut link));
    check("budget", &mut || budget_check(&mut link));
    for (name, period_ms, periods) in [
        ("timer-1khz", 1.0, TIMER_PERIODS),
        ("timer-100hz", 10.0, TIMER_PERIODS / 5),
    ] {
        check(name, &mut || timer_check(&mut link, period_ms, periods));
    }
    // QEMU is stopped first: the overrun check boots its own.
    drop(qemu);
    check("overrun", &mut || overrun_check(&image));
    for controller in ["lqr", "lqg", "mpc"] {
        check(&format!("cli-{controller}"), &mut || {
            cli_check(&image, controller)
        });
    }
    for l in &lines {
        println!("{l}");
    }
    std::process::exit(if ok { 0 } else { 1 });
}

/// The image loaded on the host in rip-control's controller in scalar `R`, as the device
/// loads it.
fn host_copy<R: rip_control::Real>(
    img: &[u8],
) -> Result<Box<ControlLaw<R, { onboard::MAX_IMAGE }>>, rip_device::DesignRefused> {
    let mut law = Box::new(ControlLaw::<R, { onboard::MAX_IMAGE }>::new());
    law.buffer()[..img.len()].copy_from_slice(img);
    law.load(img.len())?;
    Ok(law)
}

/// Host mode's watchdog stop on the chip (module docs, "Watchdog"): the line's fields, or
/// what failed.
fn watchdog_check(link: &mut Link<'_>) -> Result<String, String> {
    let cfg = config(10.0);
    let design = onboard::design(ControllerKind::Lqr, &cfg)?;
    let img = onboard::image(&design, &cfg)?;
    link.upload(&img)?;
    let armed = WatchdogStop {
        flags: ONBOARD_WIRING_VERIFIED,
        arm_zero: 0,
        pendulum_down: 0,
    };
    match link.request(Message::WatchdogStop(armed))? {
        (ACK_OK, 1) => {}
        other => return Err(format!("the watchdog stop was not armed: {other:?}")),
    }
    let enable = rip_protocol::Command {
        voltage_mv: 300,
        flags: COMMAND_ENABLE,
    };
    let m = link
        .sample(Duration::from_secs(1))
        .map_err(|e| e.to_string())?
        .ok_or("no measurement before the command")?;
    link.telemetry.clear();
    link.send(Message::Command(enable))
        .map_err(|e| e.to_string())?;
    // Silence: only reading, until the stop's final record (the run over) or its bound.
    let bound = Duration::from_secs_f64(rip_control::stop::MAX_STOP_S + 10.0);
    let start = std::time::Instant::now();
    let ended = |t: &[Telemetry]| t.last().is_some_and(|r| r.status & STATUS_ONBOARD == 0);
    while !ended(&link.telemetry) && start.elapsed() < bound {
        link.wait(Duration::from_millis(50), |_| false)
            .map_err(|e| e.to_string())?;
    }
    let t = link.telemetry.clone();
    let (Some(first), Some(last)) = (t.first(), t.last()) else {
        return Err("no telemetry: the device did not start its stop".into());
    };
    if !ended(&t) || t.iter().any(|r| r.onboard != ONBOARD_HOST_SILENT) {
        return Err(format!("{} records, the last {last:?}", t.len()));
    }
    if last.applied_mv != 0 || last.status & STATUS_ENABLED != 0 {
        return Err(format!("the stop ended driving: {last:?}"));
    }
    let us = |r: &Telemetry| f64::from(r.device_time_us.wrapping_sub(m.device_time_us));
    let first_ms = us(first) * 1e-3;
    if !(40.0..=80.0).contains(&first_ms) {
        return Err(format!("the stop began {first_ms} ms after the command"));
    }
    let stop_period_us = rip_control::stop::STOP_PERIOD_S * 1e6;
    let steps: Vec<&Telemetry> = t
        .iter()
        .filter(|r| r.status & STATUS_ONBOARD != 0)
        .collect();
    let mut period_us = 0.0f64;
    for w in steps.windows(2) {
        let dt = f64::from(w[1].device_time_us.wrapping_sub(w[0].device_time_us));
        if (dt - stop_period_us).abs() > PERIOD_TOLERANCE * stop_period_us {
            return Err(format!("records {dt} µs apart: {:?} then {:?}", w[0], w[1]));
        }
        period_us = period_us.max(dt);
    }
    let end_s = (us(last) - us(first)) * 1e-6;
    if end_s > rip_control::stop::MAX_STOP_S + 0.05 {
        return Err(format!("the stop took {end_s} s"));
    }
    Ok(format!(
        "records={} first_ms={first_ms:.1} period_us={period_us} end_s={end_s:.2} applied_mv={}",
        t.len(),
        last.applied_mv
    ))
}

/// The device's own stop in the loop (module docs, "Stop").
fn stop_check(link: &mut Link<'_>) -> Result<String, String> {
    let cfg = config(10.0);
    let ts = cfg.period_s();
    let period_us = (ts * 1e6).round() as u32;
    let design = onboard::design(ControllerKind::Lqr, &cfg)?;
    let img = onboard::image(&design, &cfg)?;
    link.upload(&img)?;
    let mut host32 =
        host_copy::<f32>(&img).map_err(|_| "the host's f32 copy refused the image".to_string())?;
    let mut plant = PlantSim::new(EmulatorConfig::default().model, 0.0, 0.05);
    plant.set_state([0.2, 3.0, 0.3, 1.5]);
    let sub = (ts / 1e-3).round().max(1.0) as usize;
    let (mut max_du, mut max_ticks, mut max_arm) = (0.0f64, 0u32, 0.0f64);
    let periods = (rip_control::stop::MAX_STOP_S / ts).ceil() as usize;
    let mut k = 0;
    while k < periods {
        let c = counts(plant.state());
        if k == 0 {
            host32.reset(c);
            if !host32.begin_stop(true, None) {
                return Err("the host's f32 copy has no stop".into());
            }
        }
        let want = match host32.stop_step(c, k as u32 * period_us) {
            Some(rip_control::stop::BrakeCommand::Volts(v)) => v,
            Some(rip_control::stop::BrakeCommand::Short) => f64::INFINITY,
            None => f64::NAN,
        };
        let step = PilStep {
            arm_counts: c[0],
            pendulum_counts: c[1],
            flags: PIL_STOP | if k == 0 { PIL_RESET } else { 0 },
        };
        let seq = link
            .send(Message::PilStep(step))
            .map_err(|e| e.to_string())?;
        let got = match link.wait(
            Duration::from_secs(5),
            |m| matches!(m, Message::PilMove(p) if p.ack_seq == seq),
        ) {
            Ok(Some(Message::PilMove(m))) if m.code == ACK_OK => {
                max_ticks = max_ticks.max(m.cycles);
                m.voltage()
            }
            other => return Err(format!("step {k}: {other:?}")),
        };
        let same = (got.is_nan() && want.is_nan()) || got == want || (got - want).abs() <= 1e-3;
        if !same {
            return Err(format!("step {k}: the image {got} V, the host {want} V"));
        }
        max_du = max_du.max(if got.is_finite() {
            (got - want).abs()
        } else {
            0.0
        });
        if got.is_nan() {
            break;
        }
        for _ in 0..sub {
            if got.is_finite() {
                plant.step(got.clamp(-12.0, 12.0), ts / sub as f64);
            } else {
                plant.step_windings(rip_rt::plant::Windings::Shorted, ts / sub as f64);
            }
            max_arm = max_arm.max(plant.state()[0].abs());
        }
        k += 1;
    }
    let max_instr = (max_ticks as f64 * INSTR_PER_TICK).round();
    if max_arm >= 3.0 {
        return Err(format!("the arm reached {max_arm:.3} rad"));
    }
    Ok(format!(
        "steps={k} max_du={max_du:.3e} max_instr={max_instr} max_arm={max_arm:.3}"
    ))
}

/// The device's own step budget (module docs, "Budget"): the 1 kHz MPC with the iteration
/// bound the host caps to what fits (accepted), then the same design with one iteration
/// more and with the file's uncapped 200 (both refused at the commit, and then no design is
/// loaded: onboard mode does not start).
fn budget_check(link: &mut Link<'_>) -> Result<String, String> {
    let cfg = config(1.0);
    let mut design = onboard::design(ControllerKind::Mpc, &cfg)?;
    let cap = design.max_iterations;
    link.upload(&onboard::image(&design, &cfg)?)
        .map_err(|e| format!("the capped design (max_iterations {cap}) was refused: {e}"))?;
    for over in [cap + 1, cfg.spec.mpc.max_iterations as u32] {
        design.max_iterations = over;
        let img = onboard::image(&design, &cfg)?;
        match link.upload(&img) {
            Ok(()) => return Err(format!("max_iterations {over} was accepted")),
            Err(e) if e.contains("refused the design") => {}
            Err(e) => return Err(format!("max_iterations {over}: {e}")),
        }
        let start = OnboardStart {
            host_timeout_ms: 50,
            ..WIDE_OPEN
        };
        let (code, _) = link.request(Message::OnboardStart(start))?;
        if code == ACK_OK {
            link.stop();
            return Err(format!(
                "onboard mode started after max_iterations {over} was refused"
            ));
        }
    }
    Ok(format!(
        "accepted=max_iterations:{cap} refused=max_iterations:{},{}",
        cap + 1,
        cfg.spec.mpc.max_iterations
    ))
}

/// Onboard start settings no reading can leave, with the longest host timeout: for the checks
/// of the timer and the step, since QEMU models no encoders.
const WIDE_OPEN: OnboardStart = OnboardStart {
    decimation: 1,
    host_timeout_ms: u16::MAX,
    arm_center: 0,
    arm_limit: u32::MAX,
    pendulum_center: 0,
    pendulum_limit: u32::MAX,
    flags: 0,
};

/// Uploads `image` and starts it with [`WIDE_OPEN`], then collects telemetry until `done`
/// holds of it or `timeout` (wall time) passes. QEMU runs its virtual clock slower than real
/// time; a sample request every 10 ms keeps the device's host-silence watchdog fed.
fn run_wide_open(
    link: &mut Link<'_>,
    image: &[u8],
    timeout: Duration,
    done: impl Fn(&[Telemetry]) -> bool,
) -> Result<(), String> {
    link.upload(image)?;
    link.telemetry.clear();
    let (code, state) = link.request(Message::OnboardStart(WIDE_OPEN))?;
    if code != ACK_OK {
        return Err(format!("start refused (ack code {code}, state {state})"));
    }
    let deadline = std::time::Instant::now() + timeout;
    while !done(&link.telemetry) && std::time::Instant::now() < deadline {
        link.send(Message::SampleRequest)
            .map_err(|e| e.to_string())?;
        link.wait(Duration::from_millis(10), |_| false)
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Onboard mode at `period_ms` for `periods` steps, timed by QEMU's clock (module docs,
/// "Timer"): the line's fields, or what failed.
fn timer_check(link: &mut Link<'_>, period_ms: f64, periods: usize) -> Result<String, String> {
    let mut cfg = Config::default();
    cfg.loop_.period_ms = period_ms;
    let design = onboard::design(ControllerKind::Lqr, &cfg)?;
    let image = onboard::image(&design, &cfg)?;
    run_wide_open(link, &image, Duration::from_secs(120), |t| {
        t.len() > periods
    })?;
    link.stop();
    let t: Vec<_> = link.telemetry.iter().take(periods + 1).copied().collect();
    if t.len() < periods + 1 {
        return Err(format!("{} telemetry records of {}", t.len(), periods + 1));
    }
    let period_us = period_ms * 1e3;
    let (mut min, mut max, mut max_ticks) = (f64::INFINITY, 0.0f64, 0u32);
    for (i, w) in t.windows(2).enumerate() {
        let [a, b] = [w[0], w[1]];
        if b.step != a.step.wrapping_add(1) || b.onboard != ONBOARD_RUNNING || b.overruns != 0 {
            return Err(format!("record {i}: {a:?} then {b:?}"));
        }
        let dt = f64::from(b.device_time_us.wrapping_sub(a.device_time_us));
        if (dt - period_us).abs() > PERIOD_TOLERANCE * period_us {
            return Err(format!("step {}: {dt} µs after the previous one", b.step));
        }
        min = min.min(dt);
        max = max.max(dt);
        // `step_cycles` is the previous step's; the first record has none.
        if i > 0 {
            max_ticks = max_ticks.max(b.step_cycles);
        }
    }
    let span = t[periods].device_time_us.wrapping_sub(t[0].device_time_us);
    let mean = f64::from(span) / periods as f64;
    if (mean - period_us).abs() > 1.0 {
        return Err(format!("mean interval {mean} µs, period {period_us} µs"));
    }
    let budget = period_us * 168.0;
    if max_ticks == 0 || f64::from(max_ticks) >= budget {
        return Err(format!("step time {max_ticks} ticks, budget {budget}"));
    }
    Ok(format!(
        "periods={periods} mean_us={mean:.3} min_us={min} max_us={max} max_step_instr={} overruns=0",
        (f64::from(max_ticks) * INSTR_PER_TICK).round()
    ))
}

/// Whether the firmware on `link` answers a sample request, waiting for its boot.
fn answers(link: &mut Link<'_>) -> bool {
    (0..100).any(|_| matches!(link.sample(Duration::from_millis(300)), Ok(Some(_))))
}

/// QEMU's instruction time for the overrun check (module docs, "Overrun"): 64 ns of virtual
/// time per instruction, a core ten times slower than the chip at CPI 2.
const OVERRUN_ICOUNT: &str = "shift=6";
/// Nanoseconds of virtual time per instruction under [`OVERRUN_ICOUNT`].
const OVERRUN_NS_PER_INSTR: f64 = 64.0;

/// An overrun on QEMU's clock (module docs, "Overrun"): the same image under
/// [`OVERRUN_ICOUNT`], where the 1 kHz MPC the device's budget accepts (its cost is counted
/// in instructions, not in this core's time) takes longer than its period. Its first step must
/// end onboard mode as an overrun, and the final record must show the motor disabled at 0 V.
fn overrun_check(image: &str) -> Result<String, String> {
    let (qemu, pty) = boot(image, OVERRUN_ICOUNT);
    let port = SerialPort::open(std::path::Path::new(&pty), 115_200).map_err(|e| e.to_string())?;
    let mut link = Link::new(port.io());
    if !answers(&mut link) {
        return Err("the firmware did not answer".into());
    }
    let cfg = config(1.0);
    let design = onboard::design(ControllerKind::Mpc, &cfg)?;
    let ended = |t: &[Telemetry]| t.iter().any(|r| r.onboard != ONBOARD_RUNNING);
    run_wide_open(
        &mut link,
        &onboard::image(&design, &cfg)?,
        Duration::from_secs(60),
        ended,
    )?;
    let stopped_by_host = !ended(&link.telemetry);
    link.stop();
    drop(qemu);
    if stopped_by_host {
        return Err(format!(
            "no overrun within 60 s: {} records, the last {:?}",
            link.telemetry.len(),
            link.telemetry.last()
        ));
    }
    let last = *link
        .telemetry
        .iter()
        .find(|r| r.onboard != ONBOARD_RUNNING)
        .unwrap();
    let period_ticks = 168_000u32;
    let disabled = last.status & STATUS_ENABLED == 0 && last.applied_mv == 0;
    if last.onboard != ONBOARD_OVERRUN
        || last.overruns != 1
        || last.step_cycles <= period_ticks
        || !disabled
    {
        return Err(format!("the run ended with {last:?}"));
    }
    let instr = f64::from(last.step_cycles) / 0.168 / OVERRUN_NS_PER_INSTR;
    Ok(format!(
        "step={} step_us={:.0} step_instr={instr:.0} state=overrun overruns={} applied_mv=0 enabled=no",
        last.step,
        f64::from(last.step_cycles) / 168.0,
        last.overruns
    ))
}

/// Seconds of each [`cli_check`] run.
const CLI_SECONDS: f64 = 4.0;

/// `rip-rt run --onboard` itself against a freshly booted image (module docs, "Command
/// line"): the `qemu` build reads its encoders as 0, which `device.pendulum_zero = "up"` makes
/// the upright pendulum at rest, so the run uploads, verifies and starts the design,
/// supervises the telemetry for [`CLI_SECONDS`] of wall time and stops the motor: exit 0, a
/// logged row per telemetry record, and the device, asked after the run, disabled at 0 V. QEMU's clock runs about ten times slower than wall time here (the firmware's
/// main loop never sleeps, and `-icount shift=0` makes its time its instruction count), so the
/// device steps far fewer than the host's periods.
fn cli_check(image: &str, controller: &str) -> Result<String, String> {
    let rip_rt = std::env::current_exe()
        .map_err(|e| e.to_string())?
        .parent()
        .and_then(|examples| examples.parent())
        .map(|release| release.join("rip-rt"))
        .ok_or("no target directory")?;
    let dir = std::env::temp_dir().join(format!("riprs-pil-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let config = dir.join("qemu.toml");
    std::fs::write(&config, "[device]\npendulum_zero = \"up\"\n").map_err(|e| e.to_string())?;
    let log = dir.join(format!("{controller}.csv"));
    let (qemu, pty) = boot(image, "shift=0");
    // The firmware answers before the run opens the port: the run's own start-up waits less.
    {
        let port =
            SerialPort::open(std::path::Path::new(&pty), 115_200).map_err(|e| e.to_string())?;
        if !answers(&mut Link::new(port.io())) {
            return Err("the firmware did not answer".into());
        }
    }
    let out = Command::new(&rip_rt)
        .args([
            "run",
            "--port",
            &pty,
            "--onboard",
            "--controller",
            controller,
        ])
        .args(["--duration", &CLI_SECONDS.to_string()])
        .arg("--config")
        .arg(&config)
        .arg("--log")
        .arg(&log)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("{}: {e}", rip_rt.display()))?;
    // The device's own state after the run, not the run's last record: QEMU's slow clock may
    // not have reached the step that reports the stop before the run exited.
    let after = {
        let port =
            SerialPort::open(std::path::Path::new(&pty), 115_200).map_err(|e| e.to_string())?;
        Link::new(port.io())
            .sample(Duration::from_secs(2))
            .map_err(|e| e.to_string())?
            .ok_or("no measurement after the run")?
    };
    drop(qemu);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let text = std::fs::read_to_string(&log).map_err(|e| format!("{}: {e}", log.display()))?;
    let _ = std::fs::remove_dir_all(&dir);
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let _header = lines.next();
    let rows: Vec<&str> = lines.filter(|l| l.ends_with(",onboard")).collect();
    let field = |name: &str| {
        stderr
            .split_whitespace()
            .find_map(|w| w.strip_prefix(name))
            .and_then(|v| v.parse::<usize>().ok())
    };
    let code = out.status.code();
    let disabled = after.status & STATUS_ENABLED == 0 && after.applied_mv == 0;
    if code != Some(0)
        || rows.len() < 5
        || field("telemetry=") != Some(rows.len())
        || !disabled
        || !stderr.contains("stop frames sent (0 V, disabled)")
    {
        return Err(format!(
            "exit {code:?}, {} onboard rows, then {after:?}: {stderr}",
            rows.len()
        ));
    }
    let cycles = field("max_step_cycles=").unwrap_or(0);
    let rows = rows.len();
    Ok(format!("exit=0 rows={rows} max_step_cycles={cycles}"))
}

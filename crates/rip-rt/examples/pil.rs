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
//! Usage: `cargo run --release -p rip-rt --example pil -- IMAGE [STEPS [CONTROLLER]]`; the last
//! lines are `pil: <controller> steps=N max_du=X max_instr=Y balanced=yes|no`. Exit 1 if any
//! check fails.
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
use rip_protocol::{Message, PilStep, PIL_PHASES, PIL_PHASE_QP, PIL_PHASE_SHIFT, PIL_RESET};
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

struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn boot(image: &str) -> (Qemu, String) {
    let mut child = Command::new("qemu-system-arm")
        .args(["-M", "netduinoplus2", "-nographic", "-monitor", "none"])
        .args([
            "-icount",
            &std::env::var("PIL_ICOUNT").unwrap_or("shift=0".into()),
        ])
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
    let (qemu, pty) = boot(&image);
    let port = SerialPort::open(std::path::Path::new(&pty), 115_200).expect("pty");
    let mut link = Link::new(port.io());
    // Wait for the firmware to boot and answer.
    let mut up = false;
    for _ in 0..100 {
        if let Ok(Some(_)) = link.sample(Duration::from_millis(300)) {
            up = true;
            break;
        }
    }
    assert!(up, "the firmware did not answer");

    let mut ok = true;
    let mut lines = Vec::new();
    for (name, kind, period_ms) in [
        ("lqr", ControllerKind::Lqr, 10.0),
        ("lqg", ControllerKind::Lqg, 10.0),
        ("mpc", ControllerKind::Mpc, 10.0),
        ("lqr-1khz", ControllerKind::Lqr, 1.0),
        ("lqg-1khz", ControllerKind::Lqg, 1.0),
    ] {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let mut cfg = Config::default();
        cfg.loop_.period_ms = period_ms;
        let ts = cfg.period_s();
        let design = onboard::design(kind, &cfg).expect("design");
        let img = onboard::image(&design, &cfg).expect("image");
        if let Err(e) = link.upload(&img) {
            println!("pil: {name} upload of {} bytes failed: {e}", img.len());
            ok = false;
            continue;
        }
        // The host's copies of the same image: f32 as on the chip, f64 for the reference.
        let mut host32 = Box::new(ControlLaw::<f32, { onboard::MAX_IMAGE }>::new());
        host32.buffer()[..img.len()].copy_from_slice(&img);
        host32.load(img.len()).expect("host f32 load");
        let mut host64 = Box::new(ControlLaw::<f64, { onboard::MAX_IMAGE }>::new());
        host64.buffer()[..img.len()].copy_from_slice(&img);
        host64.load(img.len()).expect("host f64 load");

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
    for l in &lines {
        println!("{l}");
    }
    // `exit` runs no destructors: QEMU is stopped first, or it would outlive the check.
    drop(qemu);
    std::process::exit(if ok { 0 } else { 1 });
}

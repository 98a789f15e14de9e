//! Onboard mode (protocol v2 and v3) on arbitrary traffic: uploads, commits, starts (with the
//! wiring verified or not, so that the device's own stop runs too), stops, watchdog stops
//! (host mode's, which the command watchdog then runs), PIL steps, v1
//! commands and controller steps in any order, with the encoders moving and the fault line
//! toggling. The device never panics, never drives beyond its limit, drives only
//! while onboard mode runs or after a host's enabling command, and never while faulted.
//!
//! Input layout: records of a control byte and a payload. Control bits 0–3 pick the action
//! (a v2 frame from the following bytes, a chunk of a real LQR image, a controller step, a
//! v1 command), bit 7 is the fault line, bits 4–6 advance the clock.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rip_control::{Design, Kind};
use rip_control::stop::{BrakingLaw, HoldLaw, StopDesign};
use rip_control::swing::ArmModel;
use rip_device::law::{write_image, ControlLaw, Sensor};
use rip_device::{Config, Device, Inputs};
use rip_protocol::{
    crc32, Command, Event, Frame, Message, OnboardStart, PilStep, UploadBegin, UploadChunk,
    UploadCommit, WatchdogStop, CHUNK_MAX, ONBOARD_OVERRUN,
};

fn image() -> ([u8; 512], usize) {
    // An LQR with its input-disturbance observer, so the device's observer runs on the
    // traffic too: a 4-state model (θ += Ts θ̇, α += Ts α̇) and a gain with g·b = 0.05.
    let mut design = Design {
        kind: Kind::Lqr,
        ts: 0.001,
        k: [-3.0, -2.0, 40.0, 4.0],
        cancels_input_disturbance: true,
        nx: 4,
        disturbance_gain: [0.0, 0.5, 0.0, -0.5],
        ..Design::default()
    };
    for i in 0..4 {
        design.a[i * 4 + i] = 1.0;
    }
    design.a[1] = 0.001;
    design.a[2 * 4 + 3] = 0.001;
    design.b[1] = 0.05;
    design.b[3] = -0.05;
    let sensor = Sensor {
        arm_rad_per_count: 0.003,
        pendulum_rad_per_count: 0.003,
        pendulum_offset: 3.14159,
        ..Sensor::default()
    };
    // The device's own stop too, which a start with the wiring verified lets it run.
    let stop = StopDesign {
        law: BrakingLaw {
            voltage: 12.0,
            linear_below: 0.5,
        },
        dead_band: 0.2,
        hold: HoldLaw {
            k: [-30.0, -2.0, 20.0, 0.5],
            voltage: 12.0,
        },
        model: ArmModel {
            j0: 1e-3,
            ja: 5e-4,
            m12: 3e-4,
            grav: 0.03,
            b: 5e-3,
            c_arm: 2e-4,
            dp: 1e-5,
        },
        dead_zone: 0.2,
    };
    let mut out = [0u8; 512];
    let n = write_image(&sensor, Some(&stop), &design, &mut out).expect("image");
    (out, n)
}

fuzz_target!(|data: &[u8]| {
    let (img, img_len) = image();
    let cfg = Config::DEFAULT;
    let mut now = u32::MAX - 50_000;
    let mut enc = [0u16, 1024];
    let at = |now: u32, enc: [u16; 2], fault: bool| Inputs {
        now_us: now,
        encoders: enc,
        driver_fault: fault,
    };
    let mut dev = Device::with_onboard(
        cfg,
        &at(now, enc, false),
        [0, 1024],
        ControlLaw::<f64, 1024>::new(),
    );
    let mut host_enabled = false;
    // The fault line as the device last read it (each tick and frame passes it the inputs).
    let mut seen_fault = false;
    let mut rest = data;
    let mut seq = 0u16;
    while let Some((&ctl, tail)) = rest.split_first() {
        rest = tail;
        let mut take = |n: usize| -> [u8; 8] {
            let mut b = [0u8; 8];
            let k = n.min(rest.len());
            b[..k].copy_from_slice(&rest[..k]);
            rest = &rest[k..];
            b
        };
        now = now.wrapping_add(((ctl >> 4) & 7) as u32 * 700);
        let fault = ctl & 0x80 != 0;
        let p = take(8);
        enc[0] = enc[0].wrapping_add(p[0] as i8 as u16);
        enc[1] = enc[1].wrapping_add(p[1] as i8 as u16);
        let inputs = at(now, enc, fault);
        let u32_of = |i: usize| u32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]]);
        let message = match ctl & 0x0F {
            0 => Message::UploadBegin(UploadBegin {
                total_len: if p[2] & 1 == 0 {
                    img_len as u32
                } else {
                    u32_of(4)
                },
            }),
            1 | 2 => {
                let off = (p[2] as usize % img_len.div_ceil(CHUNK_MAX)) * CHUNK_MAX;
                let end = (off + CHUNK_MAX).min(img_len);
                Message::UploadChunk(UploadChunk::new(off as u32, &img[off..end]))
            }
            3 => Message::UploadCommit(UploadCommit {
                len: if p[2] & 1 == 0 {
                    img_len as u32
                } else {
                    u32_of(4)
                },
                crc32: if p[3] & 1 == 0 {
                    crc32(&img[..img_len])
                } else {
                    u32_of(4)
                },
            }),
            4 => Message::OnboardStart(OnboardStart {
                decimation: p[2] as u16,
                host_timeout_ms: p[3] as u16,
                arm_center: 0,
                arm_limit: p[4] as u32 * 8,
                pendulum_center: 1024,
                pendulum_limit: p[5] as u32 * 4,
                flags: p[6] & 1,
            }),
            5 => Message::OnboardStop { flags: p[2] },
            6 => Message::PilStep(PilStep {
                arm_counts: u32_of(2) as i32,
                pendulum_counts: u32_of(4) as i32,
                flags: p[6],
            }),
            7 => Message::Command(Command {
                voltage_mv: i16::from_le_bytes([p[2], p[3]]),
                flags: p[4],
            }),
            // Host mode's stop on the command watchdog, armed with any flags and zeros.
            9 => Message::WatchdogStop(WatchdogStop {
                flags: p[2] & 0x81,
                arm_zero: i16::from_le_bytes([p[3], p[4]]).into(),
                pendulum_down: 1024 + i32::from(p[5] as i8),
            }),
            8 => {
                // No inputs reach the device here: judge it on the fault line it last read.
                // An overrun, and only an overrun, ends the run with a final record.
                let was_running = dev.onboard_running();
                let last = dev.record_step_cycles(u32_of(2), u32_of(4), 0);
                assert_eq!(last.is_some(), was_running && u32_of(2) > u32_of(4));
                if last.is_some() {
                    assert_eq!(dev.onboard_state(), ONBOARD_OVERRUN);
                }
                check(&dev, host_enabled, seen_fault, cfg);
                continue;
            }
            _ => {
                // Without a run the tick returns before reading the inputs, so the device is
                // judged on the fault line it last read: a host-enabled device that has not
                // yet seen a fault may stay enabled.
                let ran = dev.onboard_running();
                let _ = dev.onboard_tick(&inputs);
                if ran {
                    seen_fault = fault;
                }
                if !dev.onboard_running() && !dev.enabled() {
                    host_enabled = false;
                }
                check(&dev, host_enabled, seen_fault, cfg);
                continue;
            }
        };
        match message {
            Message::Command(c) => host_enabled = c.enabled(),
            Message::OnboardStop { .. } => host_enabled = false,
            _ => {}
        }
        seq = seq.wrapping_add(1);
        let _ = dev.handle(Event::Frame(Frame { seq, message }), &inputs);
        // A start the device accepted takes over from the host's command (and its end
        // disables); a refused one changes nothing.
        if matches!(message, Message::OnboardStart(_)) && dev.onboard_running() {
            host_enabled = false;
        }
        seen_fault = fault;
        if !dev.enabled() {
            host_enabled = false;
        }
        check(&dev, host_enabled, fault, cfg);
    }
});

fn check(dev: &Device<ControlLaw<f64, 1024>>, host_enabled: bool, fault: bool, cfg: Config) {
    assert!(dev.voltage_mv().unsigned_abs() <= cfg.voltage_limit_mv);
    if dev.enabled() {
        assert!(dev.onboard_running() || host_enabled);
        assert!(!fault);
    }
}

//! Onboard mode on the host: the design upload's state machine, the checksum check, the
//! controller stepped from the device's own encoder positions, and every stop rule.

use proptest::prelude::*;
use rip_device::{Config, DesignRefused, Device, Inputs, Onboard, Pwm};
use rip_protocol::{
    crc32, Ack, Command, Event, Frame, Message, OnboardStart, Rejection, Telemetry, UploadBegin,
    UploadChunk, UploadCommit, ACK_BAD_SETTINGS, ACK_BUSY, ACK_CRC_MISMATCH, ACK_DESIGN_REFUSED,
    ACK_LENGTH_MISMATCH, ACK_NO_DESIGN, ACK_NO_UPLOAD, ACK_OK, ACK_OUT_OF_ORDER, ACK_REFUSED,
    ACK_TOO_LARGE, CHUNK_MAX, COMMAND_BRAKE, ONBOARD_ARM_LIMIT, ONBOARD_BAD_MOVE,
    ONBOARD_DRIVER_FAULT, ONBOARD_HOST_SILENT, ONBOARD_OVERRUN, ONBOARD_PENDULUM_LIMIT,
    ONBOARD_PROTOCOL, ONBOARD_RUNNING, ONBOARD_STOPPED, STATUS_BRAKING, STATUS_ENABLED,
    STATUS_ONBOARD, STATUS_WATCHDOG,
};

/// A test law: `u = k_arm · arm + k_pend · (pendulum − 2048)` volts, from an image
/// `b"LAW1" k_arm:f32 k_pend:f32 period_us:u32` padded with `pad` bytes (to make uploads span
/// many chunks). A step may be told to return NaN.
#[derive(Debug, Clone)]
struct Law {
    buf: [u8; 512],
    k: [f32; 2],
    period_us: u32,
    steps: Vec<[i32; 2]>,
    reset_at: Option<[i32; 2]>,
    nan: bool,
    fallbacks: u32,
}

impl Law {
    fn new() -> Self {
        Self {
            buf: [0; 512],
            k: [0.0; 2],
            period_us: 0,
            steps: Vec::new(),
            reset_at: None,
            nan: false,
            fallbacks: 0,
        }
    }
}

impl Onboard for Law {
    fn buffer(&mut self) -> &mut [u8] {
        &mut self.buf
    }
    fn load(&mut self, len: usize) -> Result<(), DesignRefused> {
        let b = &self.buf[..len];
        if len < 16 || &b[..4] != b"LAW1" {
            return Err(DesignRefused);
        }
        let f = |i: usize| f32::from_le_bytes(b[i..i + 4].try_into().unwrap());
        self.k = [f(4), f(8)];
        self.period_us = u32::from_le_bytes(b[12..16].try_into().unwrap());
        Ok(())
    }
    fn period_us(&self) -> u32 {
        self.period_us
    }
    fn reset(&mut self, positions: [i32; 2]) {
        self.reset_at = Some(positions);
    }
    fn step(&mut self, p: [i32; 2]) -> f64 {
        self.steps.push(p);
        if self.nan {
            return f64::NAN;
        }
        (self.k[0] * p[0] as f32 + self.k[1] * (p[1] - 2048) as f32) as f64
    }
    fn fallbacks(&self) -> u32 {
        self.fallbacks
    }
}

fn image(k: [f32; 2], period_us: u32, pad: usize) -> Vec<u8> {
    let mut v = b"LAW1".to_vec();
    v.extend(k[0].to_le_bytes());
    v.extend(k[1].to_le_bytes());
    v.extend(period_us.to_le_bytes());
    v.extend((0..pad).map(|i| (i * 7 + 3) as u8));
    v
}

fn inputs(now_us: u32, arm: u16, pendulum: u16) -> Inputs {
    Inputs {
        now_us,
        encoders: [arm, pendulum],
        driver_fault: false,
    }
}

/// A device whose pendulum is upright (2048 counts of a 4096-count encoder) and arm at 0.
fn device() -> Device<Law> {
    Device::with_onboard(Config::DEFAULT, &inputs(0, 0, 2048), [0, 2048], Law::new())
}

fn ack(dev: &mut Device<Law>, seq: u16, message: Message, now_us: u32) -> Ack {
    match dev.handle(
        Event::Frame(Frame { seq, message }),
        &inputs(now_us, 0, 2048),
    ) {
        Some(Frame {
            message: Message::Ack(a),
            ..
        }) => {
            assert_eq!(a.ack_seq, seq);
            assert_eq!(a.request, message.kind());
            a
        }
        other => panic!("no ack: {other:?}"),
    }
}

fn upload(dev: &mut Device<Law>, img: &[u8]) -> Ack {
    let begin = Message::UploadBegin(UploadBegin {
        total_len: img.len() as u32,
    });
    assert_eq!(ack(dev, 1, begin, 0).code, ACK_OK);
    for (i, piece) in img.chunks(CHUNK_MAX).enumerate() {
        let off = (i * CHUNK_MAX) as u32;
        let a = ack(
            dev,
            2,
            Message::UploadChunk(UploadChunk::new(off, piece)),
            0,
        );
        assert_eq!((a.code, a.value), (ACK_OK, off + piece.len() as u32));
    }
    let commit = Message::UploadCommit(UploadCommit {
        len: img.len() as u32,
        crc32: crc32(img),
    });
    ack(dev, 3, commit, 0)
}

fn start_settings() -> OnboardStart {
    OnboardStart {
        decimation: 4,
        host_timeout_ms: 50,
        arm_center: 0,
        arm_limit: 1000,
        pendulum_center: 2048,
        pendulum_limit: 300,
        flags: 0,
    }
}

fn start(dev: &mut Device<Law>) -> Ack {
    ack(dev, 4, Message::OnboardStart(start_settings()), 0)
}

fn telemetry(f: Option<Frame>) -> Telemetry {
    match f {
        Some(Frame {
            message: Message::Telemetry(t),
            ..
        }) => t,
        other => panic!("no telemetry: {other:?}"),
    }
}

fn running(period_us: u32) -> Device<Law> {
    let mut dev = device();
    let a = upload(&mut dev, &image([0.001, -0.01], period_us, 300));
    assert_eq!(
        (a.code, a.value),
        (ACK_OK, crc32(&image([0.001, -0.01], period_us, 300)))
    );
    assert_eq!(start(&mut dev).code, ACK_OK);
    dev
}

#[test]
fn an_upload_in_chunks_lands_byte_for_byte_and_is_checked() {
    let mut dev = device();
    let img = image([0.5, -0.25], 1000, 400);
    assert!(img.len() > 14 * CHUNK_MAX);
    let a = upload(&mut dev, &img);
    // The ack's value is the CRC-32 the device computed, zlib's for these bytes.
    assert_eq!((a.code, a.value), (ACK_OK, crc32(&img)));
    assert!(dev.design_loaded());
    assert_eq!(&dev.onboard().buf[..img.len()], &img[..]);
    assert_eq!(dev.onboard().k, [0.5, -0.25]);
    assert_eq!(dev.onboard().period_us, 1000);
}

#[test]
fn out_of_order_duplicate_and_oversize_chunks_are_refused_without_effect() {
    let mut dev = device();
    let img = image([1.0, 2.0], 1000, 100);
    let n = img.len() as u32;
    // Before any begin: nothing to append to.
    let c0 = Message::UploadChunk(UploadChunk::new(0, &img[..CHUNK_MAX]));
    assert_eq!(ack(&mut dev, 1, c0, 0).code, ACK_NO_UPLOAD);
    // An image larger than the buffer is refused at the begin.
    let big = Message::UploadBegin(UploadBegin { total_len: 513 });
    assert_eq!(ack(&mut dev, 2, big, 0).code, ACK_TOO_LARGE);
    assert_eq!(ack(&mut dev, 3, c0, 0).code, ACK_NO_UPLOAD);

    let begin = Message::UploadBegin(UploadBegin { total_len: n });
    assert_eq!(ack(&mut dev, 4, begin, 0).code, ACK_OK);
    assert_eq!(ack(&mut dev, 5, c0, 0).value, CHUNK_MAX as u32);
    // The same chunk again (its ack was lost): refused, naming where to continue.
    let a = ack(&mut dev, 6, c0, 0);
    assert_eq!((a.code, a.value), (ACK_OUT_OF_ORDER, CHUNK_MAX as u32));
    // A chunk from further on: refused likewise.
    let far = Message::UploadChunk(UploadChunk::new(
        2 * CHUNK_MAX as u32,
        &img[2 * CHUNK_MAX..3 * CHUNK_MAX],
    ));
    assert_eq!(ack(&mut dev, 7, far, 0).code, ACK_OUT_OF_ORDER);
    // A chunk that would run past the announced length.
    let garbage = [0xEEu8; CHUNK_MAX];
    let mut off = CHUNK_MAX as u32;
    for piece in img[CHUNK_MAX..].chunks(CHUNK_MAX) {
        if off + CHUNK_MAX as u32 > n {
            let over = Message::UploadChunk(UploadChunk::new(off, &garbage));
            let a = ack(&mut dev, 8, over, 0);
            assert_eq!((a.code, a.value), (ACK_TOO_LARGE, off));
        }
        let c = Message::UploadChunk(UploadChunk::new(off, piece));
        assert_eq!(ack(&mut dev, 9, c, 0).code, ACK_OK);
        off += piece.len() as u32;
    }
    // None of the refused chunks changed the buffer: the commit's CRC matches the image.
    let commit = Message::UploadCommit(UploadCommit {
        len: n,
        crc32: crc32(&img),
    });
    assert_eq!(ack(&mut dev, 10, commit, 0).code, ACK_OK);
    assert_eq!(&dev.onboard().buf[..img.len()], &img[..]);
}

#[test]
fn a_commit_is_checked_for_length_and_crc_and_the_design_for_sense() {
    let mut dev = device();
    let img = image([1.0, 2.0], 1000, 50);
    let n = img.len() as u32;
    let begin = Message::UploadBegin(UploadBegin { total_len: n });
    assert_eq!(ack(&mut dev, 1, begin, 0).code, ACK_OK);
    for (i, piece) in img.chunks(CHUNK_MAX).enumerate() {
        let c = Message::UploadChunk(UploadChunk::new((i * CHUNK_MAX) as u32, piece));
        ack(&mut dev, 2, c, 0);
    }
    let short = Message::UploadCommit(UploadCommit {
        len: n - 1,
        crc32: crc32(&img[..n as usize - 1]),
    });
    assert_eq!(ack(&mut dev, 3, short, 0).code, ACK_LENGTH_MISMATCH);
    let wrong = Message::UploadCommit(UploadCommit {
        len: n,
        crc32: crc32(&img) ^ 1,
    });
    let a = ack(&mut dev, 4, wrong, 0);
    assert_eq!((a.code, a.value), (ACK_CRC_MISMATCH, crc32(&img)));
    assert!(!dev.design_loaded());
    assert_eq!(start(&mut dev).code, ACK_NO_DESIGN);
    // A CRC mismatch ends the upload: it must begin again.
    let right = Message::UploadCommit(UploadCommit {
        len: n,
        crc32: crc32(&img),
    });
    assert_eq!(ack(&mut dev, 5, right, 0).code, ACK_NO_UPLOAD);
    // An intact image the controller cannot use.
    let mut bad = img.clone();
    bad[0] = b'X';
    assert_eq!(upload(&mut dev, &bad).code, ACK_DESIGN_REFUSED);
    assert_eq!(start(&mut dev).code, ACK_NO_DESIGN);
    assert!(!dev.enabled());
}

#[test]
fn the_v1_device_refuses_every_upload() {
    let mut dev = Device::new(Config::DEFAULT, &inputs(0, 0, 0));
    let reply = dev.handle(
        Event::Frame(Frame {
            seq: 1,
            message: Message::UploadBegin(UploadBegin { total_len: 10 }),
        }),
        &inputs(0, 0, 0),
    );
    let Some(Frame {
        message: Message::Ack(a),
        ..
    }) = reply
    else {
        panic!("{reply:?}")
    };
    assert_eq!(a.code, ACK_TOO_LARGE);
}

#[test]
fn start_settings_are_checked() {
    let mut dev = device();
    upload(&mut dev, &image([0.0, 0.0], 1000, 0));
    for bad in [
        OnboardStart {
            decimation: 0,
            ..start_settings()
        },
        OnboardStart {
            host_timeout_ms: 0,
            ..start_settings()
        },
        // A flag the device does not know (v3 defines bit 0 only).
        OnboardStart {
            flags: 0b10,
            ..start_settings()
        },
    ] {
        let a = ack(&mut dev, 1, Message::OnboardStart(bad), 0);
        assert_eq!(a.code, ACK_BAD_SETTINGS);
    }
    // Already outside the pendulum limit (hanging: 0 counts, 2048 from upright).
    let hanging = OnboardStart {
        pendulum_center: 4096,
        ..start_settings()
    };
    assert_eq!(
        ack(&mut dev, 2, Message::OnboardStart(hanging), 0).code,
        ACK_REFUSED
    );
    assert!(!dev.onboard_running());
}

#[test]
fn each_step_applies_the_law_on_the_devices_own_counts_with_decimated_telemetry() {
    let mut dev = running(1000);
    assert_eq!(dev.onboard().reset_at, Some([0, 2048]));
    let mut reports = Vec::new();
    for k in 0..12u32 {
        let arm = (80 * k) as u16;
        let pend = 2048 - 10 * k as u16;
        if let Some(f) = dev.onboard_tick(&inputs(k * 1000, arm, pend)) {
            reports.push(telemetry(Some(f)));
        }
        // Between steps nothing is due.
        assert!(dev
            .onboard_tick(&inputs(k * 1000 + 400, arm, pend))
            .is_none());
        let want = 0.001f32 * arm as f32 + -0.01f32 * (pend as i32 - 2048) as f32;
        assert_eq!(dev.voltage_mv(), (want * 1000.0).round() as i16, "step {k}");
        assert!(dev.enabled());
    }
    assert_eq!(dev.onboard().steps.len(), 12);
    assert_eq!(dev.onboard().steps[5], [400, 1998]);
    // Every 4th step reported, with its counts, move and state.
    assert_eq!(
        reports.iter().map(|t| t.step).collect::<Vec<_>>(),
        [0, 4, 8]
    );
    let t = reports[2];
    assert_eq!((t.arm_counts, t.pendulum_counts), (640, 1968));
    assert_eq!(t.applied_mv, 1440);
    assert_eq!(t.onboard, ONBOARD_RUNNING);
    assert_eq!(
        t.status & (STATUS_ONBOARD | STATUS_ENABLED),
        STATUS_ONBOARD | STATUS_ENABLED
    );
}

#[test]
fn telemetry_carries_the_laws_fallback_count_saturated_to_its_field() {
    let mut dev = running(1000);
    let report = |dev: &mut Device<Law>, k: u32| -> Option<Telemetry> {
        dev.onboard_tick(&inputs(k * 1000, 0, 2048))
            .map(|f| telemetry(Some(f)))
    };
    let first = report(&mut dev, 0).expect("step 0 is reported");
    assert_eq!(first.fallbacks, 0);
    dev.onboard_mut().fallbacks = 3;
    let reported: Vec<_> = (1..=4).filter_map(|k| report(&mut dev, k)).collect();
    assert_eq!(reported.len(), 1);
    assert_eq!((reported[0].step, reported[0].fallbacks), (4, 3));
    // A count beyond the u16 field reads as its largest value, never as a wrapped small one.
    dev.onboard_mut().fallbacks = 70_000;
    let reported: Vec<_> = (5..=8).filter_map(|k| report(&mut dev, k)).collect();
    assert_eq!(reported[0].fallbacks, u16::MAX);
}

#[test]
fn the_move_is_clamped_to_the_devices_voltage_limit() {
    let mut dev = Device::with_onboard(
        Config {
            voltage_limit_mv: 5000,
            ..Config::DEFAULT
        },
        &inputs(0, 0, 2048),
        [0, 2048],
        Law::new(),
    );
    upload(&mut dev, &image([1.0, 0.0], 1000, 0));
    assert_eq!(start(&mut dev).code, ACK_OK);
    dev.onboard_step(&inputs(0, 900, 2048));
    assert_eq!(dev.voltage_mv(), 5000);
    dev.onboard_step(&inputs(1000, (-900i16) as u16, 2048));
    assert_eq!(dev.voltage_mv(), -5000);
}

/// Runs steps until the device stops, returning the final telemetry.
fn until_stop(dev: &mut Device<Law>, mut at: impl FnMut(u32) -> Inputs) -> Telemetry {
    for k in 0..1000u32 {
        let t = dev.onboard_step(&at(k));
        if !dev.onboard_running() {
            return telemetry(t);
        }
    }
    panic!("never stopped");
}

fn assert_stopped(dev: &Device<Law>, t: &Telemetry, state: u8, brake: bool) {
    assert_eq!(t.onboard, state);
    assert_eq!(dev.onboard_state(), state);
    assert!(!dev.enabled());
    assert_eq!(dev.voltage_mv(), 0);
    assert_eq!(t.applied_mv, 0);
    assert_eq!(t.status & (STATUS_ONBOARD | STATUS_ENABLED), 0);
    assert_eq!(dev.pwm(1000), if brake { Pwm::BRAKE } else { Pwm::OFF });
    assert_eq!(t.status & STATUS_BRAKING != 0, brake);
}

#[test]
fn the_arm_limit_stops_and_brakes() {
    let mut dev = running(1000);
    let t = until_stop(&mut dev, |k| inputs(k * 1000, (k * 50) as u16, 2048));
    assert_stopped(&dev, &t, ONBOARD_ARM_LIMIT, true);
    // Stopped at the first step beyond 1000 counts, before the law ran on it.
    assert_eq!(t.arm_counts, 1050);
    assert_eq!(dev.onboard().steps.last(), Some(&[1000, 2048]));
}

#[test]
fn the_pendulum_limit_stops_and_brakes() {
    let mut dev = running(1000);
    let t = until_stop(&mut dev, |k| inputs(k * 1000, 0, 2048 + (k * 20) as u16));
    assert_stopped(&dev, &t, ONBOARD_PENDULUM_LIMIT, true);
    assert_eq!(t.pendulum_counts, 2048 + 320);
}

#[test]
fn a_silent_host_stops_the_motor_and_any_host_frame_keeps_it_running() {
    let mut dev = running(1000);
    for k in 0..200u32 {
        // A sample request every 20 ms: the 50 ms host timeout never elapses.
        if k % 20 == 0 {
            dev.handle(
                Event::Frame(Frame {
                    seq: k as u16,
                    message: Message::SampleRequest,
                }),
                &inputs(k * 1000, 0, 2048),
            );
        }
        dev.onboard_step(&inputs(k * 1000, 0, 2048));
        assert!(dev.onboard_running(), "step {k}");
    }
    // Then silence: stopped at the first step more than 50 ms after the last frame (180 ms).
    let t = until_stop(&mut dev, |k| inputs(200_000 + k * 1000, 0, 2048));
    assert_stopped(&dev, &t, ONBOARD_HOST_SILENT, true);
    assert_eq!(t.device_time_us, 231_000);
    assert_ne!(t.status & STATUS_WATCHDOG, 0);
}

#[test]
fn a_driver_fault_stops_with_the_windings_open() {
    let mut dev = running(1000);
    let t = until_stop(&mut dev, |k| Inputs {
        driver_fault: k == 7,
        ..inputs(k * 1000, 0, 2048)
    });
    assert_eq!(t.onboard, ONBOARD_DRIVER_FAULT);
    assert!(!dev.enabled());
    assert_eq!(dev.pwm(1000), Pwm::OFF);
}

#[test]
fn a_non_finite_move_stops() {
    let mut dev = running(1000);
    dev.onboard_step(&inputs(0, 0, 2048));
    dev.onboard_mut().nan = true;
    let t = until_stop(&mut dev, |k| inputs(1000 + k * 1000, 0, 2048));
    assert_stopped(&dev, &t, ONBOARD_BAD_MOVE, true);
}

#[test]
fn an_overrun_is_a_fault() {
    let mut dev = running(1000);
    dev.onboard_step(&inputs(0, 0, 2048));
    assert!(dev.record_step_cycles(167_999, 168_000, 0).is_none());
    assert!(dev.onboard_running());
    dev.onboard_step(&inputs(1000, 0, 2048));
    // An overrun ends with a final telemetry record, as every other stop does: the host
    // reads why the run ended, how long the step took, and what the bridge does.
    let t = telemetry(dev.record_step_cycles(168_001, 168_000, 1000));
    assert_eq!(dev.onboard_state(), ONBOARD_OVERRUN);
    assert_eq!(
        (t.onboard, t.step, t.step_cycles, t.overruns),
        (ONBOARD_OVERRUN, 1, 168_001, 1)
    );
    assert_eq!(t.device_time_us, 1000);
    assert_eq!(t.applied_mv, 0);
    assert!(!dev.enabled());
    assert_eq!(dev.pwm(1000), Pwm::BRAKE);
}

#[test]
fn a_command_frame_or_a_stop_frame_ends_onboard_mode() {
    let mut dev = running(1000);
    dev.onboard_step(&inputs(0, 500, 2048));
    assert!(dev.enabled());
    dev.handle(
        Event::Frame(Frame {
            seq: 9,
            message: Message::Command(Command::STOP),
        }),
        &inputs(500, 500, 2048),
    );
    assert!(!dev.onboard_running());
    assert_eq!(dev.onboard_state(), ONBOARD_STOPPED);
    assert!(dev.onboard_step(&inputs(1000, 500, 2048)).is_none());
    assert_eq!(dev.voltage_mv(), 0);

    // Restart (the design stays loaded) and stop with the onboard stop frame, braking.
    assert_eq!(start(&mut dev).code, ACK_OK);
    dev.onboard_step(&inputs(2000, 500, 2048));
    assert!(dev.enabled());
    let a = ack(
        &mut dev,
        10,
        Message::OnboardStop {
            flags: COMMAND_BRAKE,
        },
        2500,
    );
    assert_eq!((a.code, a.value), (ACK_OK, ONBOARD_STOPPED as u32));
    assert!(!dev.enabled());
    assert_eq!(dev.pwm(1000), Pwm::BRAKE);
}

#[test]
fn a_frame_of_another_version_stops_onboard_mode() {
    let mut dev = running(1000);
    dev.onboard_step(&inputs(0, 500, 2048));
    dev.handle(
        Event::Rejected(Rejection::Version(4)),
        &inputs(100, 500, 2048),
    );
    assert_eq!(dev.onboard_state(), ONBOARD_PROTOCOL);
    assert!(!dev.enabled());
    assert_eq!(dev.pwm(1000), Pwm::BRAKE);
}

#[test]
fn uploads_are_refused_while_running() {
    let mut dev = running(1000);
    let begin = Message::UploadBegin(UploadBegin { total_len: 16 });
    assert_eq!(ack(&mut dev, 1, begin, 0).code, ACK_BUSY);
    assert!(dev.onboard_running());
    assert!(dev.design_loaded());
}

#[test]
fn the_v1_watchdog_still_stops_the_motor_if_the_steps_stop() {
    let mut dev = running(1000);
    dev.onboard_step(&inputs(0, 500, 2048));
    assert!(dev.enabled());
    // No step and no frame for 60 ms (a hung timer interrupt): the main loop's tick stops it.
    dev.tick(&inputs(60_000, 500, 2048));
    assert!(!dev.enabled());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Any sequence of host frames and steps: no panic, and the motor is never driven unless
    /// onboard mode runs or the last host command enabled it, never beyond the limit.
    #[test]
    fn any_frames_and_steps_leave_the_device_consistent(
        ops in proptest::collection::vec(
            (0u8..8, any::<u32>(), proptest::collection::vec(any::<u8>(), 1..=CHUNK_MAX),
             any::<u16>(), any::<u16>()),
            0..200)
    ) {
        let mut dev = device();
        let img = image([0.01, -0.02], 1000, 60);
        let mut now = 0u32;
        let mut host_enabled = false;
        for (op, x, data, a, p) in ops {
            now = now.wrapping_add(x % 3000);
            let inp = inputs(now, a, p);
            let message = match op {
                0 => Message::UploadBegin(UploadBegin { total_len: x % 700 }),
                1 => Message::UploadChunk(UploadChunk::new(x % 128, &data)),
                2 => {
                    // A chunk of the real image: uploads do succeed in some sequences.
                    let i = (x % 3) as usize * CHUNK_MAX;
                    let end = (i + CHUNK_MAX).min(img.len());
                    Message::UploadChunk(UploadChunk::new(i as u32, &img[i..end]))
                }
                3 => Message::UploadCommit(UploadCommit { len: x % 128, crc32: x }),
                4 => Message::OnboardStart(OnboardStart { decimation: a % 4, ..start_settings() }),
                5 => Message::OnboardStop { flags: data[0] },
                6 => Message::Command(Command { voltage_mv: a as i16, flags: data[0] }),
                _ => {
                    dev.onboard_step(&inp);
                    prop_assert!(dev.voltage_mv().unsigned_abs() <= 12_000);
                    prop_assert!(dev.enabled() <= (dev.onboard_running() || host_enabled));
                    continue;
                }
            };
            if matches!(message, Message::UploadChunk(c) if c.len == 0) {
                continue;
            }
            if let Message::Command(c) = message {
                host_enabled = c.enabled();
            }
            if matches!(message, Message::OnboardStop { .. }) {
                host_enabled = false;
            }
            dev.handle(Event::Frame(Frame { seq: 0, message }), &inp);
            prop_assert!(dev.voltage_mv().unsigned_abs() <= 12_000);
            prop_assert!(dev.enabled() <= (dev.onboard_running() || host_enabled));
        }
    }
}

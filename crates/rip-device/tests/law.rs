//! The device's onboard law (`rip_device::law`) against rip-control's controller run directly:
//! the image's counts → angles conversion and reference step, and the PIL step's move.

use rip_control::{Controller, Design, Kind, Measurement};
use rip_device::law::{write_image, ControlLaw, Sensor};
use rip_device::{Config, Device, Inputs, Onboard};
use rip_protocol::{
    crc32, Event, Frame, Message, PilStep, UploadBegin, UploadChunk, UploadCommit, ACK_NO_DESIGN,
    ACK_OK, CHUNK_MAX, PIL_PHASE_SHIFT, PIL_RESET,
};

fn lqr() -> Design {
    Design {
        kind: Kind::Lqr,
        ts: 0.01,
        k: [-3.2, -1.9, 42.0, 4.1],
        rate_cutoff_hz: 25.0,
        ..Design::default()
    }
}

fn sensor() -> Sensor {
    Sensor {
        arm_rad_per_count: std::f64::consts::TAU / 2048.0,
        pendulum_rad_per_count: -std::f64::consts::TAU / 4096.0,
        arm_offset: 0.0,
        pendulum_offset: std::f64::consts::PI,
        arm_step: 0.5,
        step_time: 0.2,
    }
}

fn send(dev: &mut Device<ControlLaw<f64, 4096>>, message: Message) -> Option<Frame> {
    dev.handle(Event::Frame(Frame { seq: 1, message }), &Inputs::default())
}

/// A device in onboard mode with no design yet, and the LQR's upload image for it.
fn device_and_lqr_image() -> (Device<ControlLaw<f64, 4096>>, Vec<u8>) {
    let mut img = vec![0u8; 4096];
    let n = write_image(&sensor(), None, &lqr(), &mut img).unwrap();
    img.truncate(n);
    let dev = Device::with_onboard(
        Config::DEFAULT,
        &Inputs::default(),
        [0, 0],
        ControlLaw::<f64, 4096>::new(),
    );
    (dev, img)
}

#[test]
fn pil_steps_match_the_controller_on_independently_converted_angles() {
    let (mut dev, img) = device_and_lqr_image();
    let n = img.len();
    // Before any design: refused.
    let Some(Frame {
        message: Message::PilMove(m),
        ..
    }) = send(&mut dev, Message::PilStep(PilStep::default()))
    else {
        panic!()
    };
    assert_eq!(m.code, ACK_NO_DESIGN);
    send(
        &mut dev,
        Message::UploadBegin(UploadBegin {
            total_len: n as u32,
        }),
    );
    for (i, c) in img.chunks(CHUNK_MAX).enumerate() {
        send(
            &mut dev,
            Message::UploadChunk(UploadChunk::new((i * CHUNK_MAX) as u32, c)),
        );
    }
    let Some(Frame {
        message: Message::Ack(a),
        ..
    }) = send(
        &mut dev,
        Message::UploadCommit(UploadCommit {
            len: n as u32,
            crc32: crc32(&img),
        }),
    )
    else {
        panic!()
    };
    assert_eq!(a.code, ACK_OK);
    assert_eq!(dev.onboard().sensor(), &sensor());

    let mut reference = Controller::new(&lqr()).unwrap();
    for k in 0..60u32 {
        let arm = (k as i32 * 7) % 50 - 20;
        // Hanging at 0 counts; upright is 2048 counts of 4096 (either way).
        let pend = -2048 + (k as i32 % 9) - 4;
        let Some(Frame {
            message: Message::PilMove(m),
            ..
        }) = send(
            &mut dev,
            Message::PilStep(PilStep {
                arm_counts: arm,
                pendulum_counts: pend,
                flags: if k == 0 { PIL_RESET } else { 0 },
            }),
        )
        else {
            panic!()
        };
        assert_eq!((m.code, m.step), (ACK_OK, k + 1));
        let theta = arm as f64 * std::f64::consts::TAU / 2048.0;
        // −2048 counts · (−2π/4096) = π from hanging, i.e. upright; each count −2π/4096.
        let alpha = -(pend + 2048) as f64 * std::f64::consts::TAU / 4096.0;
        let r = if k as f64 * 0.01 >= 0.2 { 0.5 } else { 0.0 };
        let want = reference.step(Measurement {
            angles: [theta, alpha],
            reference: [r, 0.0],
        });
        assert!(
            (m.voltage() - want.voltage).abs() < 1e-12,
            "step {k}: {} vs {}",
            m.voltage(),
            want.voltage
        );
        // The PIL step never drives the motor.
        assert!(!dev.enabled());
    }
}

static READS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);

/// A cycle counter that advances by one on every read, so each part's count is the number of
/// part boundaries the device marked inside it.
fn counting() -> u32 {
    READS.fetch_add(1, std::sync::atomic::Ordering::SeqCst)
}

#[test]
fn pil_phase_flags_time_one_part_each_and_leave_the_move_unchanged() {
    let (mut dev, img) = device_and_lqr_image();
    let n = img.len();
    dev.set_cycle_counter(counting, 0);
    send(
        &mut dev,
        Message::UploadBegin(UploadBegin {
            total_len: n as u32,
        }),
    );
    for (i, c) in img.chunks(CHUNK_MAX).enumerate() {
        send(
            &mut dev,
            Message::UploadChunk(UploadChunk::new((i * CHUNK_MAX) as u32, c)),
        );
    }
    send(
        &mut dev,
        Message::UploadCommit(UploadCommit {
            len: n as u32,
            crc32: crc32(&img),
        }),
    );
    let mut reference = ControlLaw::<f64, 4096>::new();
    reference.buffer()[..n].copy_from_slice(&img);
    reference.load(n).unwrap();
    // An LQR step: the conversion, the rate filter, then the rest; it has no QP data or solve.
    let expected = [1, 1, 1, 0, 0, 1];
    for k in 0..24u32 {
        let phase = (k % 6) as u8;
        let c = [(k as i32 * 5) % 40 - 20, -2048 + (k as i32 % 7) - 3];
        if k == 0 {
            reference.reset(c);
        }
        let want = reference.step(c);
        let Some(Frame {
            message: Message::PilMove(m),
            ..
        }) = send(
            &mut dev,
            Message::PilStep(PilStep {
                arm_counts: c[0],
                pendulum_counts: c[1],
                flags: (if k == 0 { PIL_RESET } else { 0 }) | phase << PIL_PHASE_SHIFT,
            }),
        )
        else {
            panic!()
        };
        assert_eq!(m.code, ACK_OK);
        assert_eq!(m.voltage().to_bits(), want.to_bits(), "step {k}");
        assert_eq!(m.cycles, expected[phase as usize], "step {k}, part {phase}");
    }
}

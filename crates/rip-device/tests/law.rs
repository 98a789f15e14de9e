//! The device's onboard law (`rip_device::law`) against rip-control's controller run directly:
//! the image's counts → angles conversion and reference step, and the PIL step's move.

use rip_control::stop::{BrakeCommand, BrakingLaw, HoldLaw, StopDesign};
use rip_control::swing::ArmModel;
use rip_control::{Controller, Design, Kind, Measurement};
use rip_device::law::{write_image, ControlLaw, Sensor};
use rip_device::{Config, Device, Inputs, Onboard};
use rip_protocol::{
    crc32, Ack, Command, Event, Frame, Message, OnboardStart, PilStep, UploadBegin, UploadChunk,
    UploadCommit, WatchdogStop, ACK_BAD_SETTINGS, ACK_BUSY, ACK_NO_DESIGN, ACK_OK, ACK_REFUSED,
    CHUNK_MAX, COMMAND_BRAKE, COMMAND_ENABLE, ONBOARD_DRIVER_FAULT, ONBOARD_HOST_SILENT,
    ONBOARD_WIRING_VERIFIED, PIL_PHASE_SHIFT, PIL_RESET, PIL_STOP, TYPE_WATCHDOG_STOP,
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

/// A stop's design with the paper preset's lumped constants and gains of its size.
fn stop_design() -> StopDesign {
    StopDesign {
        law: BrakingLaw {
            voltage: 10.0,
            linear_below: 1.2,
        },
        dead_band: 0.46,
        hold: HoldLaw {
            k: [-50.0, -3.0, 25.0, 0.6],
            voltage: 10.0,
        },
        model: ArmModel {
            j0: 1.0e-3,
            ja: 8.0e-4,
            m12: 5.0e-4,
            grav: 0.033,
            b: 5.0e-3,
            c_arm: 2.3e-3,
            dp: 4.5e-4,
        },
        dead_zone: 0.0,
    }
}

/// `dev` with `img` uploaded and committed.
fn upload(dev: &mut Device<ControlLaw<f64, 4096>>, img: &[u8]) -> u8 {
    let n = img.len();
    send(
        dev,
        Message::UploadBegin(UploadBegin {
            total_len: n as u32,
        }),
    );
    for (i, c) in img.chunks(CHUNK_MAX).enumerate() {
        send(
            dev,
            Message::UploadChunk(UploadChunk::new((i * CHUNK_MAX) as u32, c)),
        );
    }
    match send(
        dev,
        Message::UploadCommit(UploadCommit {
            len: n as u32,
            crc32: crc32(img),
        }),
    ) {
        Some(Frame {
            message: Message::Ack(a),
            ..
        }) => a.code,
        other => panic!("{other:?}"),
    }
}

fn pil_stop(dev: &mut Device<ControlLaw<f64, 4096>>, counts: [i32; 2], reset: bool) -> (u8, f64) {
    match send(
        dev,
        Message::PilStep(PilStep {
            arm_counts: counts[0],
            pendulum_counts: counts[1],
            flags: PIL_STOP | if reset { PIL_RESET } else { 0 },
        }),
    ) {
        Some(Frame {
            message: Message::PilMove(m),
            ..
        }) => (m.code, m.voltage()),
        other => panic!("{other:?}"),
    }
}

/// The image's stop, stepped through the PIL, is rip-control's stop sequence on angles
/// converted here and rates over the design period: the same command each period; an image
/// without a stop's design refuses it.
#[test]
fn the_images_stop_is_rip_controls_sequence_on_independently_converted_angles() {
    let (mut dev, img) = device_and_lqr_image();
    assert_eq!(upload(&mut dev, &img), ACK_OK);
    assert_eq!(pil_stop(&mut dev, [0, -2048], true).0, ACK_REFUSED);
    let mut img = vec![0u8; 4096];
    let n = write_image(&sensor(), Some(&stop_design()), &lqr(), &mut img).unwrap();
    img.truncate(n);
    assert_eq!(upload(&mut dev, &img), ACK_OK);
    let mut reference = stop_design().sequence(0.01, true);
    let mut last: Option<(f64, f64)> = None;
    let mut kinds = [0usize; 3];
    for k in 0..400i32 {
        // The arm slowing from 60 counts a period, the pendulum falling from upright.
        let arm = (60 * k - k * k / 2).min(3600);
        let pend = -2048 + k * k / 40;
        let theta = arm as f64 * std::f64::consts::TAU / 2048.0;
        let alpha =
            rip_control::swing::wrap_angle(-(pend + 2048) as f64 * std::f64::consts::TAU / 4096.0);
        let (rate, alpha_rate) = match last {
            Some((t, a)) => (
                (theta - t) / 0.01,
                rip_control::swing::wrap_angle(alpha - a) / 0.01,
            ),
            None => (0.0, 0.0),
        };
        last = Some((theta, alpha));
        let want = reference.step(theta, rate, alpha, alpha_rate);
        let (code, got) = pil_stop(&mut dev, [arm, pend], k == 0);
        assert_eq!(code, ACK_OK);
        match want {
            Some(BrakeCommand::Volts(v)) => {
                kinds[0] += 1;
                assert!((got - v).abs() < 1e-9, "step {k}: {got} vs {v}");
            }
            Some(BrakeCommand::Short) => {
                kinds[1] += 1;
                assert_eq!(got, f64::INFINITY, "step {k}");
            }
            None => {
                kinds[2] += 1;
                assert!(got.is_nan(), "step {k}: {got}");
                break;
            }
        }
        assert!(!dev.enabled());
    }
    assert!(kinds[0] > 10, "{kinds:?}");
}

/// In onboard mode a silent host stops the run; with the wiring verified the device drives
/// its stop's braking law, without it it shorts the windings at once.
#[test]
fn a_silent_host_leaves_the_verified_device_braking_and_the_unverified_one_shorted() {
    for verified in [true, false] {
        let (mut dev, _) = device_and_lqr_image();
        let mut img = vec![0u8; 4096];
        let n = write_image(&sensor(), Some(&stop_design()), &lqr(), &mut img).unwrap();
        img.truncate(n);
        assert_eq!(upload(&mut dev, &img), ACK_OK);
        let start = OnboardStart {
            decimation: 1,
            host_timeout_ms: 50,
            arm_center: 0,
            arm_limit: 2000,
            pendulum_center: -2048,
            pendulum_limit: 400,
            flags: if verified { ONBOARD_WIRING_VERIFIED } else { 0 },
        };
        // The arm moving at 20 counts a period, the pendulum upright.
        let at = |t_us: u32| Inputs {
            now_us: t_us,
            encoders: [(t_us / 10_000 * 20) as u16, (-2048i32) as u16],
            driver_fault: false,
        };
        let handled = dev.handle(
            Event::Frame(Frame {
                seq: 2,
                message: Message::OnboardStart(start),
            }),
            &at(0),
        );
        assert!(handled.is_some());
        let mut drove_after = false;
        for k in 0..20u32 {
            let t = k * 10_000;
            dev.onboard_step(&at(t));
            if t > 60_000 && dev.enabled() {
                drove_after = true;
                // The arm moves the positive way: the braking law drives it back, at the bound.
                assert!(dev.voltage_mv() <= -9_000, "{} mV", dev.voltage_mv());
            }
        }
        assert_eq!(dev.onboard_state(), ONBOARD_HOST_SILENT);
        assert_eq!(drove_after, verified, "verified {verified}");
        if verified {
            // The device's own stop runs to its end: a start meanwhile is busy.
            let a = match dev.handle(
                Event::Frame(Frame {
                    seq: 3,
                    message: Message::OnboardStart(start),
                }),
                &at(200_000),
            ) {
                Some(Frame {
                    message: Message::Ack(a),
                    ..
                }) => a,
                other => panic!("{other:?}"),
            };
            assert_eq!(a.code, ACK_BUSY);
            assert!(dev.onboard_running());
        } else {
            assert!(!dev.onboard_running() && dev.braking());
        }
    }
}

/// The ack of `message` sent at `inputs`.
fn ack(dev: &mut Device<ControlLaw<f64, 4096>>, message: Message, inputs: &Inputs) -> Ack {
    match dev.handle(Event::Frame(Frame { seq: 4, message }), inputs) {
        Some(Frame {
            message: Message::Ack(a),
            ..
        }) => a,
        other => panic!("{other:?}"),
    }
}

/// A device with the LQR's image and its stop's design loaded.
fn device_with_stop() -> Device<ControlLaw<f64, 4096>> {
    let (mut dev, _) = device_and_lqr_image();
    let mut img = vec![0u8; 4096];
    let n = write_image(&sensor(), Some(&stop_design()), &lqr(), &mut img).unwrap();
    img.truncate(n);
    assert_eq!(upload(&mut dev, &img), ACK_OK);
    dev
}

const ARMED: WatchdogStop = WatchdogStop {
    flags: ONBOARD_WIRING_VERIFIED,
    arm_zero: 500,
    pendulum_down: 1000,
};

/// A watchdog stop is refused without a design, with a flag the device does not know and
/// during an onboard run, each refusal changing nothing: the watchdog then shorts.
#[test]
fn a_watchdog_stop_is_refused_where_it_cannot_hold_and_changes_nothing() {
    let (mut dev, _) = device_and_lqr_image();
    let w = Message::WatchdogStop(ARMED);
    assert_eq!(ack(&mut dev, w, &Inputs::default()).code, ACK_NO_DESIGN);
    let mut dev = device_with_stop();
    let unknown = Message::WatchdogStop(WatchdogStop {
        flags: 0x80,
        ..ARMED
    });
    assert_eq!(
        ack(&mut dev, unknown, &Inputs::default()).code,
        ACK_BAD_SETTINGS
    );
    // An image without a stop's design: accepted, and the short (value 0).
    let (mut plain, img) = device_and_lqr_image();
    assert_eq!(upload(&mut plain, &img), ACK_OK);
    let a = ack(&mut plain, w, &Inputs::default());
    assert_eq!(
        (a.code, a.value, a.request),
        (ACK_OK, 0, TYPE_WATCHDOG_STOP)
    );
    // Every refusal above left the watchdog's stop the short.
    for d in [&mut dev, &mut plain] {
        send(
            d,
            Message::Command(Command {
                voltage_mv: 1000,
                flags: COMMAND_ENABLE,
            }),
        );
        d.tick(&Inputs {
            now_us: 60_000,
            ..Inputs::default()
        });
        assert!(d.braking() && !d.onboard_running());
    }
    // During an onboard run: busy.
    let mut dev = device_with_stop();
    let start = OnboardStart {
        decimation: 1,
        host_timeout_ms: 50,
        arm_limit: 2000,
        pendulum_center: -2048,
        pendulum_limit: 400,
        ..OnboardStart::default()
    };
    let pendulum_up = Inputs {
        encoders: [0, (-2048i32) as u16],
        ..Inputs::default()
    };
    assert_eq!(
        ack(&mut dev, Message::OnboardStart(start), &pendulum_up).code,
        ACK_OK
    );
    assert_eq!(ack(&mut dev, w, &pendulum_up).code, ACK_BUSY);
}

/// Host mode: with the watchdog's stop armed, a host that goes silent while driving leaves
/// the device running rip-control's stop sequence, every period, on the angles zeroed at the
/// frame's counts (converted here independently), until a host command takes over; armed
/// unverified, or after a new upload, the watchdog shorts the windings.
#[test]
fn a_silent_host_in_host_mode_leaves_the_armed_device_running_the_stop_on_its_zeros() {
    let tau = std::f64::consts::TAU;
    // The arm moving the positive way at 20 counts a period from its zero, the pendulum
    // hanging at its zero count.
    let at = |t_us: u32| Inputs {
        now_us: t_us,
        encoders: [(500 + t_us / 10_000 * 20) as u16, 1000],
        driver_fault: false,
    };
    let mut dev = device_with_stop();
    let a = ack(&mut dev, Message::WatchdogStop(ARMED), &at(0));
    assert_eq!((a.code, a.value), (ACK_OK, 1));
    let enable = Message::Command(Command {
        voltage_mv: 2000,
        flags: COMMAND_ENABLE,
    });
    dev.handle(
        Event::Frame(Frame {
            seq: 5,
            message: enable,
        }),
        &at(0),
    );
    let mut reference = stop_design().sequence(0.01, true);
    let mut last: Option<(f64, f64)> = None;
    let mut compared = 0;
    for k in 0..60u32 {
        let t = k * 10_000;
        let inputs = at(t);
        dev.onboard_step(&inputs);
        if !dev.onboard_running() {
            // Before the watchdog's 50 ms: the host's command.
            assert!(t <= 50_000, "no stop at {t} µs");
            assert_eq!(dev.voltage_mv(), if t <= 50_000 { 2000 } else { 0 });
            continue;
        }
        assert_eq!(dev.onboard_state(), ONBOARD_HOST_SILENT);
        let theta = f64::from(inputs.encoders[0] as i32 - 500) * tau / 2048.0;
        let alpha = rip_control::swing::wrap_angle(
            f64::from(inputs.encoders[1] as i32 - 1000) * -tau / 4096.0 + std::f64::consts::PI,
        );
        let (rate, alpha_rate) = last.map_or((0.0, 0.0), |(t0, a0)| {
            (
                (theta - t0) / 0.01,
                rip_control::swing::wrap_angle(alpha - a0) / 0.01,
            )
        });
        last = Some((theta, alpha));
        match reference.step(theta, rate, alpha, alpha_rate) {
            Some(BrakeCommand::Volts(v)) => {
                assert!(dev.enabled(), "step {k}");
                assert_eq!(i32::from(dev.voltage_mv()), (v * 1000.0).round() as i32);
                compared += 1;
            }
            Some(BrakeCommand::Short) => assert!(dev.braking(), "step {k}"),
            None => break,
        }
    }
    assert!(compared > 5, "{compared} driven periods compared");
    // The host returns: its command takes over.
    dev.handle(
        Event::Frame(Frame {
            seq: 6,
            message: enable,
        }),
        &at(600_000),
    );
    assert!(!dev.onboard_running() && dev.voltage_mv() == 2000);
    // Armed without the flag, or armed and then a new upload (the wiring was verified for
    // the image before): the short.
    let unverified = WatchdogStop { flags: 0, ..ARMED };
    let upload = Message::UploadBegin(UploadBegin { total_len: 10 });
    for (armed, then) in [(unverified, None), (ARMED, Some(upload))] {
        let mut dev = device_with_stop();
        let a = ack(&mut dev, Message::WatchdogStop(armed), &at(0));
        assert_eq!((a.code, a.value), (ACK_OK, u32::from(then.is_some())));
        if let Some(message) = then {
            send(&mut dev, message);
        }
        dev.handle(
            Event::Frame(Frame {
                seq: 5,
                message: enable,
            }),
            &at(0),
        );
        dev.onboard_step(&at(60_000));
        assert!(dev.braking() && !dev.onboard_running());
    }
}

/// What ends the armed watchdog stop or refuses it: a driver fault that comes and goes
/// between two steps stops the device's stop for good, the plain stop frame (the end of the
/// host's run) disarms it while a brake command does not, and a design whose period the
/// board's timer does not run gets the short.
#[test]
fn the_watchdog_stop_ends_on_a_passing_fault_the_stop_frame_and_an_unrunnable_period() {
    let at = |t_us: u32, fault: bool| Inputs {
        now_us: t_us,
        encoders: [(500 + t_us / 10_000 * 20) as u16, 1000],
        driver_fault: fault,
    };
    let enable = |dev: &mut Device<ControlLaw<f64, 4096>>, t_us: u32| {
        let command = Message::Command(Command {
            voltage_mv: 2000,
            flags: COMMAND_ENABLE,
        });
        dev.handle(
            Event::Frame(Frame {
                seq: 5,
                message: command,
            }),
            &at(t_us, false),
        );
    };
    // A fault read by the main loop's tick between two steps, cleared by the next step.
    let mut dev = device_with_stop();
    ack(&mut dev, Message::WatchdogStop(ARMED), &at(0, false));
    enable(&mut dev, 0);
    dev.onboard_step(&at(60_000, false));
    dev.onboard_step(&at(70_000, false));
    assert!(dev.onboard_running() && dev.enabled());
    dev.tick(&at(75_000, true));
    dev.onboard_step(&at(80_000, false));
    assert!(!dev.onboard_running() && !dev.enabled() && !dev.braking());
    assert_eq!(dev.onboard_state(), ONBOARD_DRIVER_FAULT);
    // The plain stop frame disarms; a brake command keeps it armed.
    for (flags, armed) in [(COMMAND_BRAKE, true), (0, false)] {
        let mut dev = device_with_stop();
        ack(&mut dev, Message::WatchdogStop(ARMED), &at(0, false));
        let stop = Message::Command(Command {
            voltage_mv: 0,
            flags,
        });
        dev.handle(
            Event::Frame(Frame {
                seq: 6,
                message: stop,
            }),
            &at(0, false),
        );
        enable(&mut dev, 10_000);
        dev.onboard_step(&at(70_000, false));
        assert_eq!(dev.onboard_running(), armed, "flags {flags:#x}");
    }
    // A board whose timer runs 1–5 ms periods, a 10 ms design: the short.
    let (mut dev, _) = device_and_lqr_image();
    let mut dev2 = Device::with_onboard(
        Config {
            onboard_period_us: [1_000, 5_000],
            ..Config::DEFAULT
        },
        &Inputs::default(),
        [0, 0],
        ControlLaw::<f64, 4096>::new(),
    );
    let mut img = vec![0u8; 4096];
    let n = write_image(&sensor(), Some(&stop_design()), &lqr(), &mut img).unwrap();
    for d in [&mut dev, &mut dev2] {
        assert_eq!(upload(d, &img[..n]), ACK_OK);
    }
    let a = ack(&mut dev2, Message::WatchdogStop(ARMED), &at(0, false));
    assert_eq!((a.code, a.value), (ACK_OK, 0));
    let a = ack(&mut dev, Message::WatchdogStop(ARMED), &at(0, false));
    assert_eq!((a.code, a.value), (ACK_OK, 1));
}

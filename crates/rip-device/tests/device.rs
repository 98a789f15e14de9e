//! The device's behaviour on the host: watchdog timing, version mismatch, clamping, status,
//! sequence numbers, encoder wrap-around and command floods.

use proptest::prelude::*;
use rip_device::{Config, Device, Direction, EncoderCounter, Inputs, Pwm};
use rip_protocol::{
    encode, Command, Event, Frame, Measurement, Message, Parser, Rejection, COMMAND_BRAKE,
    COMMAND_ENABLE, MAX_FRAME, STATUS_BRAKING, STATUS_ENABLED, STATUS_FAULT, STATUS_RX_ERROR,
    STATUS_WATCHDOG,
};

fn at(now_us: u32) -> Inputs {
    Inputs {
        now_us,
        ..Inputs::default()
    }
}

fn command(seq: u16, voltage_mv: i16, flags: u8) -> Event {
    Event::Frame(Frame {
        seq,
        message: Message::Command(Command { voltage_mv, flags }),
    })
}

fn enable(mv: i16) -> Event {
    command(0, mv, COMMAND_ENABLE)
}

fn sample(dev: &mut Device, seq: u16, inputs: &Inputs) -> Measurement {
    match dev.handle(
        Event::Frame(Frame {
            seq,
            message: Message::SampleRequest,
        }),
        inputs,
    ) {
        Some(Frame {
            message: Message::Measurement(m),
            ..
        }) => m,
        other => panic!("no measurement: {other:?}"),
    }
}

#[test]
fn disabled_at_power_up_until_an_enabling_command() {
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    assert!(!dev.enabled());
    assert_eq!(dev.pwm(1000), Pwm::OFF);
    // A command without the enable bit leaves the driver off whatever its voltage.
    dev.handle(command(0, 5000, 0), &at(10));
    assert_eq!(dev.voltage_mv(), 0);
    assert_eq!(sample(&mut dev, 1, &at(20)).status & STATUS_ENABLED, 0);
    dev.handle(enable(5000), &at(30));
    assert_eq!(dev.voltage_mv(), 5000);
    let m = sample(&mut dev, 2, &at(40));
    assert_eq!(m.applied_mv, 5000);
    assert_eq!(m.status, STATUS_ENABLED);
}

#[test]
fn watchdog_zeroes_and_disables_after_the_timeout_and_not_before() {
    let cfg = Config {
        command_timeout_us: 50_000,
        ..Config::DEFAULT
    };
    let t0 = 1_000_000;
    let mut dev = Device::new(cfg, &at(t0));
    dev.handle(enable(3000), &at(t0));
    dev.tick(&at(t0 + 50_000));
    assert!(
        dev.enabled(),
        "exactly at the timeout the command is still fresh"
    );
    assert_eq!(dev.voltage_mv(), 3000);
    dev.tick(&at(t0 + 50_001));
    assert!(!dev.enabled());
    assert_eq!(dev.voltage_mv(), 0);
    // The host went silent while driving: the device brakes rather than let the arm coast.
    assert_eq!(dev.pwm(4199), Pwm::BRAKE);
    let m = sample(&mut dev, 9, &at(t0 + 60_000));
    assert_eq!(m.status, STATUS_WATCHDOG | STATUS_BRAKING);
    assert_eq!(m.applied_mv, 0);
    // It stays tripped (not re-enabled by time passing) until the next command.
    dev.tick(&at(t0 + 5_000_000));
    assert_eq!(dev.status(), STATUS_WATCHDOG | STATUS_BRAKING);
    dev.handle(enable(-2000), &at(t0 + 5_000_001));
    assert_eq!(dev.status(), STATUS_ENABLED);
    assert_eq!(dev.voltage_mv(), -2000);
}

#[test]
fn commands_every_period_keep_the_watchdog_fed_across_the_clock_wrap() {
    let mut dev = Device::new(Config::DEFAULT, &at(u32::MAX - 200_000));
    let mut t = u32::MAX - 200_000;
    for k in 0..100 {
        dev.handle(enable(1000 + k), &at(t));
        for _ in 0..10 {
            t = t.wrapping_add(1000);
            dev.tick(&at(t));
        }
        assert!(dev.enabled(), "period {k}, t = {t}");
    }
    assert!(t < 1_000_000, "the clock wrapped");
    // Then the host goes silent: 51 ms later the motor is off.
    t = t.wrapping_add(41_001);
    dev.tick(&at(t));
    assert!(!dev.enabled());
}

#[test]
fn a_version_mismatch_disables_at_once_until_a_new_enabling_command() {
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    dev.handle(enable(4000), &at(0));
    assert!(dev.enabled());
    dev.handle(Event::Rejected(Rejection::Version(2)), &at(100));
    assert!(!dev.enabled());
    assert_eq!(dev.pwm(1000), Pwm::BRAKE);
    let m = sample(&mut dev, 1, &at(200));
    assert_eq!(m.status, STATUS_RX_ERROR | STATUS_BRAKING);
    // RX_ERROR is reported once.
    assert_eq!(sample(&mut dev, 2, &at(300)).status, STATUS_BRAKING);
    dev.handle(enable(4000), &at(400));
    assert!(dev.enabled());
}

#[test]
fn a_frame_of_another_version_on_the_wire_disables_through_the_parser() {
    // A command of a future version 4: the same layout with version byte 4 and a valid CRC.
    let mut raw = vec![0xA5, 0x5A, 0x04, 0x02, 0x00, 0x00, 0x03, 0x88, 0x13, 0x01];
    let crc = rip_protocol::crc16(&raw[2..]).to_le_bytes();
    raw.extend_from_slice(&crc);
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    let mut parser = Parser::new();
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(
        &Frame {
            seq: 0,
            message: Message::Command(Command {
                voltage_mv: 5000,
                flags: COMMAND_ENABLE,
            }),
        },
        &mut buf,
    );
    dev.receive(&mut parser, &buf[..n], &at(0), |_| panic!("no reply"));
    assert!(dev.enabled());
    dev.receive(&mut parser, &raw, &at(10), |_| panic!("no reply"));
    assert!(!dev.enabled());
    assert_eq!(parser.stats().version_mismatches, 1);
}

#[test]
fn corrupt_frames_set_rx_error_but_keep_the_motor_running() {
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    dev.handle(enable(1500), &at(0));
    for r in [
        Rejection::Crc,
        Rejection::BadHeader,
        Rejection::Unknown { kind: 9, len: 0 },
    ] {
        dev.handle(Event::Rejected(r), &at(10));
        assert!(dev.enabled(), "{r:?}");
        assert_eq!(
            sample(&mut dev, 0, &at(20)).status,
            STATUS_ENABLED | STATUS_RX_ERROR
        );
    }
}

#[test]
fn commands_are_clamped_to_the_device_limit() {
    let cfg = Config {
        voltage_limit_mv: 6000,
        supply_mv: 12_000,
        ..Config::DEFAULT
    };
    let mut dev = Device::new(cfg, &at(0));
    for (cmd, applied, duty) in [
        (i16::MAX, 6000, 500),
        (6001, 6000, 500),
        (6000, 6000, 500),
        (-6000, -6000, 500),
        (-6001, -6000, 500),
        (i16::MIN, -6000, 500),
        (1200, 1200, 100),
        (-12, -12, 1),
        (0, 0, 0),
    ] {
        dev.handle(enable(cmd), &at(0));
        assert_eq!(dev.voltage_mv(), applied, "command {cmd}");
        assert_eq!(sample(&mut dev, 0, &at(0)).applied_mv, applied);
        let pwm = dev.pwm(1000);
        assert_eq!(pwm.duty, duty, "command {cmd}");
        assert!(pwm.enable);
        let dir = if applied < 0 {
            Direction::Reverse
        } else {
            Direction::Forward
        };
        assert_eq!(pwm.direction, dir);
    }
    // A limit above the supply is reduced to the supply.
    let dev = Device::new(
        Config {
            voltage_limit_mv: 30_000,
            supply_mv: 12_000,
            ..Config::DEFAULT
        },
        &at(0),
    );
    assert_eq!(dev.config().voltage_limit_mv, 12_000);
}

#[test]
fn driver_fault_disables_and_requires_a_new_enable() {
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    dev.handle(enable(2000), &at(0));
    let faulted = Inputs {
        driver_fault: true,
        ..at(100)
    };
    dev.tick(&faulted);
    assert!(!dev.enabled());
    assert_eq!(sample(&mut dev, 0, &faulted).status, STATUS_FAULT);
    // Commands during the fault are not applied.
    dev.handle(enable(2000), &faulted);
    assert!(!dev.enabled());
    // The fault clearing does not re-enable by itself.
    dev.tick(&at(300));
    assert!(!dev.enabled());
    dev.handle(enable(2000), &at(400));
    assert!(dev.enabled());
}

#[test]
fn measurements_echo_the_request_and_count_their_own_sequence() {
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    let mut parser = Parser::new();
    let mut replies = Vec::new();
    let mut stream = Vec::new();
    let mut buf = [0u8; MAX_FRAME];
    for seq in [65534u16, 65535, 0, 1] {
        let n = encode(
            &Frame {
                seq,
                message: Message::SampleRequest,
            },
            &mut buf,
        );
        stream.extend_from_slice(&buf[..n]);
    }
    dev.receive(&mut parser, &stream, &at(1234), |bytes| {
        replies.push(bytes.to_vec())
    });
    let mut host = Parser::new();
    let mut frames = Vec::new();
    host.feed(&replies.concat(), |f| frames.push(f));
    let got: Vec<(u16, u16)> = frames
        .iter()
        .map(|f| match f.message {
            Message::Measurement(m) => (f.seq, m.ack_seq),
            _ => panic!("{f:?}"),
        })
        .collect();
    assert_eq!(got, vec![(0, 65534), (1, 65535), (2, 0), (3, 1)]);
    assert_eq!(dev.next_seq(), 4);
}

#[test]
fn encoder_counter_follows_many_revolutions_both_ways() {
    // 2048 counts per revolution; 500 revolutions forward then 800 back, read every 700
    // counts, with the raw counter wrapping every 32 revolutions.
    let cpr = 2048i64;
    let start = 0x7FF0u16;
    let mut c = EncoderCounter::new(start, 0);
    let mut truth: i64 = 0;
    let step = |c: &mut EncoderCounter, d: i64, truth: &mut i64| {
        *truth += d;
        let raw = (start as i64 + *truth).rem_euclid(65536) as u16;
        assert_eq!(c.update(raw) as i64, *truth);
    };
    while truth < 500 * cpr {
        step(&mut c, 700, &mut truth);
    }
    while truth > -300 * cpr {
        step(&mut c, -700, &mut truth);
    }
    // The largest movement between readings that is still counted right.
    step(&mut c, 32767, &mut truth);
    step(&mut c, -32768, &mut truth);
    assert_eq!(c.position() as i64, truth);
}

#[test]
fn device_positions_track_the_counters() {
    let inputs = |now_us, a: u16, p: u16| Inputs {
        now_us,
        encoders: [a, p],
        driver_fault: false,
    };
    let mut dev = Device::with_positions(Config::DEFAULT, &inputs(0, 65000, 10), [100, -5]);
    dev.tick(&inputs(1, 1000, 0));
    assert_eq!(dev.positions(), [100 + 1536, -15]);
    let m = sample(&mut dev, 0, &inputs(2, 64536, 65535));
    // 1000 → 64536 is 2000 counts backwards through the wrap; 0 → 65535 one count back.
    assert_eq!([m.arm_counts, m.pendulum_counts], [100 + 1536 - 2000, -16]);
    assert_eq!(m.device_time_us, 2);
}

#[test]
fn a_flood_of_commands_applies_the_latest_and_answers_every_request() {
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    let mut parser = Parser::new();
    let mut stream = Vec::new();
    let mut buf = [0u8; MAX_FRAME];
    for k in 0..20_000u32 {
        let message = if k % 100 == 99 {
            Message::SampleRequest
        } else {
            Message::Command(Command {
                voltage_mv: (k % 24_000) as i16 - 12_000,
                flags: COMMAND_ENABLE,
            })
        };
        let n = encode(
            &Frame {
                seq: k as u16,
                message,
            },
            &mut buf,
        );
        stream.extend_from_slice(&buf[..n]);
    }
    let mut replies = 0;
    // Delivered in chunks of odd size, as a USB endpoint or a UART FIFO does.
    for (i, chunk) in stream.chunks(61).enumerate() {
        dev.receive(&mut parser, chunk, &at(i as u32), |_| replies += 1);
    }
    assert_eq!(replies, 200);
    assert_eq!(dev.commands_received(), 19_800);
    // The last command was k = 19 998: 19998 % 24000 - 12000.
    assert_eq!(dev.voltage_mv(), 7998);
    assert_eq!(parser.stats().errors(), 0);
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 256,
        failure_persistence: None,
        rng_seed: proptest::test_runner::RngSeed::Fixed(7),
        ..ProptestConfig::default()
    })]

    /// Whatever arrives and whenever, the drive stays within the limit, is off whenever the
    /// driver is disabled, and is off once the watchdog time has passed without a command.
    #[test]
    fn any_byte_stream_keeps_the_drive_safe(
        chunks in proptest::collection::vec(
            (proptest::collection::vec(any::<u8>(), 0..64), 0u32..80_000, any::<bool>()),
            0..64,
        ),
        limit in 0u16..=12_000,
    ) {
        let cfg = Config { voltage_limit_mv: limit, ..Config::DEFAULT };
        let mut dev = Device::new(cfg, &at(0));
        let mut parser = Parser::new();
        let mut now = 0u32;
        let mut last_command = 0u32;
        for (bytes, dt, fault) in &chunks {
            now = now.wrapping_add(*dt);
            let inputs = Inputs { now_us: now, encoders: [0, 0], driver_fault: *fault };
            let before = dev.commands_received();
            dev.receive(&mut parser, bytes, &inputs, |_| {});
            dev.tick(&inputs);
            if dev.commands_received() != before {
                last_command = now;
            }
            let v = dev.voltage_mv();
            prop_assert!(v.unsigned_abs() <= limit);
            let pwm = dev.pwm(1000);
            prop_assert!(pwm.duty <= 1000);
            if !dev.enabled() {
                // Not driving: open, or braking on a board that brakes, never under a fault.
                prop_assert!(pwm == Pwm::OFF || (pwm == Pwm::BRAKE && !*fault));
                prop_assert_eq!(pwm == Pwm::BRAKE, dev.status() & STATUS_BRAKING != 0);
                prop_assert_eq!(v, 0);
            }
            if *fault || now.wrapping_sub(last_command) > cfg.command_timeout_us {
                prop_assert!(!dev.enabled());
            }
        }
    }
}

#[test]
fn a_brake_command_shorts_the_windings_and_a_stop_command_opens_them() {
    let mut dev = Device::new(Config::DEFAULT, &at(0));
    dev.handle(enable(4000), &at(0));
    dev.handle(command(1, 0, COMMAND_BRAKE), &at(10));
    assert!(!dev.enabled());
    assert_eq!(dev.voltage_mv(), 0);
    assert_eq!(dev.pwm(1000), Pwm::BRAKE);
    assert_eq!(sample(&mut dev, 1, &at(20)).status, STATUS_BRAKING);
    // Braking is not driving: the watchdog does not trip on a silent host while it brakes.
    dev.tick(&at(1_000_000));
    assert_eq!(dev.status(), STATUS_BRAKING);
    // BRAKE with ENABLE drives the voltage.
    dev.handle(
        command(2, 3000, COMMAND_ENABLE | COMMAND_BRAKE),
        &at(1_000_010),
    );
    assert_eq!((dev.voltage_mv(), dev.status()), (3000, STATUS_ENABLED));
    // The stop frame (0 V, flags 0) leaves the windings open.
    dev.handle(command(3, 0, 0), &at(1_000_020));
    assert_eq!(dev.pwm(1000), Pwm::OFF);
    assert_eq!(dev.status(), 0);
}

#[test]
fn a_board_without_a_brake_leaves_the_windings_open_and_a_fault_opens_them() {
    let cfg = Config {
        can_brake: false,
        ..Config::DEFAULT
    };
    let mut dev = Device::new(cfg, &at(0));
    dev.handle(command(1, 0, COMMAND_BRAKE), &at(10));
    assert_eq!(dev.pwm(1000), Pwm::OFF);
    assert_eq!(dev.status(), 0);
    dev.handle(enable(2000), &at(20));
    dev.tick(&at(100_000));
    assert_eq!((dev.pwm(1000), dev.status()), (Pwm::OFF, STATUS_WATCHDOG));

    let mut dev = Device::new(Config::DEFAULT, &at(0));
    dev.handle(command(1, 0, COMMAND_BRAKE), &at(10));
    assert_eq!(dev.pwm(1000), Pwm::BRAKE);
    let faulted = Inputs {
        driver_fault: true,
        ..at(20)
    };
    dev.tick(&faulted);
    assert_eq!(dev.pwm(1000), Pwm::OFF);
    assert_eq!(dev.status(), STATUS_FAULT);
}

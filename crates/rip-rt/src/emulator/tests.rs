use super::*;
use crate::protocol::{
    Command, Measurement, COMMAND_ENABLE, STATUS_BRAKING, STATUS_ENABLED, STATUS_WATCHDOG,
};

fn measure(dev: &mut Device) -> Measurement {
    let mut out = [0u8; MAX_FRAME];
    let Reply::Bytes(n) = dev.handle(
        Event::Frame(Frame {
            seq: 3,
            message: Message::SampleRequest,
        }),
        &mut out,
    ) else {
        panic!("no reply");
    };
    let mut frames = Vec::new();
    Parser::new().feed(&out[..n], |f| frames.push(f));
    match frames[..] {
        [Frame {
            message: Message::Measurement(m),
            ..
        }] => m,
        _ => panic!("{frames:?}"),
    }
}

#[test]
fn the_motor_gets_the_pwm_voltage_until_the_watchdog_trips() {
    let mut dev = Device::new(EmulatorConfig::default());
    let mut out = [0u8; MAX_FRAME];
    let enable = Event::Frame(Frame {
        seq: 0,
        message: Message::Command(Command {
            voltage_mv: -5000,
            flags: COMMAND_ENABLE,
        }),
    });
    assert_eq!(dev.handle(enable, &mut out), Reply::None);
    dev.advance(1_000_000);
    // 24 V over 8400 steps: within half a step of the command.
    let step = 24.0 / PWM_MAX_DUTY as f64;
    assert!((dev.applied_voltage() + 5.0).abs() <= step / 2.0);
    let m = measure(&mut dev);
    assert_eq!((m.applied_mv, m.status), (-5000, STATUS_ENABLED));
    // 50 ms after the command the firmware's watchdog zeroes the motor.
    for _ in 0..49 {
        dev.advance(1_000_000);
    }
    assert!(dev.applied_voltage() != 0.0);
    dev.advance(1_000_000);
    dev.advance(1_000_000);
    assert_eq!(dev.applied_voltage(), 0.0);
    // The device stops the arm itself: the bridge shorts the windings.
    assert_eq!(dev.driver_state(), "brake");
    let m = measure(&mut dev);
    assert_eq!(
        (m.applied_mv, m.status),
        (0, STATUS_WATCHDOG | STATUS_BRAKING)
    );
    // Without a brake the windings are left open.
    let mut dev = Device::new(EmulatorConfig {
        can_brake: false,
        ..EmulatorConfig::default()
    });
    dev.handle(enable, &mut out);
    for _ in 0..52 {
        dev.advance(1_000_000);
    }
    assert_eq!(dev.driver_state(), "open");
    assert_eq!(measure(&mut dev).status, STATUS_WATCHDOG);
}

#[test]
fn counts_beyond_the_16_bit_counter_are_reported_whole() {
    // 400 rad of arm angle is 130 380 counts: two wraps of the firmware's 16-bit counter.
    let cfg = EmulatorConfig {
        initial_arm: 400.0,
        ..EmulatorConfig::default()
    };
    let mut dev = Device::new(cfg);
    for _ in 0..10 {
        dev.advance(1_000_000);
    }
    let m = measure(&mut dev);
    let expected = (400.0 * 2048.0 / std::f64::consts::TAU).round() as i32;
    assert_eq!(m.arm_counts, expected);
    // Hanging down is zero: upright (initial 0.05 rad) is half a revolution, 1024 counts on.
    let pendulum = ((0.05 + std::f64::consts::PI) * 2048.0 / std::f64::consts::TAU).round();
    assert_eq!(m.pendulum_counts, pendulum as i32);
}

/// Mean and standard deviation of `v`.
fn stats(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (
        m,
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt(),
    )
}

#[test]
fn the_encoders_read_the_sensor_section_as_the_simulation_measures_it() {
    use rand::SeedableRng;
    let text = "[sensor]\nencoder_counts = [4096, 1024]\nnoise_std = [2e-3, 5e-3]\n\
                encoder_offsets = [0.2, -0.1]\n";
    let sensor = rip_core::Spec::parse(text)
        .unwrap()
        .sim_config(0.01, 0)
        .sensor;
    let (arm, pendulum) = (0.3, 0.05);
    let cfg = EmulatorConfig {
        initial_arm: arm,
        initial_pendulum: pendulum,
        seed: 5,
        ..EmulatorConfig::default()
    }
    .with_sensor(&sensor);
    assert_eq!(
        (cfg.arm_counts_per_rev, cfg.pendulum_counts_per_rev),
        (4096, 1024)
    );
    // The device (held still until enabled) read N times, in radians as rip-rt reads it.
    let n = 4000;
    let tau = std::f64::consts::TAU;
    let mut dev = Device::new(cfg);
    let (mut emulated, mut simulated) = ([vec![], vec![]], [vec![], vec![]]);
    let mut rng = StdRng::seed_from_u64(11);
    let x = [arm, 0.0, pendulum, 0.0];
    for _ in 0..n {
        let m = measure(&mut dev);
        emulated[0].push(f64::from(m.arm_counts) * tau / 4096.0);
        emulated[1].push(f64::from(m.pendulum_counts) * tau / 1024.0 - tau / 2.0);
        let y = sensor.measure(&x, sensor.noise_std, &mut rng);
        simulated[0].push(y[0]);
        simulated[1].push(y[1]);
    }
    for j in 0..2 {
        let (me, se) = stats(&emulated[j]);
        let (ms, ss) = stats(&simulated[j]);
        let sigma = sensor.noise_std[j];
        // The same mean: the offset angle, quantised (4 standard errors of the difference).
        assert!(
            (me - ms).abs() < 4.0 * sigma * (2.0 / n as f64).sqrt(),
            "{j}: {me} {ms}"
        );
        assert!(
            (ms - x[2 * j] - sensor.offsets[j]).abs() < tau / 1024.0,
            "{j}: {ms}"
        );
        // The same spread, within what rounding the noise to whole counts adds (the
        // variance of a count's rounding, 1/12 count², is under 10 % of σ² here).
        assert!((se / ss - 1.0).abs() < 0.1, "{j}: {se} {ss}");
        assert!((ss / sigma - 1.0).abs() < 0.05, "{j}: {ss} {sigma}");
    }
}

#[test]
fn a_silence_loses_every_reply_in_its_window_only() {
    let mut dev = Device::new(EmulatorConfig {
        silence: Some((0.02, 0.01)),
        ..EmulatorConfig::default()
    });
    let mut out = [0u8; MAX_FRAME];
    let mut wire = Vec::new();
    let frame = [1u8, 2, 3];
    // Before the first enabling command the window has not started.
    dev.advance(30_000_000);
    dev.inject_faults(&frame, &mut wire);
    assert_eq!(wire, frame);
    let enable = Event::Frame(Frame {
        seq: 0,
        message: Message::Command(Command {
            voltage_mv: 0,
            flags: COMMAND_ENABLE,
        }),
    });
    dev.handle(enable, &mut out);
    // Sent at each millisecond after the enable: through before 20 ms, lost in [20, 30) ms,
    // through again from 30 ms.
    let mut sent = Vec::new();
    for _ in 0..40 {
        dev.inject_faults(&frame, &mut wire);
        sent.push(!wire.is_empty());
        dev.advance(1_000_000);
    }
    let lost: Vec<usize> = (0..40).filter(|&ms| !sent[ms]).collect();
    assert_eq!(lost, (20..30).collect::<Vec<_>>());
}

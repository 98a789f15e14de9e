//! The device's command handling on arbitrary traffic, timing and fault-line changes: it never
//! panics, never drives beyond its limit, drives nothing while disabled, and is disabled
//! whenever the driver faults or the watchdog time has passed since the last command.
//!
//! Input layout: two bytes of voltage limit, then records of a control byte (bit 7: fault
//! line; bits 0–6: chunk length), two bytes of elapsed time (×4 µs, so up to 262 ms, spanning
//! the 50 ms watchdog) and the chunk's bytes.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rip_device::{Config, Device, Inputs, Pwm};
use rip_protocol::Parser;

fuzz_target!(|data: &[u8]| {
    let Some((head, mut rest)) = data.split_first_chunk::<2>() else {
        return;
    };
    let cfg = Config {
        voltage_limit_mv: u16::from_le_bytes(*head) % 13_000,
        ..Config::DEFAULT
    };
    let limit = cfg.voltage_limit_mv;
    let mut now = u32::MAX - 100_000; // the clock wraps during long inputs
    let mut encoders = [0u16; 2];
    let mut dev = Device::new(
        cfg,
        &Inputs {
            now_us: now,
            encoders,
            driver_fault: false,
        },
    );
    let mut parser = Parser::new();
    let mut last_command = now;
    while let Some((&[ctl, t0, t1], tail)) = rest.split_first_chunk::<3>() {
        let len = (ctl & 0x7F) as usize;
        let (chunk, tail) = tail.split_at(len.min(tail.len()));
        rest = tail;
        let dt = u16::from_le_bytes([t0, t1]) as u32 * 4;
        now = now.wrapping_add(dt);
        encoders[0] = encoders[0].wrapping_add(t0 as u16);
        encoders[1] = encoders[1].wrapping_sub(t1 as u16);
        let inputs = Inputs {
            now_us: now,
            encoders,
            driver_fault: ctl & 0x80 != 0,
        };
        let before = dev.commands_received();
        dev.receive(&mut parser, chunk, &inputs, |reply| {
            assert!(!reply.is_empty())
        });
        dev.tick(&inputs);
        if dev.commands_received() != before {
            last_command = now;
        }
        let v = dev.voltage_mv();
        assert!(
            v.unsigned_abs() <= limit,
            "{v} mV beyond the {limit} mV limit"
        );
        let pwm = dev.pwm(4199);
        assert!(pwm.duty <= 4199);
        if !dev.enabled() {
            assert_eq!(pwm, Pwm::OFF);
            assert_eq!(v, 0);
        }
        if inputs.driver_fault || now.wrapping_sub(last_command) > cfg.command_timeout_us {
            assert!(!dev.enabled());
        }
    }
});

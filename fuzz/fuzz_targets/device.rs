//! The device's command handling on arbitrary traffic, timing and fault-line changes: it never
//! panics, never drives beyond its limit, drives nothing while disabled (it may only brake), and is disabled
//! whenever the driver faults or the watchdog time has passed since the last command.
//!
//! Input layout: two bytes of voltage limit, then records of a control byte and two bytes of
//! elapsed time (×4 µs, up to 262 ms, spanning the 50 ms watchdog). Control bit 7 is the fault
//! line; bit 6 set makes the record a valid frame built from three more bytes (a command with
//! that voltage and flags, or a sample request when the flags' bit 7 is set), so that the
//! fuzzer reaches command handling without having to forge CRCs; otherwise bits 0–5 give the
//! length of a chunk of raw bytes that follows.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rip_device::{Config, Device, Inputs, Pwm};
use rip_protocol::{encode, Command, Frame, Message, Parser, MAX_FRAME};

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
    let mut seq = 0u16;
    let mut frame = [0u8; MAX_FRAME];
    while let Some((&[ctl, t0, t1], tail)) = rest.split_first_chunk::<3>() {
        let chunk: &[u8] = if ctl & 0x40 != 0 {
            let Some((&[v0, v1, flags], tail)) = tail.split_first_chunk::<3>() else {
                return;
            };
            rest = tail;
            let message = if flags & 0x80 != 0 {
                Message::SampleRequest
            } else {
                Message::Command(Command {
                    voltage_mv: i16::from_le_bytes([v0, v1]),
                    flags,
                })
            };
            seq = seq.wrapping_add(1);
            let n = encode(&Frame { seq, message }, &mut frame);
            &frame[..n]
        } else {
            let (chunk, tail) = tail.split_at(((ctl & 0x3F) as usize).min(tail.len()));
            rest = tail;
            chunk
        };
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
        let pwm = dev.pwm(8400);
        assert!(pwm.duty <= 8400);
        if !dev.enabled() {
            // Not driving: windings open, or shorted (braking) but never under a fault.
            assert!(pwm == Pwm::OFF || (pwm == Pwm::BRAKE && !inputs.driver_fault));
            assert_eq!(v, 0);
        }
        if inputs.driver_fault || now.wrapping_sub(last_command) > cfg.command_timeout_us {
            assert!(!dev.enabled());
        }
    }
});

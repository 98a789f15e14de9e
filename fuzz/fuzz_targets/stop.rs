//! The device's stop (`rip_control::stop`) on arbitrary bytes and readings: reading a stop
//! design never panics, and one that reads writes back to the same bytes; its stop, run in
//! `f32` as the firmware runs it on arbitrary angles and rates, never panics and commands only
//! the short or a finite voltage within the design's bound.
//!
//! Input layout: a flag byte (bit 0: the wiring verified; bit 1: read the design as `f32`),
//! then the design's bytes (those past its length are the readings: records of four `i16`
//! angles and rates in mrad and mrad/s).

#![no_main]

use libfuzzer_sys::fuzz_target;
use rip_control::stop::{BrakeCommand, StopDesign, STOP_DESIGN_LEN, STOP_MAGIC};

/// Periods run: past the stop's bound at 10 ms ([`rip_control::stop::MAX_STOP_S`]).
const PERIODS: usize = 1000;

fuzz_target!(|data: &[u8]| {
    let Some((&flags, rest)) = data.split_first() else {
        return;
    };
    // The fuzzer rarely finds the magic and the version: the design's first 8 bytes are given.
    let mut bytes = [0u8; STOP_DESIGN_LEN];
    bytes[..4].copy_from_slice(&STOP_MAGIC);
    bytes[4..6].copy_from_slice(&1u16.to_le_bytes());
    bytes[6..8].copy_from_slice(&15u16.to_le_bytes());
    let n = rest.len().min(STOP_DESIGN_LEN - 8);
    bytes[8..8 + n].copy_from_slice(&rest[..n]);
    let readings = &rest[n..];
    let _ = StopDesign::<f64>::read(rest);
    let Ok(design) = StopDesign::<f64>::read(&bytes) else {
        return;
    };
    let mut again = [0u8; STOP_DESIGN_LEN];
    design.write(&mut again).expect("a design that reads writes");
    assert_eq!(again, bytes);
    if flags & 2 == 0 {
        return;
    }
    let Ok(d32) = StopDesign::<f32>::read(&bytes) else {
        return;
    };
    let mut stop = d32.sequence(0.01, flags & 1 != 0);
    let bound = d32.law.voltage;
    let mut records = readings.chunks_exact(8);
    for _ in 0..PERIODS {
        let r = records.next().unwrap_or(&[0; 8]);
        let v = |i: usize| f32::from(i16::from_le_bytes([r[2 * i], r[2 * i + 1]])) * 1e-3;
        match stop.step(v(0), v(1), v(2), v(3)) {
            Some(BrakeCommand::Volts(u)) => assert!(u.is_finite() && u.abs() <= bound, "{u}"),
            Some(BrakeCommand::Short) => {}
            None => return,
        }
    }
});

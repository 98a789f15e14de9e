//! Firmware for the rotary inverted pendulum rig's STM32F407 (STM32F4-Discovery by default).
//!
//! One loop, no interrupts: read the hardware (clock, encoder counters, driver fault line),
//! let `rip-device` handle whatever bytes arrived on the link, drive the H-bridge from its
//! output, show the state on the LEDs and feed the hardware watchdog. The protocol code is
//! `rip-protocol` and the device behaviour `rip-device`, exactly what `rip-rt emulate` runs on
//! the PC, so the end-to-end tests against the emulator test this logic.
//!
//! Safety: the driver's enable line is low from reset until the PC sends an enabling command;
//! the command watchdog of `rip-device` stops driving when commands stop for 50 ms (and
//! brakes: the bridge shorts the windings, see `board`); the IWDG resets
//! the MCU (and so drops it) if the loop hangs; a panic drops it and halts.

#![no_std]
#![no_main]
#![deny(unsafe_op_in_unsafe_fn)]

mod board;
mod link;

use cortex_m_rt::entry;
use rip_device::{Config, Device, Inputs};
use rip_protocol::Parser;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    board::emergency_off();
    // Halt without feeding the IWDG: it resets the MCU, which starts disabled.
    loop {
        cortex_m::asm::nop();
    }
}

#[entry]
fn main() -> ! {
    let Some(dp) = pac::Peripherals::take() else {
        panic!("peripherals taken twice");
    };
    let (mut board, link) = board::take(dp);
    board.iwdg.start(board::IWDG_MS.millis());

    let cfg = Config {
        voltage_limit_mv: board::VOLTAGE_LIMIT_MV,
        supply_mv: board::SUPPLY_MV,
        can_brake: board::CAN_BRAKE,
        ..Config::DEFAULT
    };
    let read = |b: &board::Board| Inputs {
        now_us: b.now_us(),
        encoders: b.encoders(),
        driver_fault: b.bridge.fault(),
    };
    let mut device = Device::new(cfg, &read(&board));
    let mut parser = Parser::new();
    let mut link = link::Link::new(link);
    let mut rx = [0u8; 64];

    loop {
        board.iwdg.feed();
        let inputs = read(&board);
        device.tick(&inputs);
        let n = link.read(&mut rx);
        if n > 0 {
            // Sampled again: the encoders are read as close to the request as possible.
            let inputs = read(&board);
            device.receive(&mut parser, &rx[..n], &inputs, |reply| link.write(reply));
        }
        board.bridge.apply(device.pwm(board.bridge.max_duty()));
        let status = device.status();
        let alarm = status & (rip_protocol::STATUS_WATCHDOG | rip_protocol::STATUS_FAULT) != 0;
        board.leds.show(device.enabled(), alarm, inputs.now_us);
    }
}

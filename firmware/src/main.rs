//! Firmware for the rotary inverted pendulum rig's STM32F407 (STM32F4-Discovery by default).
//!
//! The main loop reads the hardware (clock, encoder counters, driver fault line), lets
//! `rip-device` handle whatever bytes arrived on the link, drives the H-bridge from its output,
//! shows the state on the LEDs and feeds the hardware watchdog. The protocol code is
//! `rip-protocol` and the device behaviour `rip-device`, exactly what `rip-rt emulate` runs on
//! the PC, so the end-to-end tests against the emulator test this logic.
//!
//! Onboard mode (protocol v2): the host uploads a design into the device's buffer and starts
//! it; then the SysTick exception, at the design's rate (1 kHz down to 100 Hz; any other
//! period is refused by stopping at once), steps rip-control's controller in `f32` (the
//! Cortex-M4F's FPU; `f64` is emulated in software) on the device's own encoder counts. The
//! step is timed by SysTick itself: its countdown at the step's end is the time since the
//! period began, and a wrap during the step (an overrun, a step longer than its period) stops
//! the motor. SysTick rather than a general-purpose timer, because QEMU models it on its
//! virtual clock, period after period, so the timer-driven loop runs there (`firmware/pil.sh`
//! checks its period); QEMU's TIM2 model does not repeat its update interrupt. The telemetry
//! the step streams is queued for the main loop to send. The device's own stop on the command
//! watchdog in host mode (protocol v3's watchdog stop) runs as such an onboard run, so SysTick
//! steps it too.
//! Processor-in-the-loop steps (`PilStep`), outside onboard mode, are timed with the DWT
//! counter on the board and, in the USART builds for QEMU, whose DWT counter reads 0, with
//! SysTick free-running over its 24 bits.
//!
//! Safety: the driver's enable line is low from reset until the PC sends an enabling command
//! or starts onboard mode; the command watchdog of `rip-device` stops driving when commands
//! stop for 50 ms (and brakes: the bridge shorts the windings, see `board`, or, armed by the
//! host with the wiring verified, runs the image's stop: braking, holding, then the short), onboard mode
//! stops on the host's silence, the angle limits, a driver fault and an overrun; the IWDG
//! resets the MCU (and so drops it) if the loop hangs; a panic drops it and halts.

#![no_std]
#![no_main]
#![deny(unsafe_op_in_unsafe_fn)]

mod board;
mod link;

use core::cell::RefCell;

use cortex_m::interrupt::{free, Mutex};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{DWT, SYST};
use cortex_m_rt::{entry, exception};
use rip_device::law::ControlLaw;
use rip_device::{Config, Device, Inputs, Onboard};
use rip_protocol::{encode, Event, Frame, Message, Parser, COMMAND_BRAKE, MAX_FRAME};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;

/// Bytes of the design buffer: the paper's MPC (P = 50, m = 3) takes 10 506.
pub const DESIGN_BUFFER: usize = 12 * 1024;
/// Shortest and longest onboard step period (µs): 1 kHz down to 100 Hz.
pub const PERIOD_RANGE_US: core::ops::RangeInclusive<u32> = 1_000..=10_000;

type Law = ControlLaw<f32, DESIGN_BUFFER>;

const CFG: Config = Config {
    voltage_limit_mv: board::VOLTAGE_LIMIT_MV,
    supply_mv: board::SUPPLY_MV,
    can_brake: board::CAN_BRAKE,
    onboard_period_us: [*PERIOD_RANGE_US.start(), *PERIOD_RANGE_US.end()],
    ..Config::DEFAULT
};

// In statics, built at compile time: the controller is tens of kilobytes, more than a copy
// on the stack could spare.
static DEVICE: Mutex<RefCell<Device<Law>>> =
    Mutex::new(RefCell::new(Device::at_power_up(CFG, Law::new())));
static BOARD: Mutex<RefCell<Option<board::Board>>> = Mutex::new(RefCell::new(None));
static OUTBOX: Mutex<RefCell<Outbox>> = Mutex::new(RefCell::new(Outbox::new()));
static SYSTICK: Mutex<RefCell<Option<SYST>>> = Mutex::new(RefCell::new(None));

/// SysTick ticks per microsecond of the build's clock.
const TICKS_PER_US: u32 = board::SYSTICK_HZ / 1_000_000;

/// Encoded frames waiting for the main loop to send them (replies and telemetry); a frame
/// that does not fit is dropped (the host counts telemetry steps).
struct Outbox {
    buf: [u8; 1024],
    len: usize,
}

impl Outbox {
    const fn new() -> Self {
        Self {
            buf: [0; 1024],
            len: 0,
        }
    }

    fn push(&mut self, frame: &Frame) {
        let mut out = [0u8; MAX_FRAME];
        let n = encode(frame, &mut out);
        self.push_bytes(&out[..n]);
    }

    fn push_bytes(&mut self, bytes: &[u8]) {
        if let Some(dst) = self.buf.get_mut(self.len..self.len + bytes.len()) {
            dst.copy_from_slice(bytes);
            self.len += bytes.len();
        }
    }

    /// Moves up to `out.len()` bytes out.
    fn take(&mut self, out: &mut [u8]) -> usize {
        let n = self.len.min(out.len());
        out[..n].copy_from_slice(&self.buf[..n]);
        self.buf.copy_within(n..self.len, 0);
        self.len -= n;
        n
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    board::emergency_off();
    // Halt without feeding the IWDG: it resets the MCU, which starts disabled.
    loop {
        cortex_m::asm::nop();
    }
}

fn read(b: &board::Board) -> Inputs {
    Inputs {
        now_us: b.now_us(),
        encoders: b.encoders(),
        driver_fault: b.bridge.fault(),
    }
}

/// SysTick as a 32-bit up-counter in units of 1/256 cycle (`rip-device`'s cycle counter with
/// shift 8): QEMU models it, on its virtual clock, where the DWT counter reads 0. Valid while
/// SysTick runs free ([`systick_free`]), i.e. outside onboard mode, where PIL steps run.
fn systick_counter() -> u32 {
    (0x00FF_FFFF - SYST::get_current()) << 8
}

/// SysTick counting down over its full 24 bits without its exception.
fn systick_free(s: &mut SYST) {
    s.disable_interrupt();
    s.disable_counter();
    s.set_reload(0x00FF_FFFF);
    s.clear_current();
    s.enable_counter();
}

/// SysTick's exception every `period_us` (at most 99 ms at 168 MHz: the reload is 24 bits).
fn systick_periodic(s: &mut SYST, period_us: u32) {
    s.disable_counter();
    s.set_reload(period_us * TICKS_PER_US - 1);
    s.clear_current();
    // A wrap flag left from free running would read as an overrun of the first step.
    let _ = s.has_wrapped();
    s.enable_interrupt();
    s.enable_counter();
}

fn dwt_counter() -> u32 {
    DWT::cycle_count()
}

#[entry]
fn main() -> ! {
    let Some(dp) = pac::Peripherals::take() else {
        panic!("peripherals taken twice");
    };
    let Some(mut cp) = cortex_m::Peripherals::take() else {
        panic!("core peripherals taken twice");
    };
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();
    cp.SYST.set_clock_source(SystClkSource::Core);
    systick_free(&mut cp.SYST);

    let (mut board, link) = board::take(dp);
    board.iwdg.start(board::IWDG_MS.millis());
    free(|cs| {
        let mut dev = DEVICE.borrow(cs).borrow_mut();
        // The counters' readings at power-up stand for position 0.
        let inputs = read(&board);
        dev.rebase(&inputs);
        if cfg!(feature = "usart") {
            dev.set_cycle_counter(systick_counter, 8);
        } else {
            dev.set_cycle_counter(dwt_counter, 0);
        }
        BOARD.borrow(cs).replace(Some(board));
        SYSTICK.borrow(cs).replace(Some(cp.SYST));
    });

    let mut parser = Parser::new();
    let mut link = link::Link::new(link);
    let mut rx = [0u8; 64];
    let mut tx = [0u8; 128];
    let mut timer_period_us = 0u32;

    loop {
        let n = link.read(&mut rx);
        free(|cs| {
            let mut b = BOARD.borrow(cs).borrow_mut();
            let Some(board) = b.as_mut() else {
                return;
            };
            board.iwdg.feed();
            let mut dev = DEVICE.borrow(cs).borrow_mut();
            let mut outbox = OUTBOX.borrow(cs).borrow_mut();
            let inputs = read(board);
            dev.tick(&inputs);
            if n > 0 {
                dev.receive(&mut parser, &rx[..n], &inputs, |reply| {
                    outbox.push_bytes(reply)
                });
            }
            // SysTick steps exactly while onboard mode runs, at the design's period.
            let want = if dev.onboard_running() {
                dev.onboard().period_us()
            } else {
                0
            };
            if want != timer_period_us {
                timer_period_us = 0;
                if let Some(syst) = SYSTICK.borrow(cs).borrow_mut().as_mut() {
                    systick_free(syst);
                    if want != 0 && PERIOD_RANGE_US.contains(&want) {
                        systick_periodic(syst, want);
                        timer_period_us = want;
                    }
                }
                if want != 0 && timer_period_us == 0 {
                    // A rate this firmware does not run: stop as the host would.
                    let stop = Frame {
                        seq: 0,
                        message: Message::OnboardStop {
                            flags: COMMAND_BRAKE,
                        },
                    };
                    let _ = dev.handle(Event::Frame(stop), &inputs);
                }
            }
            board.bridge.apply(dev.pwm(board.bridge.max_duty()));
            let status = dev.status();
            let alarm = status & (rip_protocol::STATUS_WATCHDOG | rip_protocol::STATUS_FAULT) != 0;
            board.leds.show(dev.enabled(), alarm, inputs.now_us);
        });
        // Written outside the critical section: a blocking USART write must not hold off the
        // step interrupt.
        loop {
            let k = free(|cs| OUTBOX.borrow(cs).borrow_mut().take(&mut tx));
            if k == 0 {
                break;
            }
            link.write(&tx[..k]);
        }
    }
}

/// One onboard controller step: the device's own encoder counts, the move on the bridge at
/// once, and the step's time against its period. SysTick's countdown at the end is the time
/// since the period began (the interrupt's latency included, since the move is due within the
/// period); a wrap since the entry means the step ran into the next period, an overrun, which
/// stops onboard mode.
#[exception]
fn SysTick() {
    free(|cs| {
        let mut st = SYSTICK.borrow(cs).borrow_mut();
        let mut b = BOARD.borrow(cs).borrow_mut();
        let (Some(syst), Some(board)) = (st.as_mut(), b.as_mut()) else {
            return;
        };
        // Reading the flag clears it: only a wrap during this step sets it again.
        let _ = syst.has_wrapped();
        let mut dev = DEVICE.borrow(cs).borrow_mut();
        let inputs = read(board);
        let frame = dev.onboard_step(&inputs);
        board.bridge.apply(dev.pwm(board.bridge.max_duty()));
        let period = SYST::get_reload() + 1;
        let into_period = period - 1 - SYST::get_current();
        let ticks = if syst.has_wrapped() {
            period + into_period
        } else {
            into_period
        };
        let overrun = dev.record_step_cycles(ticks, period, inputs.now_us);
        // An overrun's stop is applied now, not at the next pass of the main loop.
        board.bridge.apply(dev.pwm(board.bridge.max_duty()));
        let mut outbox = OUTBOX.borrow(cs).borrow_mut();
        for f in [frame, overrun].into_iter().flatten() {
            outbox.push(&f);
        }
    });
}

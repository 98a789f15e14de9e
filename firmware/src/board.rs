//! Every pin and peripheral the firmware uses, in one place: the STM32F4-Discovery default.
//! To wire the rig differently, change this file only (firmware/README.md lists the wiring).
//!
//! | function                     | pin        | peripheral                  |
//! |------------------------------|------------|-----------------------------|
//! | arm encoder A / B            | PB4 / PB5  | TIM3 CH1/CH2, encoder mode  |
//! | pendulum encoder A / B       | PC6 / PC7  | TIM8 CH1/CH2, encoder mode  |
//! | H-bridge PWM                 | PE9        | TIM1 CH1, 20 kHz            |
//! | H-bridge direction           | PE7        | GPIO out                    |
//! | H-bridge enable (active high)| PE8        | GPIO out, low at reset      |
//!
//! The bridge is a PHASE/ENABLE driver (the DRV8835 / DRV8838 class): PE7 sets the direction,
//! the PWM on PE9 switches the high side, and PE8 (its sleep line) enables it. With PE8 low the
//! outputs are high-impedance: the motor's windings are **open** and the arm coasts. With PE8
//! high and 0 % duty both low-side switches conduct: the windings are **shorted** and back-EMF
//! brakes the arm (`rip-device`, "A motor that is not driven"). A driver without that brake
//! state sets [`CAN_BRAKE`] false.
//! | H-bridge fault (active low)  | PE10       | GPIO in, pull-up            |
//! | status LED (green)           | PD12       | on: driver enabled          |
//! | fault LED (red)              | PD14       | on: watchdog or fault       |
//! | USB (CN5 micro-USB)          | PA11 / PA12| OTG FS, CDC-ACM             |
//! | USART (feature `usart`)      | PB6 / PB7  | USART1 TX/RX, 115200 8N1    |
//! | microsecond clock            | —          | TIM5, 32-bit free-running   |
//! | onboard controller step      | —          | SysTick exception           |

use rip_device::{Direction, Pwm};
use stm32f4xx_hal::gpio::{Input, Output, Pin, PushPull};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::qei::Qei;
use stm32f4xx_hal::rcc::{Config, Rcc};
use stm32f4xx_hal::timer::{CounterUs, PwmChannel};

/// Supply of the H-bridge (mV): the voltage at 100 % duty. This board is the reference rig, so
/// it is the device's default (the motor's rated voltage).
pub const SUPPLY_MV: u16 = rip_device::Config::DEFAULT.supply_mv;
/// The device's own voltage limit (mV), at most the supply: the device's default.
pub const VOLTAGE_LIMIT_MV: u16 = rip_device::Config::DEFAULT.voltage_limit_mv;
/// The bridge brakes (shorts the windings) at 0 % duty with its enable line high.
pub const CAN_BRAKE: bool = true;
/// PWM frequency: above hearing, low enough for common H-bridges' switching times.
pub const PWM_HZ: u32 = 20_000;
/// Hardware watchdog period (ms): the main loop feeds it every pass, so only a hung or
/// panicked firmware lets it expire, and the reset disables the motor.
pub const IWDG_MS: u32 = 100;

/// SysTick's clock (Hz), the core clock of the build ([`clocks`]): the onboard step's period
/// and budget in ticks are its period times this. QEMU's `netduinoplus2` clocks SysTick at its
/// fixed 168 MHz system clock whatever the RCC is set to, so the `qemu` build counts that.
pub const SYSTICK_HZ: u32 = if cfg!(feature = "qemu") || !cfg!(feature = "usart") {
    168_000_000
} else {
    16_000_000
};
/// The bridge has a fault line. QEMU models no GPIO (every pin reads low, the fault level), so
/// the `qemu` build reads none; a board build always does.
pub const HAS_FAULT_LINE: bool = !cfg!(feature = "qemu");
/// The encoders are read. QEMU models no encoder mode: its TIM3 counts the timer clock, an arm
/// that would read as turning a million counts a second, whatever the timer's enable bit says.
/// The `qemu` build reads both counters as 0, a rig at rest, so that a run from the command
/// line can start against the image; a board build always reads them.
pub const HAS_ENCODERS: bool = !cfg!(feature = "qemu");

/// Clocks: the Discovery's 8 MHz crystal, 168 MHz core, 48 MHz for USB. The USART build for
/// QEMU runs on the internal 16 MHz oscillator, because QEMU does not model the RCC's ready flags
/// that switching to the crystal and the PLL waits for.
pub fn clocks() -> Config {
    if cfg!(feature = "usart") {
        Config::hsi()
    } else {
        Config::hse(8.MHz()).sysclk(168.MHz()).require_pll48clk()
    }
}

/// The H-bridge: PWM, direction and enable lines, and the fault input.
pub struct Bridge {
    pwm: PwmChannel<pac::TIM1, 0>,
    direction: Pin<'E', 7, Output<PushPull>>,
    enable: Pin<'E', 8, Output<PushPull>>,
    fault: Pin<'E', 10, Input>,
    max_duty: u16,
}

impl Bridge {
    /// Compare value at 100 % duty.
    pub fn max_duty(&self) -> u16 {
        self.max_duty
    }

    /// Whether the driver reports a fault (the line is active low).
    pub fn fault(&self) -> bool {
        HAS_FAULT_LINE && self.fault.is_low()
    }

    /// Drives the bridge. Off first, on last: the enable line is only raised once the
    /// direction and duty are in place, and lowered before they change. Braking is 0 % duty
    /// with the enable line high (module docs).
    pub fn apply(&mut self, p: Pwm) {
        if !p.enable {
            self.pwm.set_duty(0);
            if p.brake && CAN_BRAKE {
                self.enable.set_high();
            } else {
                self.enable.set_low();
            }
            return;
        }
        let forward = p.direction == Direction::Forward;
        if self.direction.is_set_high() != forward {
            // Reversing under load: cut the drive for the switch.
            self.pwm.set_duty(0);
            self.direction.set_state(forward.into());
        }
        self.pwm.set_duty(p.duty.min(self.max_duty));
        self.enable.set_high();
    }
}

/// The status LEDs.
pub struct Leds {
    green: Pin<'D', 12, Output<PushPull>>,
    red: Pin<'D', 14, Output<PushPull>>,
}

impl Leds {
    /// Green: the driver is enabled (blinks slowly while idle, to show the firmware runs). Red:
    /// the command watchdog tripped or the driver faulted.
    pub fn show(&mut self, enabled: bool, alarm: bool, now_us: u32) {
        let heartbeat = (now_us >> 19) & 1 == 1; // about 1 Hz
        self.green.set_state((enabled || heartbeat).into());
        self.red.set_state(alarm.into());
    }
}

/// The link to the PC.
#[cfg(not(feature = "usart"))]
pub type LinkParts = stm32f4xx_hal::otg_fs::USB;
/// The link to the PC.
#[cfg(feature = "usart")]
pub type LinkParts = stm32f4xx_hal::serial::Serial<pac::USART1>;

/// Everything the main loop uses.
pub struct Board {
    /// Arm encoder counter.
    pub arm: Qei<pac::TIM3>,
    /// Pendulum encoder counter.
    pub pendulum: Qei<pac::TIM8>,
    /// Free-running microsecond clock.
    pub clock: CounterUs<pac::TIM5>,
    /// The H-bridge.
    pub bridge: Bridge,
    /// Status LEDs.
    pub leds: Leds,
    /// The independent hardware watchdog, not yet started.
    pub iwdg: stm32f4xx_hal::watchdog::IndependentWatchdog,
}

impl Board {
    /// The 16-bit encoder counters (arm, pendulum); 0 in the `qemu` build ([`HAS_ENCODERS`]).
    pub fn encoders(&self) -> [u16; 2] {
        if HAS_ENCODERS {
            [self.arm.count(), self.pendulum.count()]
        } else {
            [0, 0]
        }
    }

    /// The microsecond clock.
    pub fn now_us(&self) -> u32 {
        self.clock.now().ticks()
    }
}

/// Sets the clocks and takes the peripherals: the bridge disabled first, then everything else.
pub fn take(dp: pac::Peripherals) -> (Board, LinkParts) {
    let mut rcc: Rcc = dp.RCC.freeze(clocks());
    let rcc = &mut rcc;
    let gpioa = dp.GPIOA.split(rcc);
    let gpiob = dp.GPIOB.split(rcc);
    let gpioc = dp.GPIOC.split(rcc);
    let gpiod = dp.GPIOD.split(rcc);
    let gpioe = dp.GPIOE.split(rcc);

    // The driver's enable line is low (and externally pulled down) before anything else runs.
    let enable = gpioe.pe8.into_push_pull_output_in_state(false.into());
    let direction = gpioe.pe7.into_push_pull_output();
    let fault = gpioe.pe10.into_pull_up_input();

    let (_, (ch1, ..)) = dp.TIM1.pwm_hz(PWM_HZ.Hz(), rcc);
    let mut pwm = ch1.with(gpioe.pe9);
    pwm.set_duty(0);
    pwm.enable();
    let max_duty = pwm.get_max_duty();

    // PB4 leaves reset as the JTAG NJTRST input (AF0); SWD, which programs the board, does not
    // use it.
    let arm = Qei::new(dp.TIM3, (gpiob.pb4.into_input(), gpiob.pb5), rcc);
    let pendulum = Qei::new(dp.TIM8, (gpioc.pc6, gpioc.pc7), rcc);

    let mut clock = dp.TIM5.counter_us(rcc);
    // The longest period a 32-bit microsecond counter allows: it wraps after 71 minutes.
    clock
        .start(u32::MAX.micros())
        .unwrap_or_else(|_| panic!("TIM5"));
    // QEMU's timers count a 1 GHz clock divided by the prescaler, whatever the RCC is set
    // to; the prescaler for a 1 µs tick at that clock makes the device's time QEMU's virtual
    // time (and so the watchdogs' timeouts true ones).
    #[cfg(feature = "qemu")]
    {
        // SAFETY: TIM5 is owned by `clock` above; a prescaler write and an update event
        // (which loads it and restarts the count at 0) before anything reads the clock.
        let tim5 = unsafe { &*pac::TIM5::ptr() };
        tim5.psc().write(|w| w.psc().set(999));
        tim5.egr().write(|w| w.ug().set_bit());
    }

    #[cfg(not(feature = "usart"))]
    let link = stm32f4xx_hal::otg_fs::USB::new(
        (dp.OTG_FS_GLOBAL, dp.OTG_FS_DEVICE, dp.OTG_FS_PWRCLK),
        (gpioa.pa11, gpioa.pa12),
        &rcc.clocks,
    );
    #[cfg(feature = "usart")]
    let link = {
        let _ = gpioa;
        dp.USART1
            .serial((gpiob.pb6, gpiob.pb7), 115_200.bps(), rcc)
            .unwrap_or_else(|_| panic!("USART1"))
    };

    let board = Board {
        arm,
        pendulum,
        clock,
        bridge: Bridge {
            pwm,
            direction,
            enable,
            fault,
            max_duty,
        },
        leds: Leds {
            green: gpiod.pd12.into_push_pull_output(),
            red: gpiod.pd14.into_push_pull_output(),
        },
        iwdg: stm32f4xx_hal::watchdog::IndependentWatchdog::new(dp.IWDG),
    };
    (board, link)
}

/// Lowers the H-bridge enable line without the HAL: for the panic handler, which cannot reach
/// the `Board`.
pub fn emergency_off() {
    // SAFETY: a single atomic write to the port's bit-set/reset register, which cannot disturb
    // other pins; the panic handler never returns to code that holds the port.
    let gpioe = unsafe { &*pac::GPIOE::ptr() };
    gpioe.bsrr().write(|w| w.br8().set_bit());
}

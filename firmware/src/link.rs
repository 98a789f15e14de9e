//! The byte link to the PC: USB CDC-ACM (default) or USART1 (feature `usart`). Neither blocks:
//! the main loop must keep feeding the hardware watchdog, so a reply that cannot be written at
//! once is dropped (the PC counts it as a missing reply and repeats its command).

#[cfg(not(feature = "usart"))]
pub use usb::Link;

#[cfg(feature = "usart")]
pub use usart::Link;

#[cfg(not(feature = "usart"))]
mod usb {
    use static_cell::{ConstStaticCell, StaticCell};
    use stm32f4xx_hal::otg_fs::{UsbBus, UsbBusType, USB};
    use usb_device::bus::UsbBusAllocator;
    use usb_device::prelude::*;
    use usbd_serial::SerialPort;

    static EP_MEMORY: ConstStaticCell<[u32; 1024]> = ConstStaticCell::new([0; 1024]);
    static BUS: StaticCell<UsbBusAllocator<UsbBusType>> = StaticCell::new();

    /// USB CDC-ACM: no FTDI-style latency timer, a reply leaves in the next 1 ms frame.
    pub struct Link {
        dev: UsbDevice<'static, UsbBusType>,
        serial: SerialPort<'static, UsbBusType>,
    }

    impl Link {
        /// Brings up the USB device (VID/PID of the shared CDC-ACM pair from pid.codes).
        pub fn new(usb: USB) -> Self {
            let bus = BUS.init(UsbBus::new(usb, EP_MEMORY.take()));
            let serial = SerialPort::new(bus);
            let dev = UsbDeviceBuilder::new(bus, UsbVidPid(0x16c0, 0x27dd))
                .device_class(usbd_serial::USB_CLASS_CDC)
                .strings(&[StringDescriptors::default()
                    .manufacturer("riprs")
                    .product("rip pendulum (protocol v1)")
                    .serial_number("0001")])
                .unwrap_or_else(|_| panic!("USB strings"))
                .build();
            Self { dev, serial }
        }

        /// Services the USB stack and returns the bytes received, if any.
        pub fn read(&mut self, buf: &mut [u8]) -> usize {
            if !self.dev.poll(&mut [&mut self.serial]) {
                return 0;
            }
            self.serial.read(buf).unwrap_or(0)
        }

        /// Queues `bytes` for the host; what does not fit in a few tries is dropped.
        pub fn write(&mut self, bytes: &[u8]) {
            let mut off = 0;
            for _ in 0..4 {
                if off == bytes.len() {
                    break;
                }
                match self.serial.write(&bytes[off..]) {
                    Ok(n) => off += n,
                    Err(_) => {
                        self.dev.poll(&mut [&mut self.serial]);
                    }
                }
            }
            let _ = self.serial.flush();
        }
    }
}

#[cfg(feature = "usart")]
mod usart {
    use stm32f4xx_hal::pac::USART1;
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::serial::Serial;

    /// USART1 at 115200 8N1.
    pub struct Link {
        serial: Serial<USART1>,
    }

    impl Link {
        /// Wraps the configured USART.
        pub fn new(serial: Serial<USART1>) -> Self {
            Self { serial }
        }

        /// Returns the bytes received since the last call (the USART holds one byte, so the
        /// loop must run faster than one byte time, 87 µs at 115200 baud).
        pub fn read(&mut self, buf: &mut [u8]) -> usize {
            let mut n = 0;
            while n < buf.len() {
                match self.serial.read() {
                    Ok(b) => {
                        buf[n] = b;
                        n += 1;
                    }
                    // An overrun lost bytes: the parser resynchronises on what follows.
                    Err(nb::Error::Other(_)) => continue,
                    Err(nb::Error::WouldBlock) => break,
                }
            }
            n
        }

        /// Sends `bytes`, waiting for the transmitter (26 bytes take 2.3 ms at 115200 baud,
        /// well inside the hardware watchdog's period).
        pub fn write(&mut self, bytes: &[u8]) {
            for &b in bytes {
                let _ = nb::block!(self.serial.write(b));
            }
        }
    }
}

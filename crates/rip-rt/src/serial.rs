//! Raw serial I/O on a file descriptor (termios), and pseudo-terminals for the emulator.
//!
//! Raw termios on a plain descriptor works the same on a USB CDC device, a UART and a Linux
//! pseudo-terminal, and lets the loop wait with `ppoll` to microsecond resolution.

use std::ffi::CString;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd};
use std::path::{Path, PathBuf};

/// Maps a baud rate to its termios constant.
fn baud_constant(baud: u32) -> Option<libc::speed_t> {
    Some(match baud {
        9600 => libc::B9600,
        19200 => libc::B19200,
        38400 => libc::B38400,
        57600 => libc::B57600,
        115200 => libc::B115200,
        230400 => libc::B230400,
        460800 => libc::B460800,
        500000 => libc::B500000,
        921600 => libc::B921600,
        1000000 => libc::B1000000,
        2000000 => libc::B2000000,
        _ => return None,
    })
}

/// Baud rates accepted by [`SerialPort::open`].
pub const SUPPORTED_BAUDS: [u32; 11] = [
    9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600, 1000000, 2000000,
];

fn cvt(rc: libc::c_int) -> io::Result<libc::c_int> {
    if rc < 0 {
        Err(io::Error::last_os_error())
    } else {
        Ok(rc)
    }
}

/// Puts the terminal on `fd` into raw 8N1 mode (no echo, no line editing, no flow control,
/// non-blocking reads) at `speed`.
fn make_raw(fd: RawFd, speed: Option<libc::speed_t>) -> io::Result<()> {
    // SAFETY: termios is plain data; tcgetattr fills it and fails cleanly on a non-terminal.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        cvt(libc::tcgetattr(fd, &mut t))?;
        libc::cfmakeraw(&mut t);
        t.c_cflag |= libc::CLOCAL | libc::CREAD;
        t.c_cflag &= !(libc::CRTSCTS | libc::CSTOPB | libc::PARENB);
        t.c_iflag &= !(libc::IXON | libc::IXOFF | libc::IXANY);
        t.c_cc[libc::VMIN] = 0;
        t.c_cc[libc::VTIME] = 0;
        if let Some(speed) = speed {
            cvt(libc::cfsetispeed(&mut t, speed))?;
            cvt(libc::cfsetospeed(&mut t, speed))?;
        }
        cvt(libc::tcsetattr(fd, libc::TCSANOW, &t))?;
    }
    Ok(())
}

fn set_nonblocking(fd: RawFd) -> io::Result<()> {
    // SAFETY: fcntl on a descriptor we own.
    unsafe {
        let flags = cvt(libc::fcntl(fd, libc::F_GETFL))?;
        cvt(libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK))?;
    }
    Ok(())
}

/// What [`Fd::wait_readable`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Readiness {
    /// Bytes can be read.
    Readable,
    /// The timeout passed first.
    Timeout,
    /// A signal interrupted the wait.
    Interrupted,
}

/// A non-blocking byte stream on a raw descriptor (a serial device or a PTY master).
#[derive(Debug)]
pub struct Fd {
    fd: OwnedFd,
}

impl Fd {
    fn new(fd: OwnedFd) -> Self {
        Self { fd }
    }

    /// The raw descriptor (for the stop-on-panic hook, which must write without locks).
    pub fn raw(&self) -> RawFd {
        self.fd.as_raw_fd()
    }

    /// Waits until bytes are available or `timeout_ns` passes. A hang-up (the device went
    /// away) is an error of kind `BrokenPipe`.
    pub fn wait_readable(&self, timeout_ns: u64) -> io::Result<Readiness> {
        let mut pfd = libc::pollfd {
            fd: self.raw(),
            events: libc::POLLIN,
            revents: 0,
        };
        let ts = libc::timespec {
            tv_sec: (timeout_ns / 1_000_000_000) as libc::time_t,
            tv_nsec: (timeout_ns % 1_000_000_000) as libc::c_long,
        };
        // SAFETY: one valid pollfd, a valid timespec, no signal mask change.
        let rc = unsafe { libc::ppoll(&mut pfd, 1, &ts, std::ptr::null()) };
        if rc < 0 {
            let err = io::Error::last_os_error();
            return if err.kind() == io::ErrorKind::Interrupted {
                Ok(Readiness::Interrupted)
            } else {
                Err(err)
            };
        }
        if rc == 0 {
            return Ok(Readiness::Timeout);
        }
        if pfd.revents & libc::POLLIN != 0 {
            return Ok(Readiness::Readable);
        }
        if pfd.revents & (libc::POLLHUP | libc::POLLERR | libc::POLLNVAL) != 0 {
            return Err(io::Error::new(
                io::ErrorKind::BrokenPipe,
                "the device hung up",
            ));
        }
        Ok(Readiness::Timeout)
    }

    /// Reads whatever is available (0 when nothing is). End of file or `EIO` (what a PTY or a
    /// USB serial device returns once the other end is gone) is an error of kind `BrokenPipe`.
    pub fn read_available(&self, buf: &mut [u8]) -> io::Result<usize> {
        // SAFETY: `buf` is valid for `buf.len()` bytes.
        let n = unsafe { libc::read(self.raw(), buf.as_mut_ptr().cast(), buf.len()) };
        if n > 0 {
            return Ok(n as usize);
        }
        if n == 0 {
            return Err(io::Error::new(
                io::ErrorKind::BrokenPipe,
                "the device closed the connection",
            ));
        }
        let err = io::Error::last_os_error();
        match err.raw_os_error() {
            Some(libc::EAGAIN) | Some(libc::EINTR) => Ok(0),
            Some(libc::EIO) | Some(libc::ENXIO) | Some(libc::ENODEV) => Err(io::Error::new(
                io::ErrorKind::BrokenPipe,
                format!("the device is gone ({err})"),
            )),
            _ => Err(err),
        }
    }

    /// Writes all of `data`, waiting briefly when the output buffer is full.
    pub fn write_all(&self, mut data: &[u8]) -> io::Result<()> {
        let mut stalls = 0;
        while !data.is_empty() {
            // SAFETY: `data` is valid for `data.len()` bytes.
            let n = unsafe { libc::write(self.raw(), data.as_ptr().cast(), data.len()) };
            if n > 0 {
                data = &data[n as usize..];
                continue;
            }
            let err = io::Error::last_os_error();
            match err.raw_os_error() {
                Some(libc::EINTR) => {}
                Some(libc::EAGAIN) if stalls < 100 => {
                    stalls += 1;
                    let mut pfd = libc::pollfd {
                        fd: self.raw(),
                        events: libc::POLLOUT,
                        revents: 0,
                    };
                    // SAFETY: one valid pollfd.
                    unsafe { libc::poll(&mut pfd, 1, 1) };
                }
                Some(libc::EAGAIN) => {
                    return Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        "the device stopped accepting data",
                    ))
                }
                Some(libc::EIO) | Some(libc::ENXIO) | Some(libc::ENODEV) => {
                    return Err(io::Error::new(
                        io::ErrorKind::BrokenPipe,
                        format!("the device is gone ({err})"),
                    ))
                }
                _ => return Err(err),
            }
        }
        Ok(())
    }

    /// Discards unread input.
    pub fn flush_input(&self) {
        // SAFETY: plain call on our descriptor; failure (not a terminal) is harmless.
        unsafe { libc::tcflush(self.raw(), libc::TCIFLUSH) };
    }
}

/// A serial device opened in raw mode.
#[derive(Debug)]
pub struct SerialPort {
    io: Fd,
    path: PathBuf,
}

impl SerialPort {
    /// Opens `path` in raw 8N1 mode at `baud` (see [`SUPPORTED_BAUDS`]).
    pub fn open(path: &Path, baud: u32) -> io::Result<Self> {
        let speed = baud_constant(baud).ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("--baud: {baud} is not one of {SUPPORTED_BAUDS:?}"),
            )
        })?;
        let c_path = CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| {
            io::Error::new(io::ErrorKind::InvalidInput, "--port: path contains a NUL")
        })?;
        // SAFETY: valid C string; the returned descriptor is owned below.
        let raw = unsafe {
            libc::open(
                c_path.as_ptr(),
                libc::O_RDWR | libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC,
            )
        };
        let raw = cvt(raw)
            .map_err(|e| io::Error::new(e.kind(), format!("--port {}: {e}", path.display())))?;
        // SAFETY: `raw` is a freshly opened descriptor nobody else owns.
        let fd = unsafe { OwnedFd::from_raw_fd(raw) };
        // SAFETY: isatty only inspects the descriptor.
        if unsafe { libc::isatty(raw) } != 1 {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("--port {}: not a serial device (terminal)", path.display()),
            ));
        }
        // Two loops on one device would steal each other's replies while both drive the
        // motor. TIOCEXCL does not bind root, so the claim is an advisory lock every rip-rt
        // takes; it ends with the descriptor, however the process exits.
        // SAFETY: flock only inspects the descriptor.
        if unsafe { libc::flock(raw, libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let e = io::Error::last_os_error();
            let why = if e.kind() == io::ErrorKind::WouldBlock {
                "in use by another rip-rt".to_string()
            } else {
                format!("cannot lock: {e}")
            };
            return Err(io::Error::new(
                io::ErrorKind::WouldBlock,
                format!("--port {}: {why}", path.display()),
            ));
        }
        make_raw(raw, Some(speed))
            .map_err(|e| io::Error::new(e.kind(), format!("--port {}: {e}", path.display())))?;
        let io = Fd::new(fd);
        io.flush_input();
        Ok(Self {
            io,
            path: path.to_path_buf(),
        })
    }

    /// The byte stream.
    pub fn io(&self) -> &Fd {
        &self.io
    }

    /// The device path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// A pseudo-terminal pair: the emulator speaks on the master, the loop opens the slave path.
#[derive(Debug)]
pub struct Pty {
    master: Fd,
    // Held open so the master never sees a hang-up while no client is connected; and so the
    // raw mode set here persists between clients. `None` once released
    // ([`Pty::release_slave`]).
    slave: Option<OwnedFd>,
    path: PathBuf,
}

impl Pty {
    /// Opens a new pair in raw mode.
    pub fn open() -> io::Result<Self> {
        // SAFETY: standard posix_openpt/grantpt/unlockpt/ptsname_r sequence; every returned
        // descriptor is owned immediately.
        unsafe {
            let m = cvt(libc::posix_openpt(
                libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC,
            ))?;
            let master = OwnedFd::from_raw_fd(m);
            cvt(libc::grantpt(m))?;
            cvt(libc::unlockpt(m))?;
            let mut name = [0 as libc::c_char; 128];
            let rc = libc::ptsname_r(m, name.as_mut_ptr(), name.len());
            if rc != 0 {
                return Err(io::Error::from_raw_os_error(rc));
            }
            let c_name = std::ffi::CStr::from_ptr(name.as_ptr());
            let path = PathBuf::from(c_name.to_string_lossy().into_owned());
            let s = cvt(libc::open(
                c_name.as_ptr(),
                libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC,
            ))?;
            let slave = OwnedFd::from_raw_fd(s);
            make_raw(s, Some(libc::B115200))?;
            set_nonblocking(m)?;
            Ok(Self {
                master: Fd::new(master),
                slave: Some(slave),
                path,
            })
        }
    }

    /// The master side's byte stream.
    pub fn io(&self) -> &Fd {
        &self.master
    }

    /// The slave device path (what `rip-rt run --port` opens).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Lets go of the emulator's own hold on the slave side, once a client has it open: from
    /// then on the master sees a hang-up ([`Fd::wait_readable`] and [`Fd::read_available`]
    /// fail with `BrokenPipe`) whenever no client holds the slave, so that the emulator
    /// learns that its host has gone from the host's close, not by guessing from silence.
    pub fn release_slave(&mut self) {
        self.slave = None;
    }

    /// Whether [`release_slave`](Self::release_slave) was called.
    pub fn slave_released(&self) -> bool {
        self.slave.is_none()
    }
}

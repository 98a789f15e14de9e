//! The CSV log of a run (columns in `docs/rip-rt.md`), written by its own thread.
//!
//! The loop hands each row over a bounded channel ([`LogWriter::push`], no allocation, no
//! system call) and never waits on the file system. The writer thread formats the rows and
//! writes them out as soon as the channel runs empty, so a failing write (a full disk, EFBIG
//! past the file-size limit) is seen by the loop at its next period as a log fault, which
//! stops the run. The header is written and flushed by [`LogWriter::create`], before the
//! motor is ever enabled, so a log that cannot be written at all is a start-up error.

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use crate::step::StepOutput;

/// Largest state estimate a row carries.
pub const MAX_ESTIMATES: usize = 32;

/// Rows the loop may be ahead of the writer (5 s at 100 Hz) before that is a log fault.
pub const QUEUE_ROWS: usize = 512;
/// How long a [`waiting`](LogWriter::waiting) push waits for room before the writer counts as
/// fallen behind: a lockstep run outpaces any writer, but storage that accepts nothing for
/// this long has stalled, and a stop must not wait on it forever.
pub const WAIT_FOR_ROOM: std::time::Duration = std::time::Duration::from_secs(5);

/// Why a row did not go into the queue.
enum Unsent {
    Full,
    Disconnected,
}

/// `row` into the queue at once.
fn send_now(tx: &SyncSender<Row>, row: Row) -> Result<(), Unsent> {
    tx.try_send(row).map_err(|e| match e {
        TrySendError::Full(_) => Unsent::Full,
        TrySendError::Disconnected(_) => Unsent::Disconnected,
    })
}

/// `row` into the queue, waiting up to [`WAIT_FOR_ROOM`] for room (a stop requested meanwhile
/// is seen by the loop when the push returns, at most that long after).
fn send_waiting(tx: &SyncSender<Row>, mut row: Row) -> Result<(), Unsent> {
    let deadline = std::time::Instant::now() + WAIT_FOR_ROOM;
    loop {
        match tx.try_send(row) {
            Ok(()) => return Ok(()),
            Err(TrySendError::Disconnected(_)) => return Err(Unsent::Disconnected),
            Err(TrySendError::Full(back)) => {
                if std::time::Instant::now() >= deadline {
                    return Err(Unsent::Full);
                }
                row = back;
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
        }
    }
}

/// How long [`LogWriter::finish`] waits for the writer to drain the queue. The loop has
/// stopped the motor by then; what is left is to exit, and a write blocked on stalled storage
/// (a pipe nobody reads, a hung network mount) must not hold the process forever, where no
/// signal but SIGKILL could end it.
pub const FINISH_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// A log that cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The file could not be created, or the header not written and flushed.
    #[error("--log {}: {source}", path.display())]
    Create {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: io::Error,
    },
    /// The controller's state estimate is longer than a row can carry.
    #[error(
        "the controller's state estimate has {0} entries; the log holds at most {MAX_ESTIMATES}"
    )]
    TooManyEstimates(usize),
    /// A write failed while running or at the end.
    #[error("writing {} failed: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: io::Error,
    },
    /// The writer fell this many rows behind: the storage stalled.
    #[error("the log writer fell {0} rows behind (the storage stalled)")]
    Behind(usize),
    /// The writer thread is gone without reporting an error.
    #[error("the log writer thread stopped")]
    WriterGone,
    /// The writer did not drain its queue within [`FINISH_WAIT`] at the end of the run.
    #[error("writing {} did not complete within {} s (the storage stalled)", path.display(), FINISH_WAIT.as_secs())]
    Stalled {
        /// The file.
        path: PathBuf,
    },
}

/// One period's row.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    /// Seconds since balancing started.
    pub t: f64,
    /// Sequence number of the sample request.
    pub seq: u16,
    /// What the step produced (or the repeated previous step, for a period without reply).
    pub step: StepOutput,
    /// The state estimate (the first `n_estimates` entries), `None` in rows without one.
    pub estimate: Option<[f64; MAX_ESTIMATES]>,
    /// Compute time (µs).
    pub compute_us: f64,
    /// Wake-up lateness (µs).
    pub jitter_us: f64,
    /// The `phase` column: the controller's phase after the step ([`rip_core::Phase::name`])
    /// in `rip-rt run`, the experiment's stage in `rip-rt excite` (`sign_check`, `chirp`,
    /// `kick`, `coast`, ...).
    pub phase: &'static str,
}

impl Row {
    /// Copies `estimate` (at most [`MAX_ESTIMATES`] entries) into a row.
    pub fn estimate_from(estimate: Option<&[f64]>) -> Option<[f64; MAX_ESTIMATES]> {
        estimate.map(|x| {
            let mut a = [0.0; MAX_ESTIMATES];
            let n = x.len().min(MAX_ESTIMATES);
            a[..n].copy_from_slice(&x[..n]);
            a
        })
    }
}

struct Shared {
    failed: AtomicBool,
    error: Mutex<Option<io::Error>>,
}

/// The log: a header written at creation, rows written by a background thread, a footer at
/// [`finish`](LogWriter::finish).
pub struct LogWriter {
    path: PathBuf,
    tx: Option<SyncSender<Row>>,
    thread: Option<JoinHandle<BufWriter<File>>>,
    shared: Arc<Shared>,
    /// Wait for room in the queue instead of faulting ([`LogWriter::waiting`]).
    wait: bool,
}

impl std::fmt::Debug for LogWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogWriter")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

fn write_row(out: &mut impl Write, row: &Row, n_estimates: usize) -> io::Result<()> {
    let s = &row.step;
    write!(
        out,
        "{:.4},{},{:.6},{:.6},{:.6},{:.4}",
        row.t, row.seq, s.theta, s.alpha, s.reference, s.voltage
    )?;
    for i in 0..n_estimates {
        match &row.estimate {
            Some(x) => write!(out, ",{:.6}", x[i])?,
            None => write!(out, ",")?,
        }
    }
    writeln!(
        out,
        ",{:.1},{:.1},{},{}",
        row.compute_us, row.jitter_us, s.flags, row.phase
    )
}

fn writer_thread(
    mut out: BufWriter<File>,
    rx: Receiver<Row>,
    n_estimates: usize,
    shared: Arc<Shared>,
) -> BufWriter<File> {
    let write = |row: &Row, out: &mut BufWriter<File>| write_row(out, row, n_estimates);
    while let Ok(row) = rx.recv() {
        let mut result = write(&row, &mut out);
        while result.is_ok() {
            match rx.try_recv() {
                Ok(row) => result = write(&row, &mut out),
                Err(_) => break,
            }
        }
        // Out as soon as the loop has nothing more queued: a failing disk shows within a
        // period, and a crash loses at most the rows of one burst.
        let result = result.and_then(|()| out.flush());
        if let Err(e) = result {
            *shared.error.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
            shared.failed.store(true, Ordering::Release);
            break;
        }
    }
    out
}

/// Creates (truncates) `path` for writing without blocking in `open`: a FIFO nobody reads
/// would otherwise hold the start-up there, port already taken, where the stop signals
/// (handled, and restarting the call) cannot end it. Such a FIFO is refused (ENXIO); the
/// descriptor is made blocking again for the writer thread.
fn open_for_writing(path: &Path) -> io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    use std::os::unix::io::AsRawFd;
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| match e.raw_os_error() {
            Some(libc::ENXIO) => io::Error::new(e.kind(), format!("{e}: a FIFO nobody reads")),
            _ => e,
        })?;
    let fd = file.as_raw_fd();
    // SAFETY: plain fcntl calls on a descriptor this function owns.
    let rc = unsafe {
        let flags = libc::fcntl(fd, libc::F_GETFL);
        if flags < 0 {
            flags
        } else {
            libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK)
        }
    };
    if rc < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(file)
}

impl LogWriter {
    /// Creates `path`, writes the header (comment lines `# key: value`, then the columns),
    /// flushes it and starts the writer thread. Any failure here is a start-up error.
    pub fn create(
        path: &Path,
        header: &[(&str, String)],
        n_estimates: usize,
    ) -> Result<Self, LogError> {
        if n_estimates > MAX_ESTIMATES {
            return Err(LogError::TooManyEstimates(n_estimates));
        }
        let create_err = |source| LogError::Create {
            path: path.to_path_buf(),
            source,
        };
        let file = open_for_writing(path).map_err(create_err)?;
        let mut out = BufWriter::with_capacity(1 << 16, file);
        let mut header = || -> io::Result<()> {
            for (k, v) in header {
                writeln!(out, "# {k}: {v}")?;
            }
            write!(out, "t,seq,theta,alpha,theta_ref,u")?;
            for i in 0..n_estimates {
                write!(out, ",xhat_{i}")?;
            }
            writeln!(out, ",compute_us,jitter_us,status,phase")?;
            out.flush()
        };
        header().map_err(create_err)?;
        let shared = Arc::new(Shared {
            failed: AtomicBool::new(false),
            error: Mutex::new(None),
        });
        let (tx, rx) = mpsc::sync_channel(QUEUE_ROWS);
        let thread_shared = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("rip-rt-log".into())
            .spawn(move || writer_thread(out, rx, n_estimates, thread_shared))
            .map_err(create_err)?;
        Ok(Self {
            path: path.to_path_buf(),
            tx: Some(tx),
            thread: Some(thread),
            shared,
            wait: false,
        })
    }

    fn write_error(&self) -> LogError {
        let source = self
            .shared
            .error
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
            .unwrap_or_else(|| io::Error::other("reported before"));
        LogError::Write {
            path: self.path.clone(),
            source,
        }
    }

    /// Whether the writer has failed: the fault, once (later calls see the row queue
    /// disconnected).
    pub fn check(&self) -> Result<(), LogError> {
        if self.shared.failed.load(Ordering::Acquire) {
            return Err(self.write_error());
        }
        Ok(())
    }

    /// The writer with [`push`](Self::push) waiting for room in the queue when `wait`, as a
    /// lockstep run needs: it has no deadline, and it outpaces the writer on a loaded machine
    /// (a full queue there is the loop running ahead, not the storage stalling).
    pub fn waiting(mut self, wait: bool) -> Self {
        self.wait = wait;
        self
    }

    /// Queues one row; an error is a log fault (the writer failed or fell behind). Allocation
    /// free, and system-call free unless [`waiting`](Self::waiting) finds the queue full.
    pub fn push(&mut self, row: Row) -> Result<(), LogError> {
        self.check()?;
        let Some(tx) = &self.tx else {
            return Err(LogError::WriterGone);
        };
        let sent = if self.wait {
            send_waiting(tx, row)
        } else {
            send_now(tx, row)
        };
        match sent {
            Ok(()) => Ok(()),
            Err(Unsent::Full) => Err(LogError::Behind(QUEUE_ROWS)),
            Err(Unsent::Disconnected) => Err(if self.shared.failed.load(Ordering::Acquire) {
                self.write_error()
            } else {
                LogError::WriterGone
            }),
        }
    }

    /// Waits for the queued rows, writes the footer comment lines and flushes. After a write
    /// failure the footer is not attempted and the failure is returned (once more, if the
    /// loop already reported it, as [`LogError::Write`] with "reported before").
    pub fn finish(&mut self, footer: &[(&str, String)]) -> Result<(), LogError> {
        self.tx = None;
        let Some(thread) = self.thread.take() else {
            return Err(LogError::WriterGone);
        };
        let waited = std::time::Instant::now();
        while !thread.is_finished() {
            if waited.elapsed() >= FINISH_WAIT {
                // The thread stays blocked in its write; the process exits without it.
                return Err(LogError::Stalled {
                    path: self.path.clone(),
                });
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let mut out = thread.join().map_err(|_| LogError::WriterGone)?;
        self.check()?;
        let mut write = || -> io::Result<()> {
            for (k, v) in footer {
                writeln!(out, "# {k}: {v}")?;
            }
            out.flush()
        };
        write().map_err(|source| LogError::Write {
            path: self.path.clone(),
            source,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(t: f64) -> Row {
        Row {
            t,
            seq: 7,
            step: StepOutput {
                theta: 0.5,
                alpha: -0.25,
                reference: 1.0,
                voltage: 3.0,
                flags: 1,
                len: 0,
                phase: rip_core::Phase::SwingUp,
            },
            estimate: Row::estimate_from(Some(&[1.0, 2.0])),
            compute_us: 3.5,
            jitter_us: 12.0,
            phase: "swing_up",
        }
    }

    #[test]
    fn header_rows_and_footer_land_in_order() {
        let path = std::env::temp_dir().join(format!("rip-rt-log-{}.csv", std::process::id()));
        let mut log = LogWriter::create(&path, &[("controller", "lqr".into())], 2).unwrap();
        for k in 0..100 {
            log.push(row(k as f64 * 0.01)).unwrap();
        }
        log.finish(&[("stop", "finished".into())]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "# controller: lqr");
        assert_eq!(
            lines[1],
            "t,seq,theta,alpha,theta_ref,u,xhat_0,xhat_1,compute_us,jitter_us,status,phase"
        );
        assert_eq!(
            lines[2],
            "0.0000,7,0.500000,-0.250000,1.000000,3.0000,1.000000,2.000000,3.5,12.0,1,swing_up"
        );
        assert_eq!(lines.len(), 2 + 100 + 1);
        assert_eq!(lines[102], "# stop: finished");
        std::fs::remove_file(&path).unwrap();
    }

    /// A FIFO at `name` with a reader that opens it and never reads: storage that hangs
    /// once the pipe's buffer is full.
    fn hung_storage(name: &str) -> (PathBuf, File) {
        let path = std::env::temp_dir().join(format!("rip-rt-{name}-{}.fifo", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
        // SAFETY: a valid, NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        use std::os::unix::fs::OpenOptionsExt;
        // Non-blocking: a FIFO's reader would otherwise wait for its writer to open it.
        let reader = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&path)
            .unwrap();
        (path, reader)
    }

    /// A lockstep run waits for its writer rather than faulting on a full queue, since it
    /// outpaces any writer; storage that takes nothing still ends it, after
    /// [`WAIT_FOR_ROOM`], as a writer fallen behind, so a stop never waits on it forever.
    #[test]
    fn a_waiting_writer_waits_for_room_but_not_for_hung_storage() {
        let (path, _reader) = hung_storage("hung");
        let mut log = LogWriter::create(&path, &[("a", "b".into())], 2)
            .unwrap()
            .waiting(true);
        let start = std::time::Instant::now();
        let mut pushed = 0usize;
        let err = loop {
            match log.push(row(pushed as f64)) {
                Ok(()) => pushed += 1,
                Err(e) => break e,
            }
            assert!(
                start.elapsed() < WAIT_FOR_ROOM * 3,
                "the push never gave up"
            );
        };
        assert!(matches!(err, LogError::Behind(QUEUE_ROWS)), "{err}");
        // The pipe's buffer and the queue filled first; then one push waited its full time.
        assert!(pushed > QUEUE_ROWS, "{pushed} rows");
        assert!(start.elapsed() >= WAIT_FOR_ROOM, "{:?}", start.elapsed());
        drop(log);
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn an_unwritable_log_fails_at_creation() {
        // /dev/full accepts open() and fails every write: the header flush must find it.
        let e = LogWriter::create(Path::new("/dev/full"), &[("a", "b".into())], 0).unwrap_err();
        assert!(matches!(e, LogError::Create { .. }), "{e}");
        assert!(e.to_string().contains("/dev/full"), "{e}");
    }
}

//! Long native work that Ctrl-C can stop.
//!
//! Python runs signal handlers only on its main thread, between bytecodes; while a native call
//! holds that thread the handler waits, so a long simulation would ignore Ctrl-C until it ended.
//! [`interruptible`] runs the work on a worker thread and lets the calling thread wait with the
//! GIL released, waking every [`POLL`] to run pending signal handlers
//! (`Python::check_signals`). If one raises (`KeyboardInterrupt`), the worker's cancel flag is
//! set, the worker stops within one control sample (`rip_core::sim` checks the flag every
//! sample, the batches before every run), and the exception propagates.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, RecvTimeoutError};
use std::time::Duration;

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;

/// How often the waiting thread checks for signals (and reports progress).
pub const POLL: Duration = Duration::from_millis(50);

/// Runs `work(cancel)` on a worker thread while the caller waits, interruptibly.
///
/// `poll` runs on the calling thread with the GIL held after each [`POLL`] without a result
/// (e.g. to report progress); an error from it cancels the work like a signal does.
pub fn interruptible<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(&AtomicBool) -> T + Send,
    mut poll: impl FnMut(Python<'_>) -> PyResult<()>,
) -> PyResult<T> {
    let cancel = AtomicBool::new(false);
    let (tx, rx) = channel();
    std::thread::scope(|s| {
        let cancel = &cancel;
        let worker = s.spawn(move || {
            // Ignore a send error: the caller has stopped waiting and drops the result anyway.
            let _ = tx.send(work(cancel));
        });
        let mut failure: Option<PyErr> = None;
        // `Receiver` is not `Sync`, so it moves in and out of each GIL-free wait.
        let mut rx = Some(rx);
        let mut wait = |timeout: Option<Duration>| {
            let r = rx.take().expect("receiver present");
            let (got, r) = py.allow_threads(move || {
                let got = match timeout {
                    Some(t) => r.recv_timeout(t),
                    None => r.recv().map_err(|_| RecvTimeoutError::Disconnected),
                };
                (got, r)
            });
            rx = Some(r);
            got
        };
        let result = loop {
            match wait(Some(POLL)) {
                Ok(value) => break Some(value),
                Err(RecvTimeoutError::Disconnected) => break None,
                Err(RecvTimeoutError::Timeout) => {}
            }
            if let Err(err) = py.check_signals().and_then(|()| poll(py)) {
                cancel.store(true, Ordering::Relaxed);
                failure = Some(err);
                // The worker sees the flag within a control sample; its result is discarded.
                let _ = wait(None);
                break None;
            }
        };
        let joined = py.allow_threads(|| worker.join());
        match (failure, result, joined) {
            (Some(err), _, _) => Err(err),
            (None, Some(value), Ok(())) => Ok(value),
            _ => Err(PyRuntimeError::new_err(
                "internal error: the native worker thread panicked",
            )),
        }
    })
}

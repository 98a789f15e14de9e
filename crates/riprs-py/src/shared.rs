//! A controller that several Python threads may use at once.
//!
//! Controller methods release the GIL while they compute (an MPC step can take a long time), so
//! another Python thread can call into the same object meanwhile. With PyO3's own borrow flag
//! that second call fails ("Already mutably borrowed"), or panics where the borrow is taken
//! with `borrow()`. The pyclasses are therefore `frozen` and keep their Rust value in
//! [`Shared`]: calls queue on a mutex and run one after the other, each seeing a consistent
//! controller.
//!
//! Deadlock rule: a thread never waits for the mutex while holding the GIL. [`Shared::lock`]
//! takes it immediately if it is free and otherwise waits with the GIL released, so the holder
//! (which may need the GIL to return its result) can always finish.

use std::sync::{Mutex, MutexGuard, PoisonError};

use pyo3::prelude::*;

/// A value behind a mutex that is locked without ever blocking while holding the GIL.
pub struct Shared<T>(Mutex<T>);

impl<T: Send> Shared<T> {
    pub fn new(value: T) -> Self {
        Self(Mutex::new(value))
    }

    /// Exclusive access. Taken at once if free; otherwise waits with the GIL released.
    pub fn lock(&self, py: Python<'_>) -> MutexGuard<'_, T> {
        loop {
            match self.0.try_lock() {
                Ok(guard) => return guard,
                // A panic inside a core routine would already have reached Python as an
                // exception; the value itself is still a valid controller.
                Err(std::sync::TryLockError::Poisoned(p)) => return p.into_inner(),
                Err(std::sync::TryLockError::WouldBlock) => {
                    // Wait until the holder is done, then try again with the GIL held, so the
                    // guard is taken on this (GIL-holding) side.
                    py.allow_threads(|| {
                        drop(self.0.lock().unwrap_or_else(PoisonError::into_inner))
                    });
                }
            }
        }
    }
}

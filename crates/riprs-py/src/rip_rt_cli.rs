//! `rip-rt` as the Python package's console script: [`rip_rt::cli::run`] in-process, so that
//! `pip install` puts a working `rip-rt` on the PATH (one wheel cannot also hold a cargo
//! binary). `riprs._rip_rt.main` hands over `sys.argv` and exits with the code.

use std::ffi::OsString;
use std::panic::{catch_unwind, AssertUnwindSafe};

use pyo3::prelude::*;

/// Rust's exit code for a panic, as the `rip-rt` binary would end with.
const PANIC_EXIT: u8 = rip_rt::stop::exit_code::PANIC as u8;

/// Runs the `rip-rt` command line `argv` (program name first) and returns its exit code.
///
/// The GIL is released for the whole run: the loop must not wait on Python, and rip-rt installs
/// its own signal handlers, so the caller resets Python's SIGINT handler first. A panic, after
/// its hook has stopped the motor, returns 101 as the binary's exit would.
#[pyfunction]
fn rip_rt_main(py: Python<'_>, argv: Vec<OsString>) -> u8 {
    py.allow_threads(move || {
        catch_unwind(AssertUnwindSafe(|| rip_rt::cli::run(argv))).unwrap_or(PANIC_EXIT)
    })
}

/// One field of the live frame: name, `struct` code, element count, what it holds.
type LiveField = (&'static str, String, usize, &'static str);

/// The live stream's datagram layout, rip-rt's one definition of it (``docs/live.md``).
///
/// Returns
/// -------
/// fields : list of (str, str, int, str)
///     Each field in wire order: its name, its Python ``struct`` code (one element), its
///     element count and what it holds.
/// format : str
///     The whole datagram's ``struct`` format (little-endian, no padding).
/// version : int
///     The layout's version, the frame's second field.
#[pyfunction]
fn live_frame_layout() -> (Vec<LiveField>, String, u16) {
    let fields = rip_rt::live::FIELDS
        .iter()
        .map(|f| (f.name, f.ty.struct_code(1), f.count, f.doc))
        .collect();
    (fields, rip_rt::live::struct_format(), rip_rt::live::VERSION)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(rip_rt_main, m)?)?;
    m.add_function(wrap_pyfunction!(live_frame_layout, m)?)
}

//! `riprs._riprs`: the private native module behind the `riprs` Python package.
//!
//! This crate only converts: numpy arrays to `nalgebra` matrices and back, and
//! [`RipError`](rip_core::RipError)
//! variants to Python exceptions. All numerics live in `rip-core`.

use pyo3::prelude::*;

mod control;
mod convert;
mod design;
mod envs;
mod errors;
mod excitation;
mod identify;
mod interrupt;
mod mpc;
mod paper;
mod plant;
mod rig;
mod rip_rt_cli;
mod shared;
mod sim;
mod spec;
mod stats;
mod swingup;
mod tune;

#[pymodule]
fn _riprs(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    design::register(m)?;
    paper::register(m)?;
    plant::register(m)?;
    control::register(m)?;
    sim::register(m)?;
    mpc::register(m)?;
    spec::register(m)?;
    swingup::register(m)?;
    stats::register(m)?;
    excitation::register(m)?;
    identify::register(m)?;
    rip_rt_cli::register(m)?;
    rig::register(m)?;
    envs::register(m)?;
    tune::register(m)?;
    Ok(())
}

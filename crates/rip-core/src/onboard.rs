//! The designs rip-control runs: rip-core makes the design (DARE, Kalman design, condensing)
//! and fills a [`rip_control::Design`], the one description of a controller that the host's
//! controllers, `rip-rt` and the firmware all step with the same code.
//!
//! [`Lqr::control_design`](crate::regulators::Lqr::control_design),
//! [`Lqg::control_design`](crate::regulators::Lqg::control_design) and
//! [`Mpc::control_design`](crate::mpc::Mpc::control_design) give a controller's design;
//! [`with_compensation`] adds a compensation law to one.

pub use rip_control::{
    Controller as ControlStep, Design as ControlDesign, DesignError, Kind as ControlKind,
};

use crate::compensation::Compensation;
use crate::error::{Result, RipError};
use crate::linalg::Mat;

/// Copies `m` row-major into `dst`, naming `name` when it exceeds the capacity `cap_rows ×
/// cap_cols`.
pub(crate) fn put(
    name: &str,
    dst: &mut [f64],
    m: &Mat,
    cap_rows: usize,
    cap_cols: usize,
) -> Result<()> {
    if m.nrows() > cap_rows || m.ncols() > cap_cols || m.nrows() * m.ncols() > dst.len() {
        return Err(RipError::invalid(
            name,
            format!(
                "{}×{} exceeds the onboard capacity {cap_rows}×{cap_cols}",
                m.nrows(),
                m.ncols()
            ),
        ));
    }
    let cols = m.ncols();
    for i in 0..m.nrows() {
        for j in 0..cols {
            dst[i * cols + j] = m[(i, j)];
        }
    }
    Ok(())
}

/// `design` with `law` compensating every written voltage (its bounds become the design's
/// input bounds; the controller plans inside them by the law's margin).
pub fn with_compensation(mut design: ControlDesign, law: &Compensation) -> ControlDesign {
    let (vs, ws) = law.scales();
    design.compensation = rip_control::CompensationDesign {
        dead_zone: law.dead_zone(),
        friction_voltage: law.friction_voltage(),
        voltage_scale: vs,
        velocity_scale: ws,
    };
    let (lo, hi) = law.bounds();
    design.input_bounds = [lo, hi];
    design
}

/// The error of a design rip-control refuses, as a [`RipError`] naming its field.
pub(crate) fn refused(e: DesignError) -> RipError {
    let name = match e {
        DesignError::BadSize(n) | DesignError::BadValue(n) => n,
        _ => "design",
    };
    RipError::invalid(
        name,
        format!("the onboard controller refuses the design: {e}"),
    )
}

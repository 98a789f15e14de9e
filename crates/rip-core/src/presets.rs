//! The paper's regulators as the experiment file's default assembles them ([`Lqr::paper`],
//! [`Lqg::paper`]), and a spec error as a [`RipError`].
//!
//! They live here, not beside the regulators, because the assembly ([`crate::spec`]) builds
//! the regulators: a regulator that called up into the spec would close an import cycle.

use crate::error::{Result, RipError};
use crate::paper;
use crate::regulators::{Lqg, Lqr};
use crate::spec::{Design, Spec, SpecError};

/// A spec error as the [`RipError`] of the key it names.
impl From<SpecError> for RipError {
    fn from(e: SpecError) -> Self {
        RipError::invalid(e.key, e.reason)
    }
}

/// The default spec's design at the paper's sample time.
fn paper_design() -> Result<Design> {
    Ok(Spec::default().design(paper::TS)?)
}

impl Lqr {
    /// The paper's LQR: the controller assembly ([`crate::spec`]) applied to the default
    /// spec, i.e. eq. (13) weights on [`paper::discrete_model`], `Ts = 0.01 s`, default rate
    /// filter and ±12 V.
    pub fn paper() -> Result<Self> {
        Ok(paper_design()?.lqr()?)
    }
}

impl Lqg {
    /// The paper's LQG: the controller assembly ([`crate::spec`]) applied to the default
    /// spec, i.e. the eq. (13) gain on [`paper::discrete_model`] and the Kalman filter of
    /// eq. (11) on the augmented model of eq. (3). The estimator predicts with the unscaled
    /// `B_u = [B_d; 0]` (the `L_su` scaling of [`paper::augmented_model`] belongs to the noise
    /// model only).
    pub fn paper() -> Result<Self> {
        Ok(paper_design()?.lqg()?)
    }
}

//! One period's response of the arm to the voltage (the module docs of [`super`], "The sign
//! statistic"): what the sign statistic and the reversed observers name a trip by.

/// The measured change of the arm's mean rate between the last two intervals beyond the
/// model's at 0 V (`beyond`, rad/s), the voltage's part of the model's (`push`, rad/s), the
/// variance of the measured change (`var`) and the period's length (`dt`, s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Response {
    pub(super) push: f64,
    pub(super) beyond: f64,
    pub(super) var: f64,
    pub(super) dt: f64,
}

/// The voltage's gain relative to the model's that a weighted regression's sums
/// `[Σ push·beyond/var, Σ push²/var]` show, and its standard error; `None` without a
/// response.
pub(super) fn gain(regression: &[f64; 2]) -> Option<(f64, f64)> {
    let [cross, weight] = *regression;
    (weight > 0.0).then(|| (cross / weight, 1.0 / weight.sqrt()))
}

impl Response {
    /// Adds the sample to the weighted regression of `beyond` on `push` (`regression`: the
    /// sums `Σ push·beyond/var` and `Σ push²/var`, whose ratio is the voltage's gain relative
    /// to the model's).
    pub(super) fn regress(&self, regression: &mut [f64; 2]) {
        regression[0] += self.push * self.beyond / self.var;
        regression[1] += self.push * self.push / self.var;
    }

    /// Adds the sample to the rate and displacement the voltage must have added to the motion
    /// at 0 V (`expected`) and those measured beyond it (`measured`).
    pub(super) fn displace(&self, expected: &mut [f64; 2], measured: &mut [f64; 2]) {
        expected[0] += self.push;
        expected[1] += expected[0] * self.dt;
        measured[0] += self.beyond;
        measured[1] += measured[0] * self.dt;
    }
}

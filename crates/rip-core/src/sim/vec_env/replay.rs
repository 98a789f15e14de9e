//! The sim-to-real check: a logged run replayed through a plant.

use crate::error::{Result, RipError};
use crate::plant::{Plant, State};

/// The fit of a replayed log (sim-to-real check).
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayFit {
    /// The simulated angles `[θ, α]` at each logged sample.
    pub y: Vec<[f64; 2]>,
    /// Normalised RMSE of each output, `‖y − ŷ‖ / ‖y − mean(y)‖`: 0 is a perfect fit, 1 no
    /// better than the mean (MATLAB's `goodnessOfFit` NRMSE; `riprs identify`'s fit % is
    /// `100 (1 − NRMSE)`).
    pub nrmse: [f64; 2],
}

/// Replays logged voltages through `plant` from the logged start and compares the angles.
///
/// `y` are the measured angles at `t_k = k ts`, `u[k]` the voltage held over `[t_k, t_{k+1}]`.
/// The start is `[y₀, (y₁ − y₀)/ts]` per joint; the simulated angles are the plant's true
/// ones (no sensor model: the log already holds the rig's). A simulation that diverges is an
/// error.
pub fn replay(
    plant: &Plant,
    y: &[[f64; 2]],
    u: &[f64],
    ts: f64,
    substeps: usize,
) -> Result<ReplayFit> {
    if y.len() < 2 || u.len() != y.len() {
        return Err(RipError::Shape {
            name: "log".into(),
            expected: "at least 2 samples, as many voltages as angles".into(),
            rows: y.len(),
            cols: u.len(),
        });
    }
    if y.iter().flatten().any(|v| !v.is_finite()) {
        return Err(RipError::NonFinite { name: "y".into() });
    }
    let x0 = State::new(
        y[0][0],
        (y[1][0] - y[0][0]) / ts,
        y[0][1],
        (y[1][1] - y[0][1]) / ts,
    );
    let traj = plant.integrate(&x0, &u[..u.len() - 1], ts, substeps)?;
    let sim: Vec<[f64; 2]> = traj.iter().map(|x| [x[0], x[2]]).collect();
    let nrmse = std::array::from_fn(|j| {
        let n = y.len() as f64;
        let mean = y.iter().map(|v| v[j]).sum::<f64>() / n;
        let dev: f64 = y.iter().map(|v| (v[j] - mean).powi(2)).sum();
        let err: f64 = y.iter().zip(&sim).map(|(a, b)| (a[j] - b[j]).powi(2)).sum();
        (err / dev).sqrt()
    });
    Ok(ReplayFit { y: sim, nrmse })
}

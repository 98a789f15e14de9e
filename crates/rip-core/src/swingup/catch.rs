//! The predicted catch's design: the reference LQR and the rooms the `no_std` supervisor's
//! prediction checks ([`rip_control::swing::CatchPrediction`], the law's docs, "Predicted
//! catch").

use rip_control::swing::CatchPrediction;

use crate::envelope::stopping_model;
use crate::linalg::c2d;
use crate::lqr::dlqr;
use crate::plant::Plant;

use super::settings::SwingUpSettings;

/// RK4 substeps per sample of the prediction.
const SUBSTEPS: u32 = 2;

/// The prediction for `plant` (the nominal model) and `s`; `None` when it is off
/// (`catch_prediction = 0`) or the reference LQR cannot be designed on `plant`.
pub(crate) fn prediction(plant: &Plant, s: &SwingUpSettings, ts: f64) -> Option<CatchPrediction> {
    if s.catch_prediction <= 0.0 {
        return None;
    }
    let smooth = plant.smooth().ok()?;
    let (a, b) = smooth.linearize_upright();
    let (ad, bd) = c2d(&a, &b, ts).ok()?;
    // The reference LQR is the paper's, eq. (13): the `[lqr]` section's default.
    let (q, r) = crate::paper::lqr_weights();
    let design = dlqr(&ad, &bd, &q, &r, None).ok()?;
    let steps = u32::try_from((s.catch_prediction / ts).ceil() as u64).ok()?;
    Some(CatchPrediction {
        k: std::array::from_fn(|i| design.k[(0, i)]),
        steps,
        substeps: SUBSTEPS,
        arm_room: s.arm_limit - s.catch_margin,
        pendulum_room: s.balance_angle - s.catch_margin,
        stopping: stopping_model(smooth.params(), s.max_voltage, 1.0, ts),
    })
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::Mat;
    use crate::paper::TS;
    use crate::plant::State;
    use rip_control::swing::ArmModel;

    /// The prediction with the model and bound the supervisor runs it with.
    struct Predictor {
        k: [f64; 4],
        prediction: CatchPrediction,
        model: ArmModel,
        u_max: f64,
    }

    impl Predictor {
        fn recoverable(&self, x: &State, theta_ref: f64) -> bool {
            let x = [x[0], x[1], x[2], x[3]];
            self.prediction
                .recoverable(&self.model, TS, self.u_max, &x, theta_ref)
        }
    }

    fn predictor(plant: &Plant, margin: f64) -> Predictor {
        let s = SwingUpSettings {
            catch_prediction: 1.0,
            catch_margin: margin,
            ..SwingUpSettings::default()
        };
        let prediction = super::prediction(plant, &s, TS).unwrap();
        Predictor {
            k: prediction.k,
            prediction,
            model: plant.arm_model(),
            u_max: s.max_voltage,
        }
    }

    #[test]
    fn off_by_default() {
        let s = SwingUpSettings::default();
        assert!(super::prediction(&Plant::paper(), &s, TS).is_none());
    }

    #[test]
    fn the_reference_gain_stabilises_the_discrete_upright_model() {
        for plant in [Plant::paper(), Plant::qube_servo2()] {
            let p = predictor(&plant, 0.2);
            let (a, b) = plant.linearize_upright();
            let (ad, bd) = c2d(&a, &b, TS).unwrap();
            let k = Mat::from_row_slice(1, 4, &p.k);
            let closed = &ad - &bd * &k;
            let radius = crate::linalg::eigenvalues(&closed)
                .iter()
                .map(|e| e.norm())
                .fold(0.0f64, f64::max);
            assert!(radius < 1.0, "spectral radius {radius}");
        }
    }

    #[test]
    fn obvious_catches_and_losses() {
        for plant in [Plant::paper(), Plant::qube_servo2()] {
            let p = predictor(&plant, 0.2);
            // Upright at rest, anywhere in the middle of the travel: kept.
            assert!(p.recoverable(&State::new(0.0, 0.0, 0.0, 0.0), 0.0));
            assert!(p.recoverable(&State::new(0.5, 0.0, 0.05, 0.0), 0.5));
            // The arm near its limit still turning towards it: its stopping point is beyond.
            assert!(!p.recoverable(&State::new(1.2, 4.0, 0.0, 0.0), 1.2));
            // The pendulum at the catch angle falling away fast: lost.
            assert!(!p.recoverable(&State::new(0.0, 0.0, 0.3, 8.0), 0.0));
        }
    }

    #[test]
    fn a_larger_margin_accepts_fewer_states() {
        let plant = Plant::qube_servo2();
        let (tight, loose) = (predictor(&plant, 0.35), predictor(&plant, 0.1));
        let (mut n_tight, mut n_loose) = (0, 0);
        for i in 0..15 {
            for j in 0..15 {
                let theta = -1.2 + 0.17 * f64::from(i);
                let rate = -5.0 + 0.7 * f64::from(j);
                let x = State::new(theta, rate, 0.2, -2.0);
                let (a, b) = (tight.recoverable(&x, theta), loose.recoverable(&x, theta));
                assert!(!a || b, "kept by the larger margin only at {x:?}");
                n_tight += usize::from(a);
                n_loose += usize::from(b);
            }
        }
        assert!(n_tight < n_loose, "{n_tight} vs {n_loose}");
    }
}

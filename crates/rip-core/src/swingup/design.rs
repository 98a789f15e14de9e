//! The swing-up's design: the constants of the law, the catch and the balance region,
//! computed once from the nominal plant and the settings and handed to the `no_std`
//! supervisor ([`rip_control::swing`], where each is derived).

use rip_control::swing::{self as control, SwingParams, UnstableMode};

use crate::envelope::{envelope_speed, stopping_model};
use crate::plant::Plant;

use super::catch::prediction;
use super::settings::{OnFall, SwingUpSettings};

/// Least distance (rad) inside `swing_up.arm_limit` at which the swing's braking envelope
/// ends (not the stop's, `preflight::motion::ENVELOPE_MARGIN`, inside `safety.arm_limit`):
/// the continuous-time argument of the law's docs holds for the nominal model, while the loop
/// samples every `Ts` and the rig differs from the model by some percent. The envelope ends
/// one period at its top speed `√(2 a_b θ_L)` inside the limit, and at least this far.
const SWING_ENVELOPE_MARGIN: f64 = 0.05;

/// The supervisor's parameters for `plant` (the nominal model), `s` and the period `ts`;
/// `None` when the model has no real unstable mode about upright to catch.
pub(crate) fn params(plant: &Plant, s: &SwingUpSettings, ts: f64) -> Option<SwingParams> {
    let p = plant.params();
    let crate::plant::Lumped { j0, ja, grav, .. } = p.lumped();
    let stall = p.kt / p.rm * s.max_voltage / (j0 + ja);
    let brake = s.brake_fraction * stall;
    let top_speed = envelope_speed(brake, s.arm_limit);
    let margin = (top_speed * ts)
        .max(SWING_ENVELOPE_MARGIN)
        .min(0.5 * s.arm_limit);
    Some(SwingParams {
        ts,
        // The law plans the voltage the smooth model needs; the dead zone and the arm's
        // Coulomb friction are the compensation's to invert. Inverting them in the law instead
        // divides by the slope of the dead zone, 0 at rest when `V_d ≥ 1 V`, which left the
        // law at 0 V with the pendulum hanging still.
        model: plant.arm_model(),
        max_voltage: s.max_voltage,
        upright_target: s.energy_margin * grav,
        dissipation: 4.0 * p.dp * (grav / ja).sqrt(),
        pump: s.pump_fraction * grav / ja,
        brake,
        energy_gain: s.energy_gain,
        pump_width: s.pump_width,
        arm_centering: s.arm_centering,
        rise_damping: s.rise_damping,
        barrier_rate: s.barrier_rate,
        envelope_limit: s.arm_limit - margin,
        rate_cutoff_hz: s.rate_cutoff,
        estimator_window: s.estimator_window,
        catch_angle: s.catch_angle,
        catch_lookahead: s.catch_lookahead,
        catch_mode_fraction: s.catch_mode_fraction,
        catch_rate: s.catch_rate,
        catch_arm_rate: s.catch_arm_rate,
        catch_arm_angle: s.catch_arm_angle,
        mode: unstable_mode(plant, s.max_voltage)?,
        prediction: prediction(plant, s, ts),
        balance_angle: s.balance_angle,
        arm_limit: s.arm_limit,
        stopping: stopping_model(p, s.max_voltage, 1.0, ts),
        handover_time: s.handover_time,
        reference_return_rate: s.reference_return_rate,
        max_time: s.max_time,
        on_fall: match s.on_fall {
            OnFall::Retry => control::OnFall::Retry,
            OnFall::Stop => control::OnFall::Stop,
        },
    })
}

/// The unstable mode of the nominal model linearised about upright (the law's docs, "catch"):
/// `z = wᵀ x` with `wᵀ A = λ wᵀ`, `λ > 0`, normalised to `w_α = 1`, and the largest `|z|`,
/// `|wᵀ b| U / λ`, that `|u| ≤ U` can bring back to 0.
pub(crate) fn unstable_mode(plant: &Plant, u_max: f64) -> Option<UnstableMode> {
    let (a, b) = plant.linearize_upright();
    let lambda = crate::linalg::eigenvalues(&a)
        .iter()
        .filter(|e| e.im.abs() < 1e-9 * (1.0 + e.re.abs()))
        .map(|e| e.re)
        .fold(f64::NAN, f64::max);
    if !(lambda.is_finite() && lambda > 0.0) {
        return None;
    }
    // The left eigenvector spans the null space of Aᵀ − λI: the right singular vector of
    // its smallest singular value.
    let shifted = a.transpose() - crate::linalg::Mat::identity(4, 4) * lambda;
    let svd = shifted.try_svd(false, true, f64::EPSILON, 400)?;
    let v_t = svd.v_t?;
    let k = svd.singular_values.imin();
    let row = v_t.row(k);
    if row[2].abs() < 1e-12 {
        return None;
    }
    let w = [row[0] / row[2], row[1] / row[2], 1.0, row[3] / row[2]];
    let wb: f64 = (0..4).map(|i| w[i] * b[(i, 0)]).sum();
    let recoverable = wb.abs() * u_max / lambda;
    recoverable
        .is_finite()
        .then_some(UnstableMode { w, recoverable })
}

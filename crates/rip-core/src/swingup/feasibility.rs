//! Whether a rig can be swung up at all at its voltage bound and arm travel, decided from the
//! nominal model before the motor moves: an energy balance of the last swing.
//!
//! # The last swing
//!
//! Whatever law pumps it, the pendulum reaches upright on a swing that passes hanging with
//! about the upright energy: along the homoclinic orbit `½ J_α α̇² = G (1 − cos α)`,
//! `α̇ = 2 ω |sin(α/2)|`, `ω = √(G/J_α)`. Over that half swing (α from one side of upright,
//! through hanging, to the other) the pendulum's equation (module docs of [`super`]) gives
//!
//! ```text
//! ΔE = ∫ m₁₂ cos α α̇ θ̈ dt + ∫ J_α sin α cos α α̇ θ̇² dt − ∫ d_p α̇² dt − ∫ C_p |α̇| dt
//! ```
//!
//! **Losses.** Along the orbit the last two terms are `L = 8 d_p ω + 2π C_p`.
//!
//! **What the arm can put in.** With `|θ̈| ≤ a_m` (the largest arm acceleration the motor adds
//! on the orbit of the smooth model at the voltage `U − V_d − C_r R_m/k_t` left once the dead zone and the
//! arm's Coulomb friction are paid), `|θ̇| ≤ v_m = min(U/k_m, √(2 a_m θ_L))` (faster, the arm cannot
//! stop inside `±θ_L`) and `|θ| ≤ θ_L`:
//!
//! ```text
//! W_a = m₁₂ a_m ∫|cos α| dα = 4 m₁₂ a_m                                  (acceleration)
//! W_θ = 2 max|g| v_m + 2 max|ġ| θ_L + θ_L ∫|g̈| dt,   g = m₁₂ cos α α̇      (travel)
//! W_c = J_α v_m² ∫|sin α cos α| dα = 2 J_α v_m²                           (centrifugal)
//! W   = min(W_a, W_θ) + W_c
//! ```
//!
//! `W_θ` is the first term integrated by parts twice, `∫ g θ̈ = [g θ̇] − [ġ θ] + ∫ g̈ θ`: it is
//! what keeps a heavy, slow pendulum from being pumped by an arm with little travel, however
//! strong the motor.
//!
//! **Verdict.** `W < L` (with a margin, [`IMPOSSIBLE_RATIO`]): the arm cannot make up the
//! losses of the swing that must reach upright, so no law swings this rig up —
//! [`Verdict::Impossible`], with the voltage and the arm travel that would balance the losses
//! ([`Feasibility::voltage_needed`], [`Feasibility::arm_travel_needed`]). Otherwise the
//! balance does not forbid it ([`Verdict::NotExcluded`]); whether the energy law or a
//! trajectory optimisation (`riprs.swingup.find_swing_up`) actually does it is a separate,
//! constructive question. The balance is taken along the free orbit, which the forced
//! pendulum follows only approximately: it is a bound on that orbit, not on every trajectory,
//! and the margin covers the difference.

use crate::plant::{FurutaParams, Plant, State};

use super::SwingUpSettings;

/// `W / L` below which the rig is declared impossible to swing up: the arm's largest energy
/// input over the last swing is at most 80 % of what friction takes on it.
pub const IMPOSSIBLE_RATIO: f64 = 0.8;

/// Grid points over the half swing (α ∈ (0, 2π)).
const GRID: usize = 2000;

/// The verdict of [`feasibility`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// The energy balance does not forbid a swing-up.
    NotExcluded,
    /// The arm cannot make up the losses of the last swing: no law swings this rig up.
    Impossible,
}

impl Verdict {
    /// `"not_excluded"` or `"impossible"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::NotExcluded => "not_excluded",
            Self::Impossible => "impossible",
        }
    }
}

/// The energy balance of the last swing (module docs), in joules, with the verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feasibility {
    /// The verdict.
    pub verdict: Verdict,
    /// `W`: the largest energy the arm can put into the pendulum over the last swing (J).
    pub gain: f64,
    /// `L`: what friction takes from it over that swing (J).
    pub loss: f64,
    /// `G = m_p g l_p / 2` (J), the scale: swinging up raises the energy by `2 G`.
    pub gravity: f64,
    /// The voltage bound at which `W = L / IMPOSSIBLE_RATIO` at the same arm travel (V);
    /// `None` when no voltage up to 100 × the bound reaches it (the arm travel limits).
    pub voltage_needed: Option<f64>,
    /// The arm travel `θ_L` (rad) at which `W = L / IMPOSSIBLE_RATIO` at the same voltage;
    /// `None` when none up to π reaches it (the voltage limits).
    pub arm_travel_needed: Option<f64>,
    /// A lower estimate of the time to upright (s): `⌈2 G / (W − L)⌉` half swings of `π/ω`;
    /// infinite when impossible.
    pub time_estimate: f64,
}

impl std::fmt::Display for Feasibility {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.verdict {
            Verdict::NotExcluded => write!(
                f,
                "a swing-up is not excluded: over the last swing the arm can put in up to \
                 {:.3e} J against {:.3e} J of friction (at least about {:.1} s to upright)",
                self.gain, self.loss, self.time_estimate
            ),
            Verdict::Impossible => {
                write!(
                    f,
                    "no swing-up is possible: over the last swing the arm can put in at most \
                     {:.3e} J, and friction takes {:.3e} J",
                    self.gain, self.loss
                )?;
                match (self.voltage_needed, self.arm_travel_needed) {
                    (Some(v), Some(t)) => write!(
                        f,
                        "; it would need about {v:.1} V (swing_up.max_voltage) or ±{t:.2} rad \
                         of arm travel (swing_up.arm_limit)"
                    ),
                    (Some(v), None) => {
                        write!(f, "; it would need about {v:.1} V (swing_up.max_voltage)")
                    }
                    (None, Some(t)) => write!(
                        f,
                        "; it would need about ±{t:.2} rad of arm travel (swing_up.arm_limit)"
                    ),
                    (None, None) => write!(
                        f,
                        "; neither 100 times the voltage nor ±π rad of arm travel would do"
                    ),
                }
            }
        }
    }
}

/// The balance `(W, L, G, ω)` at voltage bound `u_max` and arm travel `arm_limit`.
fn balance(p: &FurutaParams, u_max: f64, arm_limit: f64) -> (f64, f64, f64, f64) {
    use std::f64::consts::{PI, TAU};
    let crate::plant::Lumped { ja, grav, m12, .. } = p.lumped();
    let w = (grav / ja).sqrt();
    // The smooth model, with the dead zone and the arm's Coulomb friction taken off the
    // voltage instead.
    let Ok(smooth) = Plant::new(p.smooth()) else {
        return (0.0, f64::INFINITY, grav, w);
    };
    // What is left for accelerating once the dead zone and the arm's Coulomb friction
    // (as a voltage, `C_r R_m / k_t`) are paid.
    let usable = (u_max - p.vd - p.cr * p.rm / p.kt).max(0.0);
    let h = TAU / GRID as f64;
    let alphas: Vec<f64> = (0..GRID).map(|i| (i as f64 + 0.5) * h).collect();
    let rate = |a: f64| 2.0 * w * (0.5 * a).sin().abs();
    // The largest arm acceleration the motor adds on the orbit (at rest arm speed: back-EMF
    // only lowers it); what the pendulum's reaction adds is an exchange of the arm's kinetic
    // energy, which the centrifugal term `W_c` bounds.
    let mut per_volt: f64 = 0.0;
    for &a in &alphas {
        let x = State::new(0.0, 0.0, a, rate(a));
        let d = smooth.derivative(&x, 1.0, 0.0)[1] - smooth.derivative(&x, 0.0, 0.0)[1];
        per_volt = per_volt.max(d.abs());
    }
    let a_max = per_volt * usable;
    let v_max = if p.km > 0.0 {
        (usable / p.km).min((2.0 * a_max * arm_limit).sqrt())
    } else {
        (2.0 * a_max * arm_limit).sqrt()
    };
    // g(α) = m₁₂ cos α α̇ and its time derivatives along the orbit, d/dt = α̇ d/dα.
    let g: Vec<f64> = alphas.iter().map(|&a| m12 * a.cos() * rate(a)).collect();
    let deriv = |f: &[f64]| -> Vec<f64> {
        (0..f.len())
            .map(|i| {
                let lo = i.saturating_sub(1);
                let hi = (i + 1).min(f.len() - 1);
                let df = (f[hi] - f[lo]) / ((hi - lo) as f64 * h);
                df * rate(alphas[i])
            })
            .collect()
    };
    let g_dot = deriv(&g);
    let g_ddot = deriv(&g_dot);
    let max_abs = |f: &[f64]| f.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // ∫|g̈| dt = ∫ |g̈| / α̇ dα.
    let int_g_ddot: f64 = alphas
        .iter()
        .zip(&g_ddot)
        .map(|(&a, v)| v.abs() / rate(a).max(1e-9) * h)
        .sum();
    let w_accel = 4.0 * m12 * a_max;
    let w_travel =
        2.0 * max_abs(&g) * v_max + 2.0 * max_abs(&g_dot) * arm_limit + arm_limit * int_g_ddot;
    let w_centrifugal = 2.0 * ja * v_max * v_max;
    let gain = w_accel.min(w_travel) + w_centrifugal;
    let loss = 8.0 * p.dp * w + 2.0 * PI * p.cp;
    (gain, loss, grav, w)
}

/// The energy balance of the last swing of `plant` at `settings.max_voltage` and
/// `settings.arm_limit` (module docs).
pub fn feasibility(plant: &Plant, settings: &SwingUpSettings) -> Feasibility {
    let p = *plant.params();
    let (u, limit) = (settings.max_voltage, settings.arm_limit);
    let (gain, loss, gravity, w) = balance(&p, u, limit);
    let needed = loss / IMPOSSIBLE_RATIO;
    let verdict = if gain < loss * IMPOSSIBLE_RATIO {
        Verdict::Impossible
    } else {
        Verdict::NotExcluded
    };
    // W grows with either bound: bisect for the one that balances the losses.
    let solve = |f: &dyn Fn(f64) -> f64, lo: f64, hi: f64| -> Option<f64> {
        if f(hi) < needed {
            return None;
        }
        let (mut lo, mut hi) = (lo, hi);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if f(mid) < needed {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(hi)
    };
    let (voltage_needed, arm_travel_needed) = if verdict == Verdict::Impossible {
        (
            solve(&|v| balance(&p, v, limit).0, u, 100.0 * u),
            solve(&|t| balance(&p, u, t).0, limit, std::f64::consts::PI),
        )
    } else {
        (None, None)
    };
    let net = gain - loss;
    let time_estimate = if verdict == Verdict::Impossible || net <= 0.0 {
        f64::INFINITY
    } else {
        // At most `net` per half swing (≈ π/ω long): a lower estimate of the time to upright.
        (2.0 * gravity / net).ceil() * std::f64::consts::PI / w
    };
    Feasibility {
        verdict,
        gain,
        loss,
        gravity,
        voltage_needed,
        arm_travel_needed,
        time_estimate,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::regulators::Lqr;
    use crate::sim::{simulate, Reference, SimConfig};
    use crate::swingup::SwingUp;
    use std::f64::consts::PI;

    #[test]
    fn the_loss_of_the_last_swing_matches_an_integration_of_the_free_pendulum() {
        // Independent of the closed form 8 d_p ω: integrate J_α α̈ = G sin α by RK4 from
        // just off upright over one half swing and sum d_p α̇² dt.
        for p in [FurutaParams::paper(), FurutaParams::qube_servo2()] {
            let ja = p.jp + p.mp * p.lp * p.lp / 4.0;
            let grav = p.mp * p.g * p.lp / 2.0;
            let f = |x: [f64; 2]| [x[1], grav / ja * x[0].sin()];
            let (mut x, h) = ([1e-7, 2.0 * (grav / ja).sqrt() * 0.5e-7], 1e-5);
            let mut loss = 0.0f64;
            while x[0] < 2.0 * PI - 1e-7 && loss.is_finite() {
                let k1 = f(x);
                let k2 = f([x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1]]);
                let k3 = f([x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1]]);
                let k4 = f([x[0] + h * k3[0], x[1] + h * k3[1]]);
                loss += p.dp * x[1] * x[1] * h;
                x[0] += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]);
                x[1] += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]);
                if x[1] <= 0.0 {
                    break;
                }
            }
            let f = feasibility(&Plant::new(p).unwrap(), &SwingUpSettings::default());
            assert!(
                (f.loss - loss).abs() < 1e-3 * loss,
                "{} vs integrated {loss}",
                f.loss
            );
        }
    }

    fn rigs() -> Vec<(String, FurutaParams)> {
        let q = FurutaParams::qube_servo2();
        let like = FurutaParams {
            mr: 0.12,
            lr: 0.105,
            jr: 0.12 * 0.105 * 0.105 / 12.0,
            rm: 6.5,
            kt: 0.055,
            km: 0.055,
            mp: 0.038,
            lp: 0.19,
            jp: 0.038 * 0.19 * 0.19 / 12.0,
            ..q
        };
        let heavy = FurutaParams {
            mp: 0.06,
            lp: 0.25,
            jp: 0.06 * 0.25 * 0.25 / 12.0,
            vd: 0.6,
            cr: 0.006,
            ..like
        };
        let mut out = vec![
            ("paper".to_string(), FurutaParams::paper()),
            ("qube_servo2".to_string(), q),
            ("qube-like".to_string(), like),
            ("heavy".to_string(), heavy),
        ];
        for seed in [3, 11, 19, 27, 35, 43, 51, 59] {
            out.push((format!("rig {seed}"), crate::rig::Rig::random(seed).params));
        }
        out
    }

    fn hanging(duration: f64) -> SimConfig {
        SimConfig {
            duration,
            x0: [0.0, 0.0, PI, 0.0],
            reference: Reference::Step {
                time: 1e9,
                value: [0.0, 0.0],
            },
            ..SimConfig::default()
        }
    }

    #[test]
    fn a_rig_the_energy_law_swings_up_is_never_declared_impossible() {
        // Soundness on the rigs of the tests: whenever the energy law does catch in
        // simulation at 12 V and ±1.5 rad, the balance must not exclude it.
        let settings = SwingUpSettings::default();
        let mut caught = 0;
        for (name, p) in rigs() {
            let plant = Plant::new(p).unwrap();
            let f = feasibility(&plant, &settings);
            assert!(f.gain.is_finite() && f.loss > 0.0, "{name}: {f:?}");
            let text = format!(
                "[plant]\npreset = \"qube_servo2\"\nmr = {}\nLr = {}\nJr = {}\nmp = {}\n\
                 Lp = {}\nJp = {}\nDr = {}\nDp = {}\nRm = {}\nkt = {}\nkm = {}\nCr = {}\n\
                 Cp = {}\nVd = {}\n",
                p.mr, p.lr, p.jr, p.mp, p.lp, p.jp, p.dr, p.dp, p.rm, p.kt, p.km, p.cr, p.cp, p.vd
            );
            let spec = crate::spec::Spec::parse(&text).unwrap();
            let Ok(design) = spec.design(0.01) else {
                continue;
            };
            let mut sup =
                crate::spec::study::supervised(&spec, &design, crate::spec::ControllerKind::Lqr)
                    .unwrap();
            let res = simulate(&plant, sup.as_mut(), &hanging(20.0)).unwrap();
            if res.catch_time.is_some() {
                caught += 1;
                assert_eq!(f.verdict, Verdict::NotExcluded, "{name}: {f}");
            }
        }
        assert!(caught >= 6, "{caught}");
    }

    #[test]
    fn too_little_voltage_is_impossible_and_names_what_it_would_need() {
        let plant = Plant::paper();
        let low = SwingUpSettings {
            max_voltage: 0.05,
            max_time: 60.0,
            ..SwingUpSettings::default()
        };
        let f = feasibility(&plant, &low);
        assert_eq!(f.verdict, Verdict::Impossible, "{f}");
        assert!(f.time_estimate.is_infinite());
        let v = f.voltage_needed.expect("a voltage that would do");
        assert!(v > 0.05 && v < 12.0, "{v}");
        let text = f.to_string();
        assert!(text.contains("swing_up.max_voltage"), "{text}");
        // Consistent: at the voltage named the balance no longer excludes a swing-up.
        let at = SwingUpSettings {
            max_voltage: v * 1.001,
            ..low.clone()
        };
        assert_eq!(feasibility(&plant, &at).verdict, Verdict::NotExcluded);
        // And the energy law, pumping for a minute at 0.05 V, indeed gets nowhere near.
        let mut sup = SwingUp::new(Lqr::paper().unwrap(), &plant, low).unwrap();
        let res = simulate(&plant, &mut sup, &hanging(60.0)).unwrap();
        assert!(res.catch_time.is_none());
        assert!(sup.report().energy_fraction() < 0.5, "{}", sup.report());
    }

    #[test]
    fn strong_pendulum_friction_is_impossible_at_any_travel_the_arm_has() {
        let p = FurutaParams {
            dp: 0.5,
            ..FurutaParams::qube_servo2()
        };
        let f = feasibility(&Plant::new(p).unwrap(), &SwingUpSettings::default());
        assert_eq!(f.verdict, Verdict::Impossible, "{f}");
        assert!(f.to_string().contains("no swing-up is possible"), "{f}");
    }
}

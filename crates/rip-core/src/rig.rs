//! Seeded random rigs across the envelope riprs must handle (`shared/DESIGN.md`, "Any rig,
//! safely"): the one generator that tests of unknown rigs draw from.
//!
//! A rig is a full parameter set ([`FurutaParams`]) plus its sensors (encoder counts and
//! angle noise), returned in the form a `[plant]` / `[sensor]` file takes
//! ([`Rig::plant_spec`], [`Rig::sensor_spec`], [`Rig::to_toml`]), so a drawn rig feeds
//! `rip-rt emulate --config`, `rip-rt run --config` and `riprs compare --config` alike.
//!
//! # The envelope
//!
//! | quantity | range | draw |
//! |---|---|---|
//! | pendulum mass `mp` | 0.015–0.08 kg | uniform |
//! | pendulum length `Lp` | 0.08–0.30 m | uniform |
//! | arm length `Lr` | 0.06–0.15 m | uniform |
//! | arm mass `mr` | 0.05–0.15 kg | uniform |
//! | `Jr / (mr Lr²/12)`, `Jp / (mp Lp²/12)` | 0.5–1.5 | uniform |
//! | `Rm` | 2–10 Ω | uniform |
//! | `kt = km` | 0.02–0.08 | uniform |
//! | `Dr` | 2e-4–3e-3 N m s | log-uniform |
//! | `Dp` | 1e-5–2e-4 N m s | log-uniform |
//! | dead zone `Vd` | 0–1 V | uniform |
//! | arm Coulomb `Cr` | 0–0.006 N m | uniform |
//! | pendulum Coulomb `Cp` | 0–5e-5 N m | uniform |
//! | encoder counts (each) | 512–8192 | log-uniform, a multiple of 4 (quadrature) |
//! | angle noise (each) | 0–2 mrad | uniform |
//!
//! Viscous friction spans an order of magnitude, hence the log-uniform draw; every other
//! range is drawn uniformly. The same seed gives the same rig for a given riprs version (the
//! generator is `rand`'s `StdRng`, fixed by the lockfile).

use std::f64::consts::TAU;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;

use crate::plant::FurutaParams;
use crate::spec::{PlantSpec, Preset, SensorSpec};

/// A closed range `[lo, hi]` of the envelope.
pub type Range = (f64, f64);

/// Pendulum mass (kg).
pub const MP: Range = (0.015, 0.08);
/// Pendulum length (m).
pub const LP: Range = (0.08, 0.30);
/// Arm length, motor axis to pendulum joint (m).
pub const LR: Range = (0.06, 0.15);
/// Arm mass (kg).
pub const MR: Range = (0.05, 0.15);
/// Centroidal inertia of each link relative to a uniform rod's `m L²/12`.
pub const INERTIA_RATIO: Range = (0.5, 1.5);
/// Motor resistance (Ω).
pub const RM: Range = (2.0, 10.0);
/// Motor torque constant, equal to the back-EMF constant (N m/A = V s/rad).
pub const KT: Range = (0.02, 0.08);
/// Arm viscous friction (N m s/rad).
pub const DR: Range = (2e-4, 3e-3);
/// Pendulum viscous friction (N m s/rad).
pub const DP: Range = (1e-5, 2e-4);
/// Voltage dead zone (V).
pub const VD: Range = (0.0, 1.0);
/// Arm Coulomb friction (N m).
pub const CR: Range = (0.0, 0.006);
/// Pendulum Coulomb friction (N m).
pub const CP: Range = (0.0, 5e-5);
/// Encoder counts per revolution.
pub const COUNTS: (u32, u32) = (512, 8192);
/// Standard deviation of the angle noise (rad).
pub const NOISE: Range = (0.0, 2e-3);

/// A drawn rig: its physics and its sensors.
#[derive(Debug, Clone, PartialEq)]
pub struct Rig {
    /// The seed it was drawn from.
    pub seed: u64,
    /// Physical parameters (`g` = 9.81 m/s²).
    pub params: FurutaParams,
    /// Counts per revolution of the arm and pendulum encoders.
    pub encoder_counts: [u32; 2],
    /// Standard deviation of the arm and pendulum angle noise (rad).
    pub noise_std: [f64; 2],
}

#[derive(Serialize)]
struct RigFile {
    plant: PlantSpec,
    sensor: SensorSpec,
}

fn uniform(rng: &mut StdRng, (lo, hi): Range) -> f64 {
    lo + (hi - lo) * rng.gen::<f64>()
}

fn log_uniform(rng: &mut StdRng, (lo, hi): Range) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * rng.gen::<f64>()).exp()
}

fn counts(rng: &mut StdRng) -> u32 {
    let c = log_uniform(rng, (f64::from(COUNTS.0), f64::from(COUNTS.1)));
    ((c / 4.0).round() as u32 * 4).clamp(COUNTS.0, COUNTS.1)
}

impl Rig {
    /// The rig of `seed`, drawn across the envelope (module docs).
    pub fn random(seed: u64) -> Self {
        let mut rng = StdRng::seed_from_u64(seed);
        let mp = uniform(&mut rng, MP);
        let lp = uniform(&mut rng, LP);
        let lr = uniform(&mut rng, LR);
        let mr = uniform(&mut rng, MR);
        let jr = uniform(&mut rng, INERTIA_RATIO) * mr * lr * lr / 12.0;
        let jp = uniform(&mut rng, INERTIA_RATIO) * mp * lp * lp / 12.0;
        let rm = uniform(&mut rng, RM);
        let kt = uniform(&mut rng, KT);
        let dr = log_uniform(&mut rng, DR);
        let dp = log_uniform(&mut rng, DP);
        let vd = uniform(&mut rng, VD);
        let cr = uniform(&mut rng, CR);
        let cp = uniform(&mut rng, CP);
        let encoder_counts = [counts(&mut rng), counts(&mut rng)];
        let noise_std = [uniform(&mut rng, NOISE), uniform(&mut rng, NOISE)];
        Self {
            seed,
            params: FurutaParams {
                rm,
                kt,
                km: kt,
                mr,
                lr,
                jr,
                mp,
                lp,
                jp,
                dr,
                dp,
                g: 9.81,
                cr,
                cp,
                vd,
            },
            encoder_counts,
            noise_std,
        }
    }

    /// The `[plant]` section: the QUBE-Servo 2 preset (its `g`) with every parameter given.
    pub fn plant_spec(&self) -> PlantSpec {
        PlantSpec::with_params(Preset::QubeServo2, &self.params)
    }

    /// The `[sensor]` section: the encoders and the angle noise, zero offsets.
    pub fn sensor_spec(&self) -> SensorSpec {
        SensorSpec {
            encoder_counts: self.encoder_counts,
            noise_std: self.noise_std,
            ..SensorSpec::default()
        }
    }

    /// The noise in encoder counts (`rip-rt emulate --noise` takes one figure: the larger).
    pub fn noise_counts(&self) -> f64 {
        (0..2)
            .map(|j| self.noise_std[j] * f64::from(self.encoder_counts[j]) / TAU)
            .fold(0.0, f64::max)
    }

    /// `[plant]` and `[sensor]` as a TOML file (the other sections take their defaults).
    pub fn to_toml(&self) -> String {
        let file = RigFile {
            plant: self.plant_spec(),
            sensor: self.sensor_spec(),
        };
        format!(
            "# rig drawn by rip_core::rig::Rig::random({})\n{}",
            self.seed,
            toml::to_string(&file).expect("every spec value has a TOML form")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::Plant;
    use crate::spec::Spec;

    fn inside(v: f64, (lo, hi): Range) -> bool {
        (lo..=hi).contains(&v)
    }

    #[test]
    fn the_same_seed_draws_the_same_rig_and_others_differ() {
        assert_eq!(Rig::random(7), Rig::random(7));
        assert_ne!(Rig::random(7).params, Rig::random(8).params);
    }

    #[test]
    fn every_draw_lies_in_the_envelope_and_fills_it() {
        let rigs: Vec<Rig> = (0..2000).map(Rig::random).collect();
        let mut lo_hi = [[f64::INFINITY, f64::NEG_INFINITY]; 2];
        for r in &rigs {
            let p = &r.params;
            assert!(inside(p.mp, MP) && inside(p.lp, LP), "{r:?}");
            assert!(inside(p.mr, MR) && inside(p.lr, LR), "{r:?}");
            assert!(inside(p.jr / (p.mr * p.lr * p.lr / 12.0), INERTIA_RATIO));
            assert!(inside(p.jp / (p.mp * p.lp * p.lp / 12.0), INERTIA_RATIO));
            assert!(inside(p.rm, RM) && inside(p.kt, KT) && p.km == p.kt);
            assert!(inside(p.dr, DR) && inside(p.dp, DP));
            assert!(inside(p.vd, VD) && inside(p.cr, CR) && inside(p.cp, CP));
            for j in 0..2 {
                let c = r.encoder_counts[j];
                assert!((COUNTS.0..=COUNTS.1).contains(&c) && c % 4 == 0, "{c}");
                assert!(inside(r.noise_std[j], NOISE));
            }
            assert!(Plant::new(r.params).is_ok());
            for (k, (v, range)) in [(p.mp, MP), (p.dr, DR)].into_iter().enumerate() {
                let x = (v - range.0) / (range.1 - range.0);
                lo_hi[k] = [lo_hi[k][0].min(x), lo_hi[k][1].max(x)];
            }
        }
        // 2000 draws reach within 1 % of both ends of a uniform range; a log-uniform one
        // reaches its ends in log terms, i.e. within 1 % of the bottom on a linear scale too.
        for [lo, hi] in lo_hi {
            assert!(lo < 0.01 && hi > 0.97, "{lo} {hi}");
        }
        // Log-uniform Dr: the geometric midpoint splits the draws in halves.
        let mid = (DR.0 * DR.1).sqrt();
        let below = rigs.iter().filter(|r| r.params.dr < mid).count();
        assert!((900..1100).contains(&below), "{below}");
    }

    #[test]
    fn the_toml_is_a_spec_file_that_reads_back_as_the_same_rig() {
        let rig = Rig::random(3);
        let spec = Spec::parse(&rig.to_toml()).unwrap();
        assert_eq!(spec.plant.params(), rig.params);
        assert_eq!(spec.sensor.encoder_counts, rig.encoder_counts);
        assert_eq!(spec.sensor.noise_std, rig.noise_std);
    }
}

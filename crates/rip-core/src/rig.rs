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
//!
//! # Named rigs
//!
//! [`NamedRig`] holds the rigs of the tables of docs/tuning.md (the paper preset, the
//! QUBE-like rig with and without a dead zone, the QUBE-Servo 3 values, the heavy pendulum),
//! each read by that table's sensor ([`TABLE_SENSOR_COUNTS`], [`TABLE_SENSOR_NOISE`]): the one
//! definition the tests, the benches and the docs' tables use.

use std::f64::consts::TAU;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use serde::Serialize;

use crate::plant::FurutaParams;
use crate::spec::{PlantSpec, Preset, SensorSpec};

/// Encoder counts per revolution (arm, pendulum) of the sensor the named rigs are read by.
pub const TABLE_SENSOR_COUNTS: [u32; 2] = [2048, 2048];
/// Angle noise (rad, arm and pendulum) of the sensor the named rigs are read by.
pub const TABLE_SENSOR_NOISE: [f64; 2] = [5e-4, 5e-4];

/// A rig of the tables of docs/tuning.md, by name (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NamedRig {
    /// The paper preset as it is (designed on the paper's recovered linear model).
    Paper,
    /// The QUBE-Servo 2 preset with a longer, heavier arm and pendulum and a stronger motor:
    /// `mr` 0.12 kg, `Lr` 0.105 m, `mp` 0.038 kg, `Lp` 0.19 m, `Rm` 6.5 Ω, `kt = km` 0.055,
    /// uniform-rod inertias; no friction beyond the preset's viscous, no dead zone.
    QubeLike,
    /// [`QubeLike`](Self::QubeLike) with a 0.4 V dead zone and 0.003 N m of arm Coulomb
    /// friction.
    QubeLikeDeadZone,
    /// The QUBE-Servo 2 preset with QUBE-Servo 3 values (`Rm` 7.5 Ω, `kt = km` 0.0422,
    /// `Jr` 1.38e-4 kg m², `Dr` 3.975e-4 N m s, `Cp` 6.1e-6 N m) and its documented 0.65 V
    /// dead band.
    QubeServo3,
    /// [`QubeLike`](Self::QubeLike) with a 0.06 kg, 0.25 m pendulum, a 0.6 V dead zone and
    /// 0.006 N m of arm Coulomb friction.
    Heavy,
}

impl NamedRig {
    /// Every named rig, in the table's order.
    pub const ALL: [NamedRig; 5] = [
        Self::Paper,
        Self::QubeLike,
        Self::QubeLikeDeadZone,
        Self::QubeServo3,
        Self::Heavy,
    ];

    /// The name [`from_name`](Self::from_name) takes.
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::QubeLike => "qube_like",
            Self::QubeLikeDeadZone => "qube_like_dead_zone",
            Self::QubeServo3 => "qube_servo3",
            Self::Heavy => "heavy",
        }
    }

    /// The rig of `name`, if it is one.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.name() == name)
    }

    /// The row label of the docs' tables.
    pub fn label(self) -> &'static str {
        match self {
            Self::Paper => "paper preset",
            Self::QubeLike => "QUBE-like",
            Self::QubeLikeDeadZone => "QUBE-like, Vd 0.4, Cr 0.003",
            Self::QubeServo3 => "QUBE-Servo 3, 0.65 V band",
            Self::Heavy => "heavy pendulum",
        }
    }

    /// The physical parameters.
    pub fn params(self) -> FurutaParams {
        let qube_like = |mp: f64, lp: f64, vd: f64, cr: f64| {
            let (mr, lr) = (0.12, 0.105);
            FurutaParams {
                mr,
                lr,
                jr: FurutaParams::rod_inertia(mr, lr),
                mp,
                lp,
                jp: FurutaParams::rod_inertia(mp, lp),
                rm: 6.5,
                kt: 0.055,
                km: 0.055,
                vd,
                cr,
                ..FurutaParams::qube_servo2()
            }
        };
        match self {
            Self::Paper => FurutaParams::paper(),
            Self::QubeLike => qube_like(0.038, 0.19, 0.0, 0.0),
            Self::QubeLikeDeadZone => qube_like(0.038, 0.19, 0.4, 0.003),
            Self::QubeServo3 => FurutaParams {
                rm: 7.5,
                kt: 0.0422,
                km: 0.0422,
                jr: 1.38e-4,
                dr: 3.975e-4,
                cp: 6.1e-6,
                vd: 0.65,
                ..FurutaParams::qube_servo2()
            },
            Self::Heavy => qube_like(0.06, 0.25, 0.6, 0.006),
        }
    }

    /// The `[plant]` section: the paper preset alone for [`Paper`](Self::Paper) (so that its
    /// controllers are the paper's), otherwise the QUBE-Servo 2 preset with every parameter
    /// given.
    pub fn plant_spec(self) -> PlantSpec {
        match self {
            Self::Paper => PlantSpec::default(),
            _ => PlantSpec::with_params(Preset::QubeServo2, &self.params()),
        }
    }

    /// The `[sensor]` section: the table's sensor, zero offsets.
    pub fn sensor_spec(self) -> SensorSpec {
        SensorSpec {
            encoder_counts: TABLE_SENSOR_COUNTS,
            noise_std: TABLE_SENSOR_NOISE,
            ..SensorSpec::default()
        }
    }

    /// `[plant]` and `[sensor]` as a TOML file (the other sections take their defaults).
    pub fn to_toml(self) -> String {
        let file = RigFile {
            plant: self.plant_spec(),
            sensor: self.sensor_spec(),
        };
        format!(
            "# {} (rip_core::rig::NamedRig::{self:?})\n{}",
            self.label(),
            toml::to_string(&file).expect("every spec value has a TOML form")
        )
    }
}

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
                // No cable is drawn: every seed keeps the rig it has always generated.
                kc: 0.0,
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
    fn a_named_rig_reads_back_as_its_parameters_and_the_paper_stays_the_preset() {
        for rig in NamedRig::ALL {
            assert_eq!(NamedRig::from_name(rig.name()), Some(rig));
            let spec = Spec::parse(&rig.to_toml()).unwrap();
            assert_eq!(spec.plant.params(), rig.params(), "{rig:?}");
            assert_eq!(spec.sensor.encoder_counts, [2048, 2048]);
            assert_eq!(spec.sensor.noise_std, [5e-4, 5e-4]);
        }
        let paper = Spec::parse(&NamedRig::Paper.to_toml()).unwrap();
        assert_eq!(paper.plant, Spec::default().plant);
        // The published figures, written out here rather than read back from the code.
        let heavy = NamedRig::Heavy.params();
        assert_eq!(
            (heavy.mp, heavy.lp, heavy.vd, heavy.cr),
            (0.06, 0.25, 0.6, 0.006)
        );
        assert!((heavy.jp - 0.06 * 0.25 * 0.25 / 12.0).abs() < 1e-18);
        let q3 = NamedRig::QubeServo3.params();
        assert_eq!((q3.rm, q3.kt, q3.km, q3.vd), (7.5, 0.0422, 0.0422, 0.65));
        assert_eq!(q3.mp, FurutaParams::qube_servo2().mp);
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

//! The environment's configuration and the draws of each episode's plant, with their checks.

use super::snapshot::{invalid, Reader, Writer};
use super::{Task, DEFAULT_ACTION_COST, DEFAULT_INIT_SPREAD, MAX_DELAY};
use crate::error::{Result, RipError};
use crate::plant::Param;
use crate::plant::{FurutaParams, Plant, State};
use crate::sim::{
    SensorModel, COUNTS_PER_REV, DEFAULT_DURATION, DEFAULT_FALL_LIMIT, DEFAULT_SUBSTEPS,
    MAX_NOISE_STD, PERIOD_MS,
};

/// A parameter covariance (e.g. an identification's): the draw is `p = p̂ + L z`, `z ~ N(0, I)`,
/// `L Lᵀ = Σ`, on the listed parameters about their values in the environment's plant.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamCovariance {
    /// The parameters, in the order of the matrix's rows.
    pub params: Vec<Param>,
    /// `Σ` (row-major, `n × n`, symmetric positive semidefinite), in the parameters' SI units.
    pub matrix: Vec<f64>,
}

/// Per-episode draws (module docs); every `None` keeps the nominal value.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Randomisation {
    /// Drawn first: a Gaussian about the nominal parameters.
    pub covariance: Option<ParamCovariance>,
    /// Then each listed parameter is multiplied by an independent `1 + U(−r, r)`, `0 ≤ r < 1`.
    pub relative: Vec<(Param, f64)>,
    /// Dead zone `Vd ~ U(lo, hi)` (V).
    pub dead_zone: Option<[f64; 2]>,
    /// Arm Coulomb friction `Cr ~ U(lo, hi)` (N·m).
    pub arm_friction: Option<[f64; 2]>,
    /// Pendulum Coulomb friction `Cp ~ U(lo, hi)` (N·m).
    pub pendulum_friction: Option<[f64; 2]>,
    /// Action delay `d ~ U{lo, …, hi}` (periods), replacing [`EnvConfig::action_delay`].
    pub action_delay: Option<[usize; 2]>,
    /// Noise standard deviation of each angle `~ U(lo, hi)` (rad), replacing the sensor's.
    pub noise_std: Option<[f64; 2]>,
}

/// Everything an environment needs (module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct EnvConfig {
    /// Balance or swing-up.
    pub task: Task,
    /// The nominal plant.
    pub params: FurutaParams,
    /// Control period (s).
    pub ts: f64,
    /// RK4 steps per period.
    pub substeps: usize,
    /// Voltage of the action 1 (V); the actuator's bound.
    pub u_limit: f64,
    /// Encoders and noise (the nominal noise level).
    pub sensor: SensorModel,
    /// Cut-off (Hz) of the rate filter; `inf` for the plain difference.
    pub rate_cutoff_hz: f64,
    /// Episode length (steps) before truncation.
    pub max_steps: u32,
    /// Balance task: terminate when `|α| > fall_limit` (rad).
    pub fall_limit: f64,
    /// Terminate when `|θ| > arm_limit` (rad).
    pub arm_limit: f64,
    /// Action delay (periods, at most [`MAX_DELAY`]).
    pub action_delay: usize,
    /// Observation latency (periods, at most [`MAX_DELAY`]).
    pub observation_latency: usize,
    /// Half-width of the initial state's uniform spread (rad, rad/s).
    pub init_spread: f64,
    /// `c_u` of the reward.
    pub action_cost: f64,
    /// Per-episode draws.
    pub randomisation: Randomisation,
}

impl Default for EnvConfig {
    fn default() -> Self {
        Self {
            task: Task::Balance,
            params: FurutaParams::paper(),
            ts: crate::paper::TS,
            substeps: DEFAULT_SUBSTEPS,
            u_limit: crate::paper::INPUT_LIMIT,
            sensor: SensorModel {
                counts_per_rev: Some([2048.0, 2048.0]),
                noise_std: [1e-3, 1e-3],
                offsets: [0.0; 2],
            },
            rate_cutoff_hz: crate::regulators::DEFAULT_RATE_CUTOFF_HZ,
            max_steps: (DEFAULT_DURATION / crate::paper::TS).round() as u32,
            fall_limit: DEFAULT_FALL_LIMIT,
            arm_limit: crate::swingup::SwingUpSettings::default().arm_limit,
            action_delay: 0,
            observation_latency: 0,
            init_spread: DEFAULT_INIT_SPREAD,
            action_cost: DEFAULT_ACTION_COST,
            randomisation: Randomisation::default(),
        }
    }
}

pub(super) fn bad(name: &str, reason: String) -> RipError {
    RipError::invalid(name, reason)
}

fn check_range(name: &str, r: [f64; 2], max: f64) -> Result<()> {
    if !(r[0].is_finite() && r[1].is_finite() && 0.0 <= r[0] && r[0] <= r[1] && r[1] <= max) {
        return Err(bad(
            name,
            format!("needs 0 <= lo <= hi <= {max:e}, got [{}, {}]", r[0], r[1]),
        ));
    }
    Ok(())
}

impl EnvConfig {
    /// Checks every setting; the error names it.
    pub fn validate(&self) -> Result<()> {
        self.params.validate()?;
        // The control period a rig's loop may run at (`[loop] period_ms`): outside it the
        // environment would train a policy for a loop no rig runs.
        let period_ms = self.ts * 1000.0;
        if !PERIOD_MS.contains(&period_ms) {
            return Err(bad(
                "Ts",
                format!(
                    "must be in {}..={} s (a rig loop's period_ms, {}..={} ms), got {}",
                    PERIOD_MS.start() / 1000.0,
                    PERIOD_MS.end() / 1000.0,
                    PERIOD_MS.start(),
                    PERIOD_MS.end(),
                    self.ts
                ),
            ));
        }
        crate::plant::check_step(self.ts, self.substeps)?;
        if !(self.u_limit.is_finite() && self.u_limit > 0.0) {
            return Err(bad(
                "u_limit",
                format!("must be positive, got {}", self.u_limit),
            ));
        }
        // A dead zone at or above the voltage bound leaves the motor still whatever the action:
        // an environment no policy can act in.
        if self.params.vd >= self.u_limit {
            return Err(bad(
                "Vd",
                format!(
                    "the dead zone must be below u_limit ({} V), got {} V",
                    self.u_limit, self.params.vd
                ),
            ));
        }
        if let Some([_, hi]) = self.randomisation.dead_zone {
            if hi >= self.u_limit {
                return Err(bad(
                    "randomize.Vd",
                    format!(
                        "the dead zone must stay below u_limit ({} V), got up to {hi} V",
                        self.u_limit
                    ),
                ));
            }
        }
        if self.rate_cutoff_hz.is_nan() || self.rate_cutoff_hz <= 0.0 {
            return Err(bad(
                "rate_cutoff",
                format!("must be positive (Hz) or inf, got {}", self.rate_cutoff_hz),
            ));
        }
        if self.max_steps == 0 {
            return Err(bad("max_episode_steps", "must be at least 1, got 0".into()));
        }
        for (name, v) in [
            ("fall_limit", self.fall_limit),
            ("arm_limit", self.arm_limit),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, format!("must be positive, got {v}")));
            }
        }
        if !(self.init_spread.is_finite() && self.init_spread >= 0.0) {
            return Err(bad(
                "init_spread",
                format!("must be non-negative, got {}", self.init_spread),
            ));
        }
        if self.task == Task::Balance && self.init_spread >= self.fall_limit {
            return Err(bad(
                "init_spread",
                format!(
                    "{} would start the pendulum beyond fall_limit {}",
                    self.init_spread, self.fall_limit
                ),
            ));
        }
        if self.init_spread >= self.arm_limit {
            return Err(bad(
                "init_spread",
                format!("{} would start the arm beyond arm_limit", self.init_spread),
            ));
        }
        if !(self.action_cost.is_finite() && self.action_cost >= 0.0) {
            return Err(bad(
                "action_cost",
                format!("must be non-negative, got {}", self.action_cost),
            ));
        }
        for (name, d) in [
            ("action_delay", self.action_delay),
            ("observation_latency", self.observation_latency),
        ] {
            if d > MAX_DELAY {
                return Err(bad(
                    name,
                    format!("must be at most {MAX_DELAY} periods, got {d}"),
                ));
            }
        }
        if let Some(cpr) = self.sensor.counts_per_rev {
            // An experiment file's rule for its `[sensor] encoder_counts`: a whole number of
            // counts a rig's loop accepts.
            let (lo, hi) = (*COUNTS_PER_REV.start(), *COUNTS_PER_REV.end());
            for c in cpr {
                if !(c.fract() == 0.0 && f64::from(lo) <= c && c <= f64::from(hi)) {
                    return Err(bad(
                        "encoder_counts",
                        format!("must be in {lo}..={hi} counts per revolution, got {c}"),
                    ));
                }
            }
        }
        for s in self.sensor.noise_std {
            if !(s.is_finite() && (0.0..=MAX_NOISE_STD).contains(&s)) {
                return Err(bad(
                    "noise_std",
                    format!("must be in [0, {MAX_NOISE_STD:e}], got {s}"),
                ));
            }
        }
        if self.sensor.offsets.iter().any(|o| !o.is_finite()) {
            return Err(RipError::NonFinite {
                name: "encoder_offsets".into(),
            });
        }
        self.randomisation.validate()?;
        // The nominal plant must be integrable at this step; draws are checked at each reset.
        Plant::new(self.params)?.step_checked(&State::zeros(), 0.0, 0.0, self.ts, self.substeps)?;
        Ok(())
    }
}

impl Randomisation {
    /// Checks the ranges; the error names the setting.
    pub fn validate(&self) -> Result<()> {
        if let Some(c) = &self.covariance {
            let n = c.params.len();
            if n == 0 || c.matrix.len() != n * n {
                return Err(RipError::Shape {
                    name: "covariance".into(),
                    expected: format!("({n}, {n}), one row per parameter"),
                    rows: c.matrix.len(),
                    cols: 1,
                });
            }
            cholesky(&c.matrix, n).ok_or_else(|| {
                bad(
                    "covariance",
                    "must be a finite symmetric positive semidefinite matrix".into(),
                )
            })?;
        }
        for (p, r) in &self.relative {
            if !(r.is_finite() && (0.0..1.0).contains(r)) {
                return Err(bad(
                    &format!("randomize.{}", p.name()),
                    format!("relative half-width must be in [0, 1), got {r}"),
                ));
            }
        }
        if let Some(r) = self.dead_zone {
            check_range("randomize.Vd", r, 1e3)?;
        }
        if let Some(r) = self.arm_friction {
            check_range("randomize.Cr", r, 1e3)?;
        }
        if let Some(r) = self.pendulum_friction {
            check_range("randomize.Cp", r, 1e3)?;
        }
        if let Some(r) = self.noise_std {
            check_range("randomize.noise_std", r, MAX_NOISE_STD)?;
        }
        if let Some([lo, hi]) = self.action_delay {
            if lo > hi || hi > MAX_DELAY {
                return Err(bad(
                    "randomize.action_delay",
                    format!("needs lo <= hi <= {MAX_DELAY}, got [{lo}, {hi}]"),
                ));
            }
        }
        Ok(())
    }
}

fn write_param(w: &mut Writer, p: Param) {
    w.u8(p.index() as u8);
}

fn read_param(r: &mut Reader<'_>) -> Result<Param> {
    Param::FIELDS
        .get(usize::from(r.u8()?))
        .copied()
        .ok_or_else(|| invalid("an unknown plant parameter"))
}

impl EnvConfig {
    /// Appends the configuration to a snapshot ([`super::snapshot`]).
    pub(super) fn encode(&self, w: &mut Writer) {
        // Destructured whole, so that a field added to the configuration fails to compile here
        // until the snapshot carries it.
        let Self {
            task,
            params,
            ts,
            substeps,
            u_limit,
            sensor,
            rate_cutoff_hz,
            max_steps,
            fall_limit,
            arm_limit,
            action_delay,
            observation_latency,
            init_spread,
            action_cost,
            randomisation,
        } = self;
        w.u8(match task {
            Task::Balance => 0,
            Task::SwingUp => 1,
        });
        w.f64s(&params.to_array());
        w.f64(*ts);
        w.usize(*substeps);
        w.f64(*u_limit);
        let SensorModel {
            counts_per_rev,
            noise_std,
            offsets,
        } = sensor;
        w.opt_pair(*counts_per_rev);
        w.f64s(noise_std);
        w.f64s(offsets);
        w.f64(*rate_cutoff_hz);
        w.u32(*max_steps);
        w.f64(*fall_limit);
        w.f64(*arm_limit);
        w.usize(*action_delay);
        w.usize(*observation_latency);
        w.f64(*init_spread);
        w.f64(*action_cost);
        let Randomisation {
            covariance,
            relative,
            dead_zone,
            arm_friction,
            pendulum_friction,
            action_delay,
            noise_std,
        } = randomisation;
        w.bool(covariance.is_some());
        if let Some(c) = covariance {
            w.usize(c.params.len());
            for p in &c.params {
                write_param(w, *p);
            }
            w.usize(c.matrix.len());
            w.f64s(&c.matrix);
        }
        w.usize(relative.len());
        for (p, half) in relative {
            write_param(w, *p);
            w.f64(*half);
        }
        w.opt_pair(*dead_zone);
        w.opt_pair(*arm_friction);
        w.opt_pair(*pendulum_friction);
        w.bool(action_delay.is_some());
        let [lo, hi] = action_delay.unwrap_or_default();
        w.usize(lo);
        w.usize(hi);
        w.opt_pair(*noise_std);
    }

    /// Reads back what [`encode`](Self::encode) wrote, and validates it.
    pub(super) fn decode(r: &mut Reader<'_>) -> Result<Self> {
        let task = match r.u8()? {
            0 => Task::Balance,
            1 => Task::SwingUp,
            _ => return Err(invalid("an unknown task")),
        };
        let params = FurutaParams::from_array(r.f64s()?);
        let ts = r.f64()?;
        let substeps = r.usize(usize::MAX)?;
        let u_limit = r.f64()?;
        let sensor = SensorModel {
            counts_per_rev: r.opt_pair()?,
            noise_std: r.f64s()?,
            offsets: r.f64s()?,
        };
        let rate_cutoff_hz = r.f64()?;
        let max_steps = r.u32()?;
        let fall_limit = r.f64()?;
        let arm_limit = r.f64()?;
        let action_delay = r.usize(MAX_DELAY)?;
        let observation_latency = r.usize(MAX_DELAY)?;
        let init_spread = r.f64()?;
        let action_cost = r.f64()?;
        let covariance = if r.bool()? {
            let n = r.len(1)?;
            let params = (0..n).map(|_| read_param(r)).collect::<Result<Vec<_>>>()?;
            let m = r.len(8)?;
            let matrix = (0..m).map(|_| r.f64()).collect::<Result<Vec<_>>>()?;
            Some(ParamCovariance { params, matrix })
        } else {
            None
        };
        let n = r.len(9)?;
        let relative = (0..n)
            .map(|_| Ok((read_param(r)?, r.f64()?)))
            .collect::<Result<Vec<_>>>()?;
        let dead_zone = r.opt_pair()?;
        let arm_friction = r.opt_pair()?;
        let pendulum_friction = r.opt_pair()?;
        let some_delay = r.bool()?;
        let delays = [r.usize(MAX_DELAY)?, r.usize(MAX_DELAY)?];
        let noise_std = r.opt_pair()?;
        let config = Self {
            task,
            params,
            ts,
            substeps,
            u_limit,
            sensor,
            rate_cutoff_hz,
            max_steps,
            fall_limit,
            arm_limit,
            action_delay,
            observation_latency,
            init_spread,
            action_cost,
            randomisation: Randomisation {
                covariance,
                relative,
                dead_zone,
                arm_friction,
                pendulum_friction,
                action_delay: some_delay.then_some(delays),
                noise_std,
            },
        };
        config.validate()?;
        Ok(config)
    }
}

/// Lower Cholesky factor of a symmetric positive semidefinite `n × n` matrix (semidefinite
/// pivots are set to zero), or `None` when it is not one.
pub(super) fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    if a.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let scale = a
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    let tol = 1e-12 * scale;
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            if (a[i * n + j] - a[j * n + i]).abs() > tol {
                return None;
            }
        }
    }
    for j in 0..n {
        let d = a[j * n + j] - (0..j).map(|k| l[j * n + k] * l[j * n + k]).sum::<f64>();
        if d < -tol {
            return None;
        }
        let ljj = d.max(0.0).sqrt();
        l[j * n + j] = ljj;
        for i in j + 1..n {
            let s = a[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
            l[i * n + j] = if ljj > 0.0 { s / ljj } else { 0.0 };
            if ljj == 0.0 && s.abs() > tol {
                return None;
            }
        }
    }
    Some(l)
}

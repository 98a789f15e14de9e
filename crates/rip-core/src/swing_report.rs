//! What a swing-up did, for the message of one that ends without a catch.

/// What the current (or last) swing-up did, measured on the supervisor's own estimate: the
/// peak pendulum energy against the catch target, the largest voltage the law asked for and
/// the arm travel it used ([`SwingUp::report`](crate::swingup::SwingUp::report)). Its
/// [`Display`](std::fmt::Display) is the sentence a failed swing-up ends with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwingUpReport {
    /// Largest pendulum energy `E` (J, 0 upright at rest) reached.
    pub peak_energy: f64,
    /// The energy the law pumps towards at upright, `δ G` (J).
    pub target_energy: f64,
    /// The energy hanging at rest, `−2 G` (J).
    pub hanging_energy: f64,
    /// Smallest `|α|` (rad from upright) reached.
    pub closest_approach: f64,
    /// Largest `|u|` (V) the law asked for (before any dead-zone compensation).
    pub peak_voltage: f64,
    /// Smallest and largest arm angle `θ` (rad) reached.
    pub arm_travel: [f64; 2],
    /// `swing_up.arm_limit` (rad).
    pub arm_limit: f64,
    /// Samples the swing-up ran.
    pub samples: u64,
}

/// Arm travel (rad) below which the arm is said not to have moved: a few encoder counts.
pub const STILL_ARM: f64 = 0.01;

impl SwingUpReport {
    /// The share of the way from hanging to the target the peak energy got,
    /// `(E_peak − E_hang)/(E_t − E_hang)` (1 = reached the target).
    pub fn energy_fraction(&self) -> f64 {
        (self.peak_energy - self.hanging_energy) / (self.target_energy - self.hanging_energy)
    }

    /// Whether the arm moved at all (its travel exceeded [`STILL_ARM`]).
    pub fn arm_moved(&self) -> bool {
        self.arm_travel[1] - self.arm_travel[0] > STILL_ARM
    }

    pub(crate) fn start(target: f64, hanging: f64, arm_limit: f64) -> Self {
        Self {
            peak_energy: f64::NEG_INFINITY,
            target_energy: target,
            hanging_energy: hanging,
            closest_approach: f64::INFINITY,
            peak_voltage: 0.0,
            arm_travel: [f64::INFINITY, f64::NEG_INFINITY],
            arm_limit,
            samples: 0,
        }
    }

    pub(crate) fn record(&mut self, energy: f64, theta: f64, alpha: f64, u: f64) {
        self.peak_energy = self.peak_energy.max(energy);
        self.closest_approach = self.closest_approach.min(alpha.abs());
        self.peak_voltage = self.peak_voltage.max(u.abs());
        self.arm_travel = [self.arm_travel[0].min(theta), self.arm_travel[1].max(theta)];
        self.samples += 1;
    }
}

impl std::fmt::Display for SwingUpReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.samples == 0 {
            return write!(f, "the swing-up took no sample");
        }
        write!(
            f,
            "the pendulum's energy peaked at {:.0} % of the way from hanging to the catch \
             target ({:.4} J against {:.4} J), {:.2} rad from upright at the closest; ",
            100.0 * self.energy_fraction(),
            self.peak_energy,
            self.target_energy,
            self.closest_approach
        )?;
        if self.peak_voltage == 0.0 {
            write!(f, "the law never asked for a voltage (|u| max 0 V); ")?;
        } else {
            write!(f, "the law asked for up to {:.1} V; ", self.peak_voltage)?;
        }
        if self.arm_moved() {
            write!(
                f,
                "the arm used {:.2} to {:.2} rad of ±{:.2} rad (swing_up.arm_limit)",
                self.arm_travel[0], self.arm_travel[1], self.arm_limit
            )
        } else {
            write!(
                f,
                "the arm never moved (travel below {STILL_ARM} rad): the motor did not drive it \
                 (check the wiring, the drive's enable and the dead zone)"
            )
        }
    }
}
